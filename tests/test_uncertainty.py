"""Friction (Appendix A) and band-limited noise: dissipation, stiction, seeding."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CONFIGS, run_raw

from nlcx import config, engine
from nlcx.plants.pendulum import PendulumParams
from nlcx.plants.x_pendulum import XPendulum

WEIGHT = 1.1 * 9.8  # (M + m) g, the normal force of Appendix A


def friction_run(force: float, mu_s: float, x0: dict, model: str = "simple", t_end: float = 2.0) -> engine.Run:
    raw = {
        "name": "friction_test",
        "plant": {"name": "x_pendulum", "x0": x0},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {"F_x": {"kind": "constant", "value": force}},
        "uncertainty": {"friction": {"kind": "friction", "model": model, "mu_s": mu_s, "mu_c": 0.5 * mu_s}},
        "simulation": {"t_end": t_end, "dt": 1e-3, "bounds": {"theta": 1e9}},
    }
    (run,) = run_raw(raw).runs
    return run


def test_stiction_holds_a_base_at_rest_below_breakaway() -> None:
    """|F| < mu_s F_N: the base stays exactly at rest; friction cancels the force exactly."""
    run = friction_run(force=0.8 * 0.3 * WEIGHT, mu_s=0.3, x0={})
    assert np.all(run.x[:, 0] == 0.0) and np.all(run.x[:, 1] == 0.0)
    assert np.allclose(run.friction[:, 0], -0.8 * 0.3 * WEIGHT, rtol=0, atol=1e-9)


def test_breakaway_above_mu_s() -> None:
    run = friction_run(force=1.2 * 0.3 * WEIGHT, mu_s=0.3, x0={})
    assert run.x[-1, 0] > 0.05 and np.all(np.diff(run.x[:, 0]) >= 0)


def test_stuck_base_holds_the_pendulum_reaction_without_chattering() -> None:
    """A falling pendulum pushes on a stuck base: the holding force follows the reaction
    smoothly until it reaches mu_s F_N, and only then does the base slide."""
    run = friction_run(force=0.0, mu_s=0.02, x0={"theta": 0.2}, t_end=1.0)
    limit = 0.02 * WEIGHT
    f = run.friction[:, 0]
    stuck = run.x[:, 1] == 0.0
    assert not stuck.all()
    first_slip = int(np.argmin(stuck))
    assert first_slip > 10  # it held for a while
    assert np.all(run.x[:first_slip, 0] == 0.0)
    assert np.all(np.abs(f[:first_slip]) <= limit + 1e-9)
    held = np.abs(f[: first_slip - 1])
    assert held.max() > 0.95 * limit  # released once the holding force reached mu_s F_N
    assert np.all(np.diff(np.sign(f[1 : first_slip - 1])) == 0)  # no sign chattering while stuck


@pytest.mark.parametrize("model", ["simple", "exponential"])
def test_friction_only_dissipates(model: str) -> None:
    """Under friction V(t_k+1) - V(t_k) <= F_k (x_k+1 - x_k): friction never adds energy."""
    figure = "fig_2_09" if model == "simple" else "fig_2_11"
    exp = config.load(CONFIGS / "thesis" / "ch2" / f"{figure}.yaml", ["simulation.t_end=10"])
    result = engine.run_experiment(exp)
    energy = XPendulum().energy(PendulumParams())
    assert [run.label for run in result.runs] == ["conventional", "proposed"]
    for run in result.runs:
        V = energy(run.x)
        work = run.u[:-1, 0] * np.diff(run.x[:, 0])
        excess = np.diff(V) - work
        assert np.max(excess) < 1e-9
        assert np.sum(excess) < -1e-3  # it did dissipate


def sensor_noise(prepared: engine.Prepared) -> np.ndarray:
    """The noise sequence (K+1, n_y) of the one sensor element of a run."""
    (element,) = [e for e in prepared.hooks.elements if e.hook == "sensor"]
    return element.data


def noise_runs(seed: int) -> engine.ExperimentResult:
    exp = config.load(CONFIGS / "thesis" / "ch2" / "fig_2_07.yaml", [f"seed={seed}", "simulation.t_end=2"])
    return engine.run_experiment(exp)


def test_noise_same_seed_same_noise_other_seed_other_noise() -> None:
    a, b, c = noise_runs(3), noise_runs(3), noise_runs(4)
    na, nb, nc = (sensor_noise(r.prepared) for r in (a, b, c))
    assert np.array_equal(na, nb) and not np.array_equal(na, nc)
    assert np.array_equal(a.runs[0].x, b.runs[0].x) and not np.array_equal(a.runs[0].x, c.runs[0].x)


def test_noise_is_band_limited_white_noise() -> None:
    """Held for the sample time; variance power / sample_time (Simulink's block)."""
    exp = config.load(
        CONFIGS / "thesis" / "ch2" / "fig_2_07.yaml",
        ["simulation.t_end=200", "uncertainty.noise.power=1e-4", "uncertainty.noise.sample_time=0.02"],
    )
    noise = sensor_noise(engine.prepare(exp))
    held = noise[:-1].reshape(-1, 20, noise.shape[1])
    assert np.all(held == held[:, :1, :])  # constant within each 20-step hold
    samples = held[:, 0, :].ravel()
    assert samples.size == 20000
    assert np.var(samples) == pytest.approx(1e-4 / 0.02, rel=0.05)
    assert abs(np.corrcoef(samples[:-1], samples[1:])[0, 1]) < 0.03  # white from sample to sample


def test_both_controllers_see_the_same_noise() -> None:
    """Common random numbers: the comparison is not confounded by two noise draws."""
    result = noise_runs(5)
    items = engine.items_of(result.prepared)
    assert len(items) == 2 and items[0].element_data is items[1].element_data  # one sequence, broadcast


@pytest.mark.parametrize("integrator", ["rk4", "heun"])
def test_the_friction_recorded_at_the_final_sample_sees_the_disturbance_at_that_instant(integrator: str) -> None:
    """A base held by stiction under a sine disturbance: the holding force recorded at the
    final sample t_K (which begins no step, so no stage of the disturbance table sits at it)
    equals the force recorded at the same instant by a run that goes on past it."""

    def held(t_end: float) -> np.ndarray:
        raw = {
            "name": "held_under_disturbance",
            "plant": {"name": "x_pendulum", "x0": {}},
            "controllers": {"open": {"kind": "open_loop"}},
            "reference": {"F_x": {"kind": "constant", "value": 0.2 * WEIGHT}},
            "uncertainty": {
                "friction": {"kind": "friction", "model": "simple", "mu_s": 0.5, "mu_c": 0.25},
                "disturbance": {"kind": "disturbance", "amplitude": 0.5, "frequency": 3.0, "states": ["x_dot"]},
            },
            "simulation": {"t_end": t_end, "dt": 1e-3, "integrator": integrator, "bounds": {"theta": 1e9}},
        }
        (run,) = run_raw(raw).runs
        assert np.all(run.x[:, 1] == 0.0)  # held throughout
        return run.friction[:, 0]

    short, long = held(0.5), held(0.6)
    assert np.isclose(short[-1], long[short.size - 1], rtol=1e-12, atol=0)
    assert np.array_equal(short[:-1], long[: short.size - 1])
    assert not np.isclose(short[-1], short[-2], rtol=1e-6)  # the disturbance moves the force between samples

"""Loop options of the identification study: an actuator lag element, a prefiltered step."""

from __future__ import annotations

import math

import numpy as np

from nlcx import config, engine

BASE = {
    "name": "lag",
    "plant": {"name": "x_pendulum"},
    "controllers": {"o": {"kind": "open_loop"}},
    "reference": {"F_x": {"kind": "step", "final": 2.0, "time": 0.05}},
    "simulation": {"t_end": 1.0, "dt": 0.001, "bounds": {"theta": 1000.0}},
}


def test_actuator_lag_is_a_sampled_first_order_lag() -> None:
    """The applied force after a step of 2 N at 0.05 s: v_k = 2 (1 - exp(-(k - k0 + 1) dt / tau))."""
    tau, dt = 0.1, 0.001
    raw = BASE | {"uncertainty": {"lag": {"kind": "actuator_lag", "tau": tau}}}
    (run,) = engine.run_experiment(config.build(raw)).runs
    k0 = 50
    k = np.arange(k0, run.t.size)
    expected = 2.0 * (1 - (math.exp(-dt / tau)) ** (k - k0 + 1))
    np.testing.assert_allclose(run.u[k0:, 0], expected, rtol=1e-12)
    assert np.all(run.u[:k0, 0] == 0.0)
    # batch = alone: the element's state is per variant
    batch = [config.build(raw | {"uncertainty": {"lag": {"kind": "actuator_lag", "tau": t}}}) for t in (0.05, 0.1)]
    together = engine.evaluate(batch)
    assert np.array_equal(together[1].runs[0].u, run.u)


def test_a_prefiltered_step_rises_exponentially_and_is_measured_as_the_step() -> None:
    raw = {
        "name": "pf",
        "plant": {"name": "x_pendulum"},
        "controllers": {"o": {"kind": "open_loop"}},
        "reference": {
            "F_x": {"kind": "filtered_step", "final": 1.0, "time": 0.2, "time_constant": 0.3},
        },
        "simulation": {"t_end": 1.0, "dt": 0.001, "bounds": {"theta": 1000.0}},
    }
    (run,) = engine.run_experiment(config.build(raw)).runs
    t = run.t
    expected = np.where(t >= 0.2, 1 - np.exp(-(t - 0.2) / 0.3), 0.0)
    np.testing.assert_allclose(run.u[:, 0], expected, atol=1e-15)
    prep = engine.prepare(config.build(raw))
    model, cfg = prep.references["F_x"]
    plan = model.signal_plan(cfg)
    assert (plan.kind, plan.final, plan.t_step) == ("step", 1.0, 0.2)


def test_actuator_saturation_clips_what_any_controller_commands() -> None:
    """An open-loop ramp of F_x through |F_x| <= 0.7: applied = clip(commanded)."""
    raw = BASE | {
        "reference": {"F_x": {"kind": "sine", "amplitude": 2.0, "frequency": 1.0}},
        "uncertainty": {"limit": {"kind": "actuator_saturation", "limit": 0.7}},
    }
    (run,) = engine.run_experiment(config.build(raw)).runs
    (free,) = engine.run_experiment(config.build(BASE | {"reference": raw["reference"]})).runs
    np.testing.assert_array_equal(run.r[:, 0], free.r[:, 0])
    np.testing.assert_array_equal(run.u[:, 0], np.clip(free.u[:, 0], -0.7, 0.7))
    assert np.max(np.abs(free.u[:, 0])) > 1.9


def test_the_pids_saturation_and_the_actuator_element_are_one_clamp() -> None:
    """A PID whose own saturation has no anti-windup and the same PID behind an
    ``actuator_saturation`` element of the same limit apply one clamp (the element's
    ``saturate``): the two closed loops are the same to the bit, and the limit is reached."""
    pid = {
        "kind": "pid",
        "loops": {
            "theta": {"sign": -1, "schedule": {"kind": "constant", "kp": 40, "ki": 2, "kd": 5}},
            "x": {"sign": 1, "schedule": {"kind": "constant", "kp": -3, "ki": -1, "kd": -2}},
        },
    }
    raw = {
        "name": "one_clamp",
        "plant": {"name": "x_pendulum"},
        "reference": {"x": {"kind": "step", "final": 1.0}},
        "simulation": {"t_end": 2.0, "dt": 0.01},
    }
    limited = {**pid, "saturation": {"limits": {"F_x": 3.0}, "anti_windup": "none"}}
    (own,) = engine.run_experiment(config.build(raw | {"controllers": {"c": limited}})).runs
    element = {"limit": {"kind": "actuator_saturation", "limit": 3.0}}
    (behind,) = engine.run_experiment(config.build(raw | {"controllers": {"c": pid}, "uncertainty": element})).runs
    assert np.array_equal(own.x.view(np.int64), behind.x.view(np.int64))
    assert np.array_equal(own.u.view(np.int64), behind.u.view(np.int64))
    assert np.max(np.abs(own.u)) == 3.0

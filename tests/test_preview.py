"""H2 / H-infinity preview control (thesis section 5.5) on the CSTR transfer function (eq. 5.10)."""

from __future__ import annotations

import copy
import itertools
from types import SimpleNamespace

import control
import numpy as np
import pytest

from nlcx import config, engine, registry
from nlcx.controllers.base import check_sample_time
from nlcx.controllers.preview import Preview, PreviewConfig
from nlcx.controllers.preview_design import (
    augment,
    companion_matrices,
    design_preview,
    gamma_min,
    hinf_riccati,
    linear_model,
)
from nlcx.errors import ConfigError
from nlcx.plants.base import linearize
from nlcx.plants.transfer_function import TransferFunction, TransferFunctionParams

registry.controllers.register("preview", "nlcx.controllers.preview:Preview", replace=True)

CSTR = {"num": [-1.117, 3.1472], "den": [1.0, 4.6429, 5.3821]}  # eq. 5.10
C_ROW = np.array(CSTR["num"][::-1])  # y = 3.1472 x1 - 1.117 x2
TS = 0.1
H = 10
STEP_TIME = 3.0


@pytest.fixture(scope="module")
def plant():
    return TransferFunction().build("transfer_function", TransferFunctionParams(**CSTR), {}, {})


@pytest.fixture(scope="module")
def model(plant):
    return linear_model(plant, TS)


def hinf_norm(A: np.ndarray, B: np.ndarray, C: np.ndarray, n_freq: int = 2000) -> float:
    """max over the unit circle of sigma_max(C (zI - A)^-1 B): a dense sweep, refined at its peak."""
    eye = np.eye(A.shape[0])

    def sigma(theta: float) -> float:
        G = C @ np.linalg.solve(np.exp(1j * theta) * eye - A, B)
        return float(np.linalg.svd(G, compute_uv=False)[0])

    grid = np.linspace(0.0, np.pi, n_freq)
    values = np.array([sigma(th) for th in grid])
    k = int(np.argmax(values))
    step = grid[1] - grid[0]
    fine = np.clip(np.linspace(grid[k] - step, grid[k] + step, 201), 0.0, np.pi)
    return max(float(values[k]), max(sigma(th) for th in fine))


def run_preview(controllers: dict, t_end: float = 15.0, dt: float = 0.01, **extra) -> engine.ExperimentResult:
    raw = {
        "name": "preview_test",
        "plant": {"name": "transfer_function", "params": CSTR},
        "controllers": controllers,
        "reference": {"y": {"kind": "step", "time": STEP_TIME}},
        "simulation": {"t_end": t_end, "dt": dt},
        **extra,
    }
    return engine.run_experiment(config.build(copy.deepcopy(raw)))


# --------------------------------------------------------------------------- design


@pytest.mark.parametrize("disturbance", [False, True])
def test_hinf_closed_loop_meets_its_bound(model, disturbance: bool) -> None:
    """||T_zw||_inf of the full-information closed loop (frequency sweep) lies in [gamma_min, gamma]."""
    d = design_preview(model, design="hinf", h=H, disturbance=disturbance)
    assert d.gamma == pytest.approx(1.05 * d.gamma_min, rel=1e-12)
    Acl, Bw, Ccl = d.closed_loop()
    assert np.max(np.abs(np.linalg.eigvals(Acl))) < 1.0
    norm = hinf_norm(Acl, Bw, Ccl)
    assert norm < d.gamma
    # no stabilising state feedback beats gamma_min, so the bound is also tight from below
    assert norm >= d.gamma_min * (1 - 1e-3)
    # and a design just above gamma_min attains it: the bisection found the optimum
    tight = design_preview(model, design="hinf", h=H, disturbance=disturbance, gamma_factor=1.001)
    assert hinf_norm(*tight.closed_loop()) == pytest.approx(tight.gamma_min, rel=2e-3)


def test_gamma_below_minimum_is_infeasible_and_riccati_holds(model) -> None:
    aug = augment(model, H, q=1.0, r=0.1, integral=1.0)
    g_min = gamma_min(aug, tol=1e-5)
    assert hinf_riccati(aug, g_min).feasible
    assert not hinf_riccati(aug, g_min * (1 - 1e-3)).feasible
    assert not hinf_riccati(aug, 0.5 * g_min).feasible
    gamma = 1.05 * g_min
    sol = hinf_riccati(aug, gamma)
    assert sol.feasible
    X, Phi = sol.X, aug.Phi
    G = np.hstack([aug.Gu, aug.Gw])
    Rt = np.diag([0.1, -(gamma**2)])
    res = X - aug.Q - Phi.T @ X @ Phi + Phi.T @ X @ G @ np.linalg.inv(Rt + G.T @ X @ G) @ G.T @ X @ Phi
    assert np.max(np.abs(res)) <= 1e-8 * max(1.0, np.max(np.abs(X)))
    assert np.min(np.linalg.eigvalsh(X)) >= -1e-10 * np.max(np.abs(X))
    assert gamma**2 - (aug.Gw.T @ X @ aug.Gw).item() > 0
    # the state-feedback gain: u = K xi with Xt = X + X Gw (gamma^2 - Gw'X Gw)^-1 Gw'X
    Xt = X + X @ aug.Gw @ np.linalg.inv(gamma**2 * np.eye(1) - aug.Gw.T @ X @ aug.Gw) @ aug.Gw.T @ X
    K = -np.linalg.solve(aug.R + aug.Gu.T @ Xt @ aug.Gu, aug.Gu.T @ Xt @ Phi)
    np.testing.assert_allclose(sol.K, K, rtol=1e-7, atol=1e-9)
    d = design_preview(model, design="hinf", h=H)
    np.testing.assert_allclose(d.K, K, rtol=1e-3)  # tolerance 1e-4 on gamma_min moves K slightly


def test_h2_gain_equals_dlqr(model) -> None:
    d = design_preview(model, design="h2", h=H)
    K_lqr, S, _ = control.dlqr(d.aug.Phi, d.aug.Gu, d.aug.Q, d.aug.R)
    np.testing.assert_allclose(d.K, -K_lqr, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(d.X, S, rtol=1e-8, atol=1e-10)
    assert d.Kx.shape == (1, 3) and d.Kd.shape == (1, H + 1)


def impulse_cost(d, n_steps: int = 400, k0: int = 30) -> float:
    """J = sum ||z||^2 on the design model when the reference is a unit pulse at sample k0."""
    aug = d.aug
    ref = np.zeros(n_steps + aug.h + 2)
    ref[k0] = 1.0
    xi = np.zeros(aug.Phi.shape[0])
    xi[aug.n_x :] = ref[: aug.h + 1]
    J = 0.0
    for k in range(n_steps):
        u = d.K @ xi
        z = aug.Cz @ xi + aug.Dz @ u
        J += float(z @ z)
        xi = aug.Phi @ xi + aug.Gu @ u + aug.Gw[:, 0] * ref[k + aug.h + 1]
    return J


def test_more_preview_does_not_worsen_h2_tracking(model) -> None:
    """The optimal H2 cost (a reference pulse first seen h samples ahead) is non-increasing in h."""
    costs = []
    for h in (0, 2, 5, 10, 20):
        d = design_preview(model, design="h2", h=h)
        cost = d.X[-1, -1]  # = ||T_zw||_2^2, the value function at xi = e_last
        assert impulse_cost(d) == pytest.approx(cost, rel=1e-9)
        costs.append(cost)
    assert all(b <= a * (1 + 1e-12) for a, b in itertools.pairwise(costs)), costs
    assert costs[-1] < 0.8 * costs[0], costs


def test_more_preview_does_not_worsen_hinf_bound(model) -> None:
    gammas = [design_preview(model, design="hinf", h=h).gamma_min for h in (0, 2, 5, 10, 20)]
    assert all(b <= a * (1 + 2e-4) for a, b in itertools.pairwise(gammas)), gammas
    assert gammas[-1] < 0.8 * gammas[0], gammas


def test_numerical_linearisation_matches_canonical_form(plant) -> None:
    A, B, _ = linearize(plant, np.array([0.3, -0.2]), np.array([0.7]), relative=True)
    A0, B0 = companion_matrices(plant.p)
    np.testing.assert_allclose(A, A0, atol=1e-8)
    np.testing.assert_allclose(B, B0, atol=1e-8)


@pytest.mark.parametrize("relative", [False, True])
def test_linearize_steps_each_coordinate_by_h_or_h_times_its_size(relative: bool) -> None:
    """Central differences about (x, u) = ((0.5, -200), (30,)): coordinate j moves by +-h, or
    with ``relative`` by +-h max(1, |x_j|) (the preview design's linearisation), one at a time."""
    x_op, u_op, h = np.array([0.5, -200.0]), np.array([30.0]), 1e-4
    visited: list[tuple[float, ...]] = []

    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        visited.append((*x, *u))
        return np.array([x[0] * x[1] + u[0], x[1] ** 2])

    fake = SimpleNamespace(states=["a", "b"], inputs=["F"], features=SimpleNamespace(x_op=None), f=f, C=np.eye(2))
    A, B, C = linearize(fake, x_op, u_op, h=h, relative=relative)
    steps = [h * max(1.0, abs(v)) if relative else h for v in (*x_op, *u_op)]
    point = np.array([*x_op, *u_op])
    expected = [tuple(point + sign * step * np.eye(3)[j]) for j, step in enumerate(steps) for sign in (1, -1)]
    assert visited == expected
    np.testing.assert_allclose(A, [[x_op[1], x_op[0]], [0.0, 2 * x_op[1]]], rtol=1e-9)
    np.testing.assert_allclose(B, [[1.0], [0.0]], rtol=1e-9)
    assert np.array_equal(C, np.eye(2))


# --------------------------------------------------------------------------- through the engine


def test_preview_tracks_step_and_moves_before_it() -> None:
    res = run_preview(
        {
            "h2": {"kind": "preview", "design": "h2", "preview": H, "sample_time": TS},
            "hinf": {"kind": "preview", "design": "hinf", "preview": H, "sample_time": TS},
            "no_preview": {"kind": "preview", "design": "h2", "preview": 0, "sample_time": TS},
        }
    )
    first_move = {}
    for run in res.runs:
        assert run.status == "ok", run.reason
        u = run.u[:, 0]
        moved = np.flatnonzero(u != 0.0)
        first_move[run.label] = run.t[moved[0]]
        # zero-order hold over the controller sample: u changes only at t = k Ts
        n_sub = round(TS / 0.01)
        np.testing.assert_array_equal(u, u[(np.arange(u.size) // n_sub) * n_sub])
        y = run.x @ C_ROW
        assert abs(y[-1] - 1.0) < 1e-4
        assert np.max(np.abs(y[run.t >= 12.0] - 1.0)) < 1e-3
        log = dict(zip(run.controller.log_names, run.log.T, strict=True))
        np.testing.assert_allclose(log["u"], u)
        np.testing.assert_allclose(log["preview"] + log["feedback"], u, atol=1e-12)
    assert first_move["h2"] == pytest.approx(STEP_TIME - H * TS)
    assert first_move["hinf"] == pytest.approx(STEP_TIME - H * TS)
    assert first_move["no_preview"] == pytest.approx(STEP_TIME)
    h2 = next(r for r in res.runs if r.label == "h2")
    k = np.searchsorted(h2.t, STEP_TIME - H * TS)
    log = dict(zip(h2.controller.log_names, h2.log.T, strict=True))
    assert log["preview"][k] != 0.0 and log["feedback"][k] == 0.0  # moved by the preview term alone
    designed = next(r for r in res.runs if r.label == "hinf").controller.records
    assert designed["gamma"] == pytest.approx(1.05 * designed["gamma_min"])
    assert any(row["parameter"] == "gamma" for row in res.prepared.tuning)  # recorded in tuning.csv


def test_constant_input_disturbance_is_rejected() -> None:
    res = run_preview(
        {
            "h2": {"kind": "preview", "design": "h2"},
            "hinf": {"kind": "preview", "design": "hinf", "disturbance": True},
        },
        uncertainty={
            "d": {"kind": "disturbance", "amplitude": 0.5, "frequency": 0, "phase": 1.5707963, "states": ["x2"]}
        },
    )
    assert [run.label for run in res.runs] == ["h2", "hinf"]
    for run in res.runs:
        y = run.x @ C_ROW
        assert abs(y[-1] - 1.0) < 1e-3, run.label
        assert run.u[-1, 0] == pytest.approx(1.0 / (3.1472 / 5.3821) - 0.5, abs=1e-3)


def test_sample_time_must_be_a_multiple_of_dt(plant) -> None:
    assert check_sample_time(0.1, 0.01) == 10
    with pytest.raises(ConfigError, match=r"controllers\.p\.sample_time = 0\.1: .* dt = 0\.03"):
        check_sample_time(0.1, 0.03, "controllers.p")
    with pytest.raises(ConfigError, match=r"controllers\.p\.sample_time = 0\.1: must be a whole multiple"):
        Preview().build("p", PreviewConfig(), plant, "controllers.p", dt=0.03)
    # the engine passes dt to build, so a run with such a step is a one-line config error
    with pytest.raises(ConfigError, match=r"controllers\.p\.sample_time = 0\.1: .* dt = 0\.03"):
        run_preview({"p": {"kind": "preview", "design": "h2"}}, t_end=0.9, dt=0.03)


def test_config_errors(plant) -> None:
    with pytest.raises(
        ConfigError, match=r"controllers\.p\.signal = 'nope': not an output of transfer_function; allowed: y"
    ):
        Preview().build("p", PreviewConfig(signal="nope"), plant, "controllers.p")
    with pytest.raises(ConfigError, match=r"controllers\.p\.design = 'h3': allowed values: 'h2' or 'hinf'"):
        run_preview({"p": {"kind": "preview", "design": "h3"}})
    with pytest.raises(ConfigError, match=r"controllers\.p\.preview = -1: must be greater than or equal to 0"):
        run_preview({"p": {"kind": "preview", "preview": -1}})


def test_nonlinear_plant_is_linearised() -> None:
    """The x pendulum (linearised about upright) follows a previewed cart step, pendulum kept up."""
    raw = {
        "name": "preview_pendulum",
        "plant": {"name": "x_pendulum", "x0": {"theta": 0.05}},
        "controllers": {
            "hinf": {"kind": "preview", "signal": "x", "sample_time": 0.02, "preview": 25, "r": 0.01},
        },
        "reference": {"x": {"kind": "step", "time": 2.0, "final": 0.2}},
        "simulation": {"t_end": 10.0, "dt": 0.002},
    }
    (run,) = engine.run_experiment(config.build(raw)).runs
    assert run.status == "ok", run.reason
    assert abs(run.x[-1, 0] - 0.2) < 1e-3
    assert np.max(np.abs(run.x[:, 2])) <= 0.05 + 1e-9

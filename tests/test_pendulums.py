"""The four pendulums (derived equations) checked by their laws: energy, power, equilibrium,
linearisation and symmetry; the x-y model's x/y asymmetry is quantified."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nlcx import config, engine
from nlcx.plants.base import evaluate_rhs
from nlcx.plants.pendulum import PendulumModel, PendulumParams
from nlcx.plants.x_pendulum import XPendulum, x_pendulum_rhs
from nlcx.plants.xy_pendulum import XYPendulum, xy_printed_rhs
from nlcx.plants.xyz_pendulum import XYZPendulum, xyz_printed_rhs
from nlcx.plants.xz_pendulum import XZPendulum, xz_printed_rhs

P = PendulumParams()
M, m, l, g = P.M, P.m, P.l, P.g
PV = np.array([M, m, l, g])
W = (M + m) * g  # the gravity-compensating F_z

PLANTS: dict[str, PendulumModel] = {
    "x_pendulum": XPendulum(),
    "xy_pendulum": XYPendulum(),
    "xz_pendulum": XZPendulum(),
    "xyz_pendulum": XYZPendulum(),
}
NO_BOUNDS = {"theta": 1e9, "phi": 1e9}


def names(plant: str) -> list[str]:
    return [s.name for s in PLANTS[plant].states]


def inputs(plant: str) -> list[str]:
    return [s.name for s in PLANTS[plant].inputs]


def open_loop(
    plant: str,
    forces: dict[str, dict[str, Any]],
    x0: dict[str, float],
    t_end: float,
    dt: float = 1e-3,
    params: dict[str, Any] | None = None,
) -> engine.Run:
    """``plant`` driven by the given forces (references of the open-loop controller)."""
    bounds = {k: v for k, v in NO_BOUNDS.items() if k in names(plant)}
    raw = {
        "name": "pendulum_test",
        "plant": {"name": plant, "x0": x0, "params": params or {}},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {f: forces.get(f, {"kind": "constant", "value": 0.0}) for f in inputs(plant)},
        "simulation": {"t_end": t_end, "dt": dt, "bounds": bounds},
    }
    (run,) = engine.run_experiment(config.build(copy.deepcopy(raw))).runs
    assert run.status == "ok", run.reason
    return run


def rhs(plant: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return evaluate_rhs(PLANTS[plant].rhs, x, u, PV)


def energy(plant: str, x: np.ndarray) -> np.ndarray:
    return PLANTS[plant].energy(P)(x)


def cos_theta(plant: str, x: np.ndarray) -> np.ndarray:
    return np.cos(x[:, names(plant).index("theta")])


# Free oscillations: the x pendulum falls and swings through; the spherical ones swing about
# the hanging position theta = pi (cos(theta) stays near -1, away from the singular 0).
FREE_X0 = {
    "x_pendulum": {"theta": 0.4, "x_dot": 0.3},
    "xy_pendulum": {"theta": math.pi - 0.4, "phi": 0.3, "theta_dot": 0.5, "phi_dot": -0.8, "x_dot": 0.3},
    "xz_pendulum": {"theta": 0.4, "theta_dot": 1.0, "x_dot": 0.3, "z_dot": 0.5},
    "xyz_pendulum": {
        "theta": math.pi - 0.4, "phi": 0.3, "theta_dot": 0.5, "phi_dot": -0.8, "x_dot": 0.3, "y_dot": -0.2,
    },
}  # fmt: skip


@pytest.mark.parametrize("plant", list(PLANTS))
def test_zero_force_conserves_energy(plant: str) -> None:
    """F = 0: E = T + V constant to 1e-6 relative over 10 s (the base free-falls where it has z)."""
    x0 = dict(FREE_X0[plant])
    if plant == "xyz_pendulum":  # in free fall the rod turns freely: keep it slow, off cos(theta) = 0
        x0.update(theta_dot=0.03, phi_dot=-0.04)
    run = open_loop(plant, {}, x0, t_end=10.0)
    E = energy(plant, run.x)
    assert np.max(np.abs(E - E[0])) / abs(E[0]) < 1e-6
    if "z" in names(plant):
        assert run.x[-1, names(plant).index("z")] < -400  # it did fall: -g t^2 / 2 = -490 m
    if "phi" in names(plant):
        assert np.min(np.abs(cos_theta(plant, run.x))) > 0.5
    else:
        assert np.ptp(run.x[:, names(plant).index("theta")]) > 2.0


@pytest.mark.parametrize("plant", ["xz_pendulum", "xyz_pendulum"])
def test_constant_lift_conserves_energy_minus_work(plant: str) -> None:
    """F_z = (M+m) g held: E - F_z z is conserved (a constant force has potential -F_z z)."""
    run = open_loop(plant, {"F_z": {"kind": "constant", "value": W}}, FREE_X0[plant], t_end=10.0)
    z = run.x[:, names(plant).index("z")]
    E = energy(plant, run.x) - W * z
    assert np.max(np.abs(E - E[0])) / abs(E[0]) < 1e-6
    assert np.ptp(run.x[:, names(plant).index("theta")]) > 0.5


FORCES = {
    "F_x": {"kind": "sine", "amplitude": 2.0, "frequency": 0.7, "offset": 0.3},
    "F_y": {"kind": "sine", "amplitude": 1.5, "frequency": 1.1, "phase": 0.5, "offset": -0.2},
    "F_z": {"kind": "sine", "amplitude": 3.0, "frequency": 0.9, "offset": W},
}
FORCED_X0 = {
    "x_pendulum": {"theta": 0.2},
    "xy_pendulum": {"theta": math.pi - 0.3, "phi": 0.2},
    "xz_pendulum": {"theta": 0.2},
    "xyz_pendulum": {"theta": math.pi - 0.3, "phi": 0.2},
}


@pytest.mark.parametrize("plant", list(PLANTS))
def test_forced_power_balance(plant: str) -> None:
    """dE/dt = sum F_i q_i' (Theorems 2.1, 3.1, 3.2, 4.1): over each step, where the forces
    are held, Delta E = sum_i F_i Delta q_i."""
    run = open_loop(plant, FORCES, FORCED_X0[plant], t_end=5.0)
    E = energy(plant, run.x)
    axes = [names(plant).index(f[2:]) for f in inputs(plant)]
    work = np.sum(run.u[:-1] * np.diff(run.x[:, axes], axis=0), axis=1)
    assert np.max(np.abs(work)) > 1e-3
    assert np.max(np.abs(np.diff(E) - work)) < 1e-8 * np.max(np.abs(work))
    assert np.max(np.abs((E[1:] - E[0]) - np.cumsum(work))) < 1e-8 * np.max(np.abs(E - E[0]))
    if "phi" in names(plant):
        assert np.min(np.abs(cos_theta(plant, run.x))) > 0.5
    # the plant's power P(x, u) = sum F_i v_i integrates (trapezoid, forces held) to Delta E
    power = PLANTS[plant].power(P)
    u_held = run.u[:-1]
    p_trap = 0.5 * (power(run.x[:-1], u_held) + power(run.x[1:], u_held)) * np.diff(run.t)
    assert np.max(np.abs(np.cumsum(p_trap) - (E[1:] - E[0]))) < 1e-5 * np.max(np.abs(E - E[0]))


@pytest.mark.parametrize("plant", list(PLANTS))
def test_upright_equilibrium(plant: str) -> None:
    """theta = phi = 0 at rest with F_z = (M+m) g (zero forces otherwise): rhs = 0 at any base position."""
    u = np.array([W if f == "F_z" else 0.0 for f in inputs(plant)])
    for pos in (-2.0, 0.0, 3.5):
        x = np.zeros(len(names(plant)))
        x[0::2] = pos
        x[names(plant).index("theta")] = 0.0
        if "phi" in names(plant):
            x[names(plant).index("phi")] = 0.0
        assert np.max(np.abs(rhs(plant, x, u))) < 1e-12


def linearisation(plant: str) -> tuple[np.ndarray, np.ndarray]:
    """A, B about the upright rest state, derived by hand from the small-angle Lagrange equations

    (M+m) x'' + m l theta'' = F_x,  l theta'' + x'' - g theta = 0   (the same for y, phi, F_y)
    (M+m) z'' = F_z - (M+m) g,

    i.e. x'' = (F_x - m g theta) / M, theta'' = ((M+m) g theta - F_x) / (M l), z'' = dF_z / (M+m).
    """
    n = names(plant)
    A = np.zeros((len(n), len(n)))
    B = np.zeros((len(n), len(inputs(plant))))
    for i in range(0, len(n), 2):
        A[i, i + 1] = 1.0
    for pos, ang, force in (("x", "theta", "F_x"), ("y", "phi", "F_y")):
        if pos not in n:
            continue
        p_dot, a, a_dot = n.index(pos + "_dot"), n.index(ang), n.index(ang + "_dot")
        j = inputs(plant).index(force)
        A[p_dot, a] = -m * g / M
        A[a_dot, a] = (M + m) * g / (M * l)
        B[p_dot, j] = 1 / M
        B[a_dot, j] = -1 / (M * l)
    if "z" in n:
        B[n.index("z_dot"), inputs(plant).index("F_z")] = 1 / (M + m)
    return A, B


@pytest.mark.parametrize("plant", list(PLANTS))
def test_jacobian_matches_hand_linearisation(plant: str) -> None:
    n, k = len(names(plant)), len(inputs(plant))
    u0 = np.array([W if f == "F_z" else 0.0 for f in inputs(plant)])
    x0 = np.zeros(n)
    h = 1e-6
    A_num = np.column_stack([rhs(plant, x0 + e, u0) - rhs(plant, x0 - e, u0) for e in h * np.eye(n)])
    B_num = np.column_stack([rhs(plant, x0, u0 + e) - rhs(plant, x0, u0 - e) for e in h * np.eye(k)])
    A_num, B_num = A_num / (2 * h), B_num / (2 * h)
    A, B = linearisation(plant)
    assert np.max(np.abs(A_num - A)) < 1e-7
    assert np.max(np.abs(B_num - B)) < 1e-7


@pytest.mark.parametrize("plant", list(PLANTS))
def test_small_angles_follow_the_linearisation(plant: str) -> None:
    """Angles 1e-3 rad and small forces: the nonlinear response matches the hand-derived linear model.

    The unstable angles grow about 16-fold in 0.6 s; angles and horizontal positions then
    differ from the linear model by < 1e-3 relative. z is driven only by dF_z at first order;
    the pendulum moves it at second order in the angles, so its error is bounded by l angle^2.
    """
    n = names(plant)
    t_end = 0.6
    x0 = {a: 1e-3 for a in ("theta", "phi") if a in n}
    dF = {"F_x": 1e-3, "F_y": -2e-3, "F_z": 1e-3}
    forces = {f: {"kind": "constant", "value": dF[f] + (W if f == "F_z" else 0.0)} for f in inputs(plant)}
    run = open_loop(plant, forces, x0, t_end=t_end)
    A, B = linearisation(plant)
    du = np.array([dF[f] for f in inputs(plant)])
    xi = np.array([x0.get(s, 0.0) for s in n])
    lin = solve_ivp(lambda t, x: A @ x + B @ du, (0, t_end), xi, t_eval=run.t, rtol=1e-11, atol=1e-14)
    angle = max(np.max(np.abs(lin.y[n.index(a)])) for a in x0)
    assert angle > 1e-2
    for s in ("theta", "phi", "x", "y"):
        if s in n:
            ref = lin.y[n.index(s)]
            assert np.max(np.abs(run.x[:, n.index(s)] - ref)) / np.max(np.abs(ref)) < 1e-3
    if "z" in n:
        ref = lin.y[n.index("z")]
        assert np.max(np.abs(ref)) > 1e-4
        assert np.max(np.abs(run.x[:, n.index("z")] - ref)) < l * angle**2


def mirror(plant: str, axis: str, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pos, angle, force) -> (-pos, -angle, -force) with their rates, for axis x (theta) or y (phi)."""
    ang = {"x": "theta", "y": "phi"}[axis]
    x, u = x.copy(), u.copy()
    for s in (axis, axis + "_dot", ang, ang + "_dot"):
        x[names(plant).index(s)] *= -1
    u[inputs(plant).index("F_" + axis)] *= -1
    return x, u


@pytest.mark.parametrize(
    ("plant", "axis"),
    [("xy_pendulum", "x"), ("xy_pendulum", "y"), ("xyz_pendulum", "x"), ("xyz_pendulum", "y")],
)
def test_mirror_symmetry(plant: str, axis: str) -> None:
    """(x, theta, F_x) -> (-x, -theta, -F_x) (and likewise y, phi, F_y) maps solutions to solutions."""
    rng = np.random.default_rng(5)
    for _ in range(50):
        x = rng.uniform(-0.6, 0.6, len(names(plant)))
        u = rng.uniform(-5, 5, len(inputs(plant)))
        xm, um = mirror(plant, axis, x, u)
        dxm, _ = mirror(plant, axis, rhs(plant, x, u), u)
        assert np.allclose(rhs(plant, xm, um), dxm, rtol=0, atol=1e-13)


def test_xy_single_axis_motion_is_the_same_in_x_and_y() -> None:
    """Excited along x only (theta0, F_x) or along y only (phi0, F_y), the responses coincide."""
    f = {"kind": "sine", "amplitude": 0.5, "frequency": 1.0}
    rx = open_loop("xy_pendulum", {"F_x": f}, {"theta": 0.1}, t_end=1.0)
    ry = open_loop("xy_pendulum", {"F_y": f}, {"phi": 0.1}, t_end=1.0)
    assert np.max(np.abs(rx.x[:, [2, 3, 6, 7]])) == 0.0  # y, phi stay exactly 0
    assert np.max(np.abs(ry.x[:, [0, 1, 4, 5]])) == 0.0  # x, theta stay exactly 0
    assert np.max(np.abs(rx.x[:, 4])) > 0.5  # it fell a long way
    assert np.allclose(rx.x[:, [0, 1, 4, 5]], ry.x[:, [2, 3, 6, 7]], rtol=0, atol=1e-12)


def diagonal_mismatch(a: float) -> tuple[float, float]:
    """Identical initial angles theta0 = phi0 = a and forces F_x = F_y for 0.5 s: the relative
    mismatch max|x - y| / max|x| and max|theta - phi| / max|theta|."""
    f = {"kind": "sine", "amplitude": 5 * a, "frequency": 1.0}
    run = open_loop("xy_pendulum", {"F_x": f, "F_y": f}, {"theta": a, "phi": a}, t_end=0.5)
    x, y, theta, phi = run.x[:, 0], run.x[:, 2], run.x[:, 4], run.x[:, 6]
    return (
        float(np.max(np.abs(x - y)) / np.max(np.abs(x))),
        float(np.max(np.abs(theta - phi)) / np.max(np.abs(theta))),
    )


def test_xy_asymmetry_is_second_order() -> None:
    """Eqs. 3.1a-b are not symmetric in (x, theta) and (y, phi): driven identically in both
    directions, x = y and theta = phi fail, by a relative amount that is second order in the
    amplitude (halving it divides the mismatch by about 4). With a = 0.02 rad (angles reach
    0.15 rad in 0.5 s) the mismatch is about 3e-4 in position and 1e-2 in angle."""
    pos_big, ang_big = diagonal_mismatch(0.02)
    pos_small, ang_small = diagonal_mismatch(0.01)
    assert 1e-4 < pos_big < 1e-3
    assert 5e-3 < ang_big < 5e-2
    assert 3.5 < pos_big / pos_small < 4.5
    assert 3.5 < ang_big / ang_small < 4.5


def test_plant_metadata() -> None:
    xyz = XYZPendulum()
    assert [s.name for s in xyz.states] == [
        "x", "x_dot", "y", "y_dot", "z", "z_dot", "theta", "theta_dot", "phi", "phi_dot",
    ]  # fmt: skip
    assert xyz.outputs == ("x", "y", "z", "theta", "phi")
    assert dict(xyz.loop_inputs) == {"x": "F_x", "theta": "F_x", "y": "F_y", "phi": "F_y", "z": "F_z"}
    assert dict(xyz.input_axes) == {"F_x": "x_dot", "F_y": "y_dot", "F_z": "z_dot"}
    assert [s.label for s in xyz.inputs] == ["Force F_x", "Force F_y", "Force F_z"]
    assert XZPendulum().outputs == ("x", "z", "theta")
    assert XYPendulum().outputs == ("x", "y", "theta", "phi")
    for model in PLANTS.values():
        assert model.weight(P) == pytest.approx(W)
        assert set(model.velocity_states) == {s.name for s in model.states[1::2]}
        assert all(v == math.pi / 2 for v in model.default_bounds.values())


@pytest.mark.parametrize(
    ("plant", "printed", "printed_differs"),
    [
        ("x_pendulum", x_pendulum_rhs, False),  # eqs. 2.8-2.11 agree with the derived ones (to rounding)
        ("xy_pendulum", xy_printed_rhs, True),
        ("xz_pendulum", xz_printed_rhs, True),
        ("xyz_pendulum", xyz_printed_rhs, True),
    ],
)
def test_equations_parameter_selects_the_variant(plant: str, printed: Any, printed_differs: bool) -> None:
    """``equations: printed`` builds the printed right-hand side, and a run with it (and m = 0.2)
    follows that right-hand side integrated here by scipy, not the derived one where they differ."""
    model = PLANTS[plant]
    built = model.build(plant, PendulumParams(equations="printed"), {}, {})
    assert built.rhs is printed
    assert model.build(plant, PendulumParams(), {}, {}).rhs is model.rhs
    assert built.params["equations"] == "printed"
    force = {f: {"kind": "constant", "value": 0.5} for f in inputs(plant)}
    run = open_loop(plant, force, FREE_X0[plant], t_end=0.2, params={"equations": "printed", "m": 0.2})
    pv, u = np.array([M, 0.2, l, g]), np.full(len(inputs(plant)), 0.5)

    def integrated(rhs: Any) -> np.ndarray:
        sol = solve_ivp(
            lambda t, x: evaluate_rhs(rhs, x, u, pv), (0, 0.2), run.x[0], t_eval=run.t, rtol=1e-11, atol=1e-12
        )
        return sol.y.T

    assert run.x[0] == pytest.approx([FREE_X0[plant].get(name, 0.0) for name in names(plant)])
    np.testing.assert_allclose(run.x, integrated(printed), rtol=0, atol=1e-8)
    assert (np.max(np.abs(run.x - integrated(model.rhs))) > 1e-4) == printed_differs

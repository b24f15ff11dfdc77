"""The x pendulum (eqs. 2.8-2.11) checked by its laws, not by its printed formulas."""

from __future__ import annotations

import math

import numpy as np
from conftest import open_loop_pendulum
from scipy.integrate import solve_ivp

from nlcx.plants.base import evaluate_rhs
from nlcx.plants.x_pendulum import XPendulum, XPendulumParams, x_pendulum_rhs

P = XPendulumParams()
M, m, l, g = P.M, P.m, P.l, P.g


def f(x: np.ndarray, F: float) -> np.ndarray:
    return evaluate_rhs(x_pendulum_rhs, x, [F], [M, m, l, g])


def test_upright_equilibrium_at_any_base_position() -> None:
    for x_pos in (-2.0, 0.0, 3.5):
        assert np.array_equal(f(np.array([x_pos, 0.0, 0.0, 0.0]), 0.0), np.zeros(4))


def test_upright_equilibrium_is_unstable_and_hanging_is_a_centre() -> None:
    """Eigenvalues of the Jacobian: +-sqrt((M+m)g/(Ml)) upright, purely imaginary hanging."""

    def jac(x0: np.ndarray) -> np.ndarray:
        h = 1e-6
        return np.column_stack([(f(x0 + h * e, 0) - f(x0 - h * e, 0)) / (2 * h) for e in np.eye(4)])

    lam_up = np.sort(np.linalg.eigvals(jac(np.zeros(4))).real)
    expected = math.sqrt((M + m) * g / (M * l))
    assert abs(lam_up[-1] - expected) < 1e-6
    lam_down = np.linalg.eigvals(jac(np.array([0.0, 0.0, math.pi, 0.0])))
    assert np.max(np.abs(lam_down.real)) < 1e-6
    assert abs(np.max(lam_down.imag) - math.sqrt((M + m) * g / (M * l))) < 1e-6


def test_mirror_symmetry() -> None:
    """(x, theta, F) -> (-x, -theta, -F) negates the accelerations."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        x = rng.normal(size=4)
        F = rng.normal()
        assert np.allclose(f(-x, -F), -f(x, F), rtol=0, atol=1e-13)


def test_zero_force_conserves_energy() -> None:
    """With F = 0 the energy V of eq. 2.24 is constant: 1e-6 relative over 10 s."""
    run = open_loop_pendulum(None, {"theta": 0.4, "x_dot": 0.3}, t_end=10.0)
    energy = XPendulum().energy(P)
    E = energy(run.x)
    assert run.status == "ok"
    assert abs(run.x[:, 2]).max() > 2.0  # it really fell and swung through
    assert np.max(np.abs(E - E[0])) / abs(E[0]) < 1e-6


def test_forced_power_balance_theorem_2_1() -> None:
    """dV/dt = F_x x_dot (eq. 2.31): over each step, where F_x is held, Delta V = F_x Delta x."""
    run = open_loop_pendulum(
        {"kind": "sine", "amplitude": 2.0, "frequency": 0.7, "offset": 0.3}, {"theta": 0.2}, t_end=5.0
    )
    E = XPendulum().energy(P)(run.x)
    work = run.u[:-1, 0] * np.diff(run.x[:, 0])
    assert np.max(np.abs(work)) > 1e-4
    assert np.max(np.abs(np.diff(E) - work)) < 1e-9 * np.max(np.abs(work))
    # and accumulated: V(t) - V(0) is the work done by F_x
    assert np.max(np.abs((E[1:] - E[0]) - np.cumsum(work))) < 1e-8 * np.max(np.abs(E - E[0]))


def test_small_angles_follow_the_linearisation() -> None:
    """theta0 = 1e-3 rad, small force: the nonlinear response matches the linear model of eq. 2.7."""
    F0 = 1e-3
    run = open_loop_pendulum({"kind": "constant", "value": F0}, {"theta": 1e-3}, t_end=1.0)
    A = np.array(
        [
            [0, 1, 0, 0],
            [0, 0, -m * g / M, 0],
            [0, 0, 0, 1],
            [0, 0, (M + m) * g / (M * l), 0],
        ]
    )
    B = np.array([0, 1 / M, 0, -1 / (M * l)])
    lin = solve_ivp(lambda t, x: A @ x + B * F0, (0, 1.0), [0, 0, 1e-3, 0], t_eval=run.t, rtol=1e-11, atol=1e-14)
    theta_lin = lin.y[2]
    err = np.max(np.abs(run.x[:, 2] - theta_lin))
    amp = np.max(np.abs(theta_lin))
    assert amp > 1e-2  # the instability grew the angle ten-fold
    assert err / amp < 5e-3  # difference is second order in the (small) angle

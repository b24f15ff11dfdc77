"""The x inverted pendulum: a base moving along x carrying a rod pivoted on it (thesis ch. 2).

States x1..x4 = (x, x_dot, theta, theta_dot), input F_x, outputs x and theta.
Parameters of Table 2.1: base mass M, pendulum mass m, distance l from pivot to the
pendulum's centre of mass (the rod is 2l long), gravity g.

``equations: derived`` (default) integrates the Euler-Lagrange equations of the Lagrangian
2.6 (generated, :func:`nlcx.plants.generated.pendulums.x_derived_rhs`); ``equations:
printed`` the printed state equations 2.8-2.11 (:func:`x_pendulum_rhs`). For this pendulum
the two agree (to rounding).
"""

from __future__ import annotations

from types import MappingProxyType

from numba import njit

from nlcx._numba_compat import hot_njit
from nlcx.kernel.signatures import FloatArray
from nlcx.kernel.trig import COLUMN_ROWS, sincos, sincos_column
from nlcx.plants.generated.pendulums import x_derived_rhs, x_energy
from nlcx.plants.pendulum import (
    ANGLE_BOUND,
    PARAMS,
    PendulumModel,
    PendulumParams,
    coordinate_signals,
    force_signals,
)

P = PARAMS.at


class XPendulumParams(PendulumParams):
    """Table 2.1 parameters."""


@njit(cache=True, inline="always", error_model="numpy")
def _x_printed_column(
    b: int, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, s: float, c: float
) -> None:  # pragma: no cover - compiled
    """Eqs. 2.8-2.11 as printed for column (variant) b: p[:, b] = (M, m, l, g), u[:, b] = (F_x,),
    s and c the sine and cosine of its theta."""
    M, m, l, g = p[P.M, b], p[P.m, b], p[P.l, b], p[P.g, b]
    theta_dot = x[3, b]
    F = u[0, b]
    den = M + m * s * s
    dx[0, b] = x[1, b]  # eq. 2.8
    dx[1, b] = (-m * g * c * s + m * l * s * theta_dot * theta_dot + F) / den  # eq. 2.9
    dx[2, b] = theta_dot  # eq. 2.10
    dx[3, b] = (-m * l * c * s * theta_dot * theta_dot - c * F + (M + m) * g * s) / (l * den)  # eq. 2.11


@hot_njit(cache=True, error_model="numpy")
def x_pendulum_rhs(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, nb: int
) -> None:  # pragma: no cover - compiled
    """Eqs. 2.8-2.11 as printed, for each of the first nb columns (variants) of x.

    sin and cos of theta from nlcx.kernel.trig as for the derived equations: for the whole
    batch in vector code, or one at a time for fewer than COLUMN_ROWS variants."""
    if nb < COLUMN_ROWS:
        for b in range(nb):
            s, c = sincos(x[2, b])
            _x_printed_column(b, x, u, p, dx, s, c)
        return
    sincos_column(x[2], nb, dx[1], dx[3])  # rows the column writes after reading them
    for b in range(nb):
        _x_printed_column(b, x, u, p, dx, dx[1, b], dx[3, b])


#: The printed variant under the name the other pendulums use.
x_printed_rhs = x_pendulum_rhs


class XPendulum(PendulumModel):
    """x inverted pendulum, Lagrangian eq. 2.6 (state equations 2.8-2.11; Table 2.1 parameters)."""

    Params = XPendulumParams
    states = coordinate_signals("x", "theta")
    inputs = force_signals("x")
    loop_inputs = MappingProxyType({"x": "F_x", "theta": "F_x"})
    input_axes = MappingProxyType({"F_x": "x_dot"})
    outputs = ("x", "theta")
    velocity_states = ("x_dot", "theta_dot")
    default_bounds = MappingProxyType({"theta": ANGLE_BOUND})
    rhs = staticmethod(x_derived_rhs)
    printed_rhs = staticmethod(x_pendulum_rhs)
    energy_function = staticmethod(x_energy)

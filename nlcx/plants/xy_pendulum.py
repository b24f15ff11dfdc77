"""The x-y (spherical) inverted pendulum: a base moving in the horizontal xy plane (thesis 3.2).

States x1..x8 = (x, x_dot, y, y_dot, theta, theta_dot, phi, phi_dot), inputs F_x and F_y,
outputs x, y, theta and phi. theta is the rod's angle in the xz plane, phi its angle towards
y (eq. 3.1: y_p = y + l cos(theta) sin(phi)); the coordinates are singular at cos(theta) = 0.

``equations: derived`` (default) integrates the Euler-Lagrange equations of the Lagrangian
3.6 (generated, :func:`nlcx.plants.generated.pendulums.xy_derived_rhs`); ``equations:
printed`` the printed state equations 3.11-3.18 (:func:`xy_printed_rhs`), which disagree
with the Lagrangian (docs/errata.md).
"""

from __future__ import annotations

from types import MappingProxyType

from numba import njit

from nlcx.kernel.signatures import FloatArray
from nlcx.kernel.trig import sincos
from nlcx.plants.generated.pendulums import xy_derived_rhs, xy_energy
from nlcx.plants.pendulum import (
    ANGLE_BOUND,
    PARAMS,
    PendulumModel,
    by_variant,
    coordinate_signals,
    force_signals,
)

P = PARAMS.at


@njit(cache=True, error_model="numpy")
def _xy_printed_row(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray
) -> None:  # pragma: no cover - compiled
    """Eqs. 3.11-3.18 transcribed literally (typos included), p = (M, m, l, g), u = (F_x, F_y)."""
    M, m, l, g = p[P.M], p[P.m], p[P.l], p[P.g]
    F_x, F_y = u[0], u[1]
    x6, x8 = x[5], x[7]
    s5, c5 = sincos(x[4])
    s7, c7 = sincos(x[6])
    den = M * M + M * m * s5**2 * c7**2 + M * m * s7**2
    dx[0] = x[1]  # eq. 3.11
    dx[1] = (  # eq. 3.12
        M * m * l * s5 * x6**2
        + M * m * l * c5**2 * s5 * x8**2
        - M * m * g * c5**2 * s5 * c7**2
        + m * c5**2 * s7**2 * F_x
        + M * F_x
        - m * c5**2 * s5 * s7 * F_y
    ) / den
    dx[2] = x[3]  # eq. 3.13
    dx[3] = (  # eq. 3.14
        (M + m) * F_y
        - m * c5**2 * F_y
        + m * s5 * c5 * s7 * F_x
        - M * m * g * c5**2 * s7 * c7
        + M * m * l * c5**3 * s7 * x8**2
        - M * m * l * c5 * s7 * x6**2
    ) / den
    dx[4] = x[5]  # eq. 3.15
    dx[5] = (  # eq. 3.16
        m * c5 * c7**2 * F_x
        - (M + m) * c5 * F_x
        + (M + m) * s5 * s7 * F_y
        + M * (m + M) * g * s5 * c7
        - M * m * l * s5 * c5 * c7**2 * x6**2
        - M * (m + M) * l * c5 * s7 * x8**2
    ) / (den * l)
    dx[6] = x[7]  # eq. 3.17
    dx[7] = (  # eq. 3.18 (its denominator has no factor l)
        -m * s5**2 * c7 * F_y
        - M * c7 * F_y
        + m * s5 * c5 * s7 * c7 * F_x
        + 2 * M * m * l * s5 * x6 * x8
        + M * (m + M) * g * s7
        + 2 * M**2 * l * s5 * x6 * x8
        - 2 * M * m * l * s5 * c5**2 * c7**2 * x6 * x8
        - M * m * l * c5**3 * s7 * c7 * x8**2
        - M * m * l * c5 * s7 * c7 * x6**2
    ) / den


@njit(cache=True, error_model="numpy")
def xy_printed_rhs(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, nb: int
) -> None:  # pragma: no cover - compiled
    """The printed equations for each of the first nb columns (variants) b of x (one variant:
    :func:`_xy_printed_row`)."""
    by_variant(_xy_printed_row, t, x, u, p, dx, nb)


class XYPendulum(PendulumModel):
    """x-y inverted pendulum, Lagrangian eq. 3.6 (state equations 3.11-3.18; Table 2.1 parameters)."""

    states = coordinate_signals("x", "y", "theta", "phi")
    inputs = force_signals("x", "y")
    loop_inputs = MappingProxyType({"x": "F_x", "theta": "F_x", "y": "F_y", "phi": "F_y"})
    input_axes = MappingProxyType({"F_x": "x_dot", "F_y": "y_dot"})
    outputs = ("x", "y", "theta", "phi")
    velocity_states = ("x_dot", "y_dot", "theta_dot", "phi_dot")
    default_bounds = MappingProxyType({"theta": ANGLE_BOUND, "phi": ANGLE_BOUND})
    rhs = staticmethod(xy_derived_rhs)
    printed_rhs = staticmethod(xy_printed_rhs)
    energy_function = staticmethod(xy_energy)

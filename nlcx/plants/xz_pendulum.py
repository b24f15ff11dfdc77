"""The x-z inverted pendulum: a base moving horizontally (x) and vertically (z) (thesis 3.6).

States x1..x6 = (x, x_dot, z, z_dot, theta, theta_dot), inputs F_x and F_z, outputs x, z
and theta. Gravity acts on the base too (P.E. = M g z + m g z_p, eq. 3.36b): the base holds
its height with F_z = (M + m) g and free-falls with F_z = 0.

``equations: derived`` (default) integrates the Euler-Lagrange equations of the Lagrangian
3.38 as its energies 3.36-3.37 define it (generated,
:func:`nlcx.plants.generated.pendulums.xz_derived_rhs`); ``equations: printed`` the
printed state equations 3.42-3.47 (:func:`xz_printed_rhs`), which disagree with the
Lagrangian (docs/errata.md).
"""

from __future__ import annotations

from types import MappingProxyType

from numba import njit

from nlcx.kernel.signatures import FloatArray
from nlcx.kernel.trig import sincos
from nlcx.plants.generated.pendulums import xz_derived_rhs, xz_energy
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
def _xz_printed_row(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray
) -> None:  # pragma: no cover - compiled
    """Eqs. 3.42-3.47 transcribed literally (typos included), p = (M, m, l, g), u = (F_x, F_z).

    The printed equations write theta and theta_dot for x5 and x6.
    """
    M, m, l, g = p[P.M], p[P.m], p[P.l], p[P.g]
    F_x, F_z = u[0], u[1]
    theta, theta_dot = x[4], x[5]
    s, c = sincos(theta)
    dx[0] = x[1]  # eq. 3.42
    dx[1] = (  # eq. 3.43
        -m * s * c * F_z + F_x * (M + m - m * s**2) + M * m * l * s * theta_dot**2
    ) / (M * (M + m))
    dx[2] = x[3]  # eq. 3.44
    dx[3] = (  # eq. 3.45
        m * F_z * (1 - c**2) - m * s * c * F_x + M * (F_z - M * g) + M * m * l * c * theta_dot**2
    ) / (M * (M + m))
    dx[4] = x[5]  # eq. 3.46
    dx[5] = (-c * F_x + s * F_z) / (M * l)  # eq. 3.47


@njit(cache=True, error_model="numpy")
def xz_printed_rhs(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, nb: int
) -> None:  # pragma: no cover - compiled
    """The printed equations for each of the first nb columns (variants) b of x (one variant:
    :func:`_xz_printed_row`)."""
    by_variant(_xz_printed_row, t, x, u, p, dx, nb)


class XZPendulum(PendulumModel):
    """x-z inverted pendulum, energies 3.36-3.37 (state equations 3.42-3.47; Table 2.1 parameters)."""

    states = coordinate_signals("x", "z", "theta")
    inputs = force_signals("x", "z")
    loop_inputs = MappingProxyType({"x": "F_x", "theta": "F_x", "z": "F_z"})
    input_axes = MappingProxyType({"F_x": "x_dot", "F_z": "z_dot"})
    outputs = ("x", "z", "theta")
    velocity_states = ("x_dot", "z_dot", "theta_dot")
    default_bounds = MappingProxyType({"theta": ANGLE_BOUND})
    rhs = staticmethod(xz_derived_rhs)
    printed_rhs = staticmethod(xz_printed_rhs)
    energy_function = staticmethod(xz_energy)

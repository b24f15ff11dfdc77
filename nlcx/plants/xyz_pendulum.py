"""The x-y-z inverted pendulum: a base moving in all three directions (thesis ch. 4).

States x1..x10 = (x, x_dot, y, y_dot, z, z_dot, theta, theta_dot, phi, phi_dot), inputs
F_x, F_y and F_z, outputs x, y, z, theta and phi. Gravity acts on the base too (P.E. =
M g z + m g z_p, eq. 4.4b): the base holds its height with F_z = (M + m) g.

``equations: derived`` (default) integrates the Euler-Lagrange equations of the energies
4.4-4.5 (generated, :func:`nlcx.plants.generated.pendulums.xyz_derived_rhs`). Eq. 4.6 prints
an extra "m g z" in the potential energy, which eq. 4.10's (M + m) g contradicts; the
derivation follows 4.4b. ``equations: printed`` integrates the printed state equations
4.18-4.27 (:func:`xyz_printed_rhs`), which disagree with the Lagrangian (docs/errata.md).
"""

from __future__ import annotations

from types import MappingProxyType

from numba import njit

from nlcx.kernel.signatures import FloatArray
from nlcx.kernel.trig import sincos
from nlcx.plants.generated.pendulums import xyz_derived_rhs, xyz_energy
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
def _xyz_printed_row(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray
) -> None:  # pragma: no cover - compiled
    """Eqs. 4.18-4.27 transcribed literally (typos included), p = (M, m, l, g), u = (F_x, F_y, F_z).

    Eq. 4.21 writes sin(theta) for sin(x7); eq. 4.25 has x9^2 where x10^2 is expected.
    """
    M, m, l, g = p[P.M], p[P.m], p[P.l], p[P.g]
    F_x, F_y, F_z = u[0], u[1], u[2]
    x8, x9, x10 = x[7], x[8], x[9]
    s7, c7 = sincos(x[6])
    s9, c9 = sincos(x9)
    dx[0] = x[1]  # eq. 4.18
    dx[1] = (  # eq. 4.19
        (M + m) * F_x
        + m * l * s7 * x8**2 * (M + m * c7**2)
        + (M + m) * m * l * c7**2 * s7 * x10**2
        - m**2 * l * c7**2 * s7 * (x8**2 + x10**2)
        - m * F_y * s9 * c7 * s7
        - m * F_z * c7 * s7
        - m * F_x * s7**2
    ) / (M * (M + m))
    dx[2] = x[3]  # eq. 4.20
    dx[3] = (  # eq. 4.21
        M * m * l * c7 * s9 * (x8**2 + x10**2) * (m * s7**2 + M)
        - M * m * F_z * c7**2 * c9 * s9
        - m * F_x * s7 * c7 * s9 * (M + 2 * m * c9**2)
        - m**2 * l * s7**2 * s9 * c7 * x8**2 * (2 * m * c9**2 + M)
        - (M + m) * m * l * c7 * s7**2 * s9 * x10**2 * (M + 2 * m * c9**2)
        - M * F_y * (-M - m + m * s9**2 * c9**2)
    ) / (M**2 * (M + m))
    dx[4] = x[5]  # eq. 4.22
    dx[5] = (  # eq. 4.23
        M * m * l * c7 * c9 * (x8**2 + x10**2) * (m * s7**2 + M)
        + 2 * m**3 * l * s7**2 * c7 * s9**2 * c9 * x8**2
        + m**2 * M * l * s7**2 * c7 * c9 * x8**2
        - M * m * F_z * c7**2 * c9**2
        + M**2 * F_z
        + M * m * F_z
        - M * m * F_x * s7 * c7 * c9
        - 2 * m**2 * F_x * s7 * c7 * c9**3
        + 2 * m * M * F_x * s7 * c7 * c9
        + 2 * m**2 * F_x * s7 * c7 * c9
        - M * (M + m) * m * l * c7 * s7**2 * c9 * x10**2
        - 2 * m * (m + M) * m * l * c7 * s7**2 * c9**3 * x10**2
        + 2 * m * l * (M + m) ** 2 * c7 * s7**2 * c9 * x10**2
        - M * m * F_y * c7**2 * c9 * s9
        - M**3 * g
        - M**2 * m * g
    ) / (M**2 * (M + m))
    dx[6] = x[7]  # eq. 4.24
    dx[7] = (  # eq. 4.25 (x9^2, not x10^2, in its third term)
        -m * F_x * c7**2
        - m**2 * l * s7 * c7**2 * x8**2
        - (M + m) * m * l * c7**2 * s7 * x9**2
        + m**2 * l * c7**2 * s7 * (x8**2 + x10**2)
        + m * F_y * s9 * c7 * s7
        + m * F_z * c7 * s7 * c9
    ) / (M * m * l * c7)
    dx[8] = x[9]  # eq. 4.26
    dx[9] = (  # eq. 4.27
        M * F_z * s9
        - M * F_y * c9
        + 2 * M**2 * l * s7 * x8 * x10
        + 2 * m * F_x * s7 * s9 * c9 * c7
        + 2 * m**2 * l * s7**2 * c7 * s9 * c9 * x8**2
        + 2 * m * l * (M + m) * c7 * s7**2 * s9 * c9 * x10**2
    ) / (M**2 * l * c7)


@njit(cache=True, error_model="numpy")
def xyz_printed_rhs(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, nb: int
) -> None:  # pragma: no cover - compiled
    """The printed equations for each of the first nb columns (variants) b of x (one variant:
    :func:`_xyz_printed_row`)."""
    by_variant(_xyz_printed_row, t, x, u, p, dx, nb)


class XYZPendulum(PendulumModel):
    """x-y-z inverted pendulum, energies 4.4-4.5 (state equations 4.18-4.27; Table 2.1 parameters)."""

    states = coordinate_signals("x", "y", "z", "theta", "phi")
    inputs = force_signals("x", "y", "z")
    loop_inputs = MappingProxyType({"x": "F_x", "theta": "F_x", "y": "F_y", "phi": "F_y", "z": "F_z"})
    input_axes = MappingProxyType({"F_x": "x_dot", "F_y": "y_dot", "F_z": "z_dot"})
    outputs = ("x", "y", "z", "theta", "phi")
    velocity_states = ("x_dot", "y_dot", "z_dot", "theta_dot", "phi_dot")
    default_bounds = MappingProxyType({"theta": ANGLE_BOUND, "phi": ANGLE_BOUND})
    rhs = staticmethod(xyz_derived_rhs)
    printed_rhs = staticmethod(xyz_printed_rhs)
    energy_function = staticmethod(xyz_energy)

"""The x inverted pendulum: a base moving along x carrying a rod pivoted on it (thesis ch. 2).

States x1..x4 = (x, x_dot, theta, theta_dot), input F_x, outputs x and theta.
Parameters of Table 2.1: base mass M, pendulum mass m, distance l from pivot to the
pendulum's centre of mass (the rod is 2l long), gravity g.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import MappingProxyType

import numpy as np
from numba import njit
from pydantic import Field

from nlcx.kernel import RHS_SIG
from nlcx.plants.base import PlantModel, PlantParams, Signal


class XPendulumParams(PlantParams):
    """Table 2.1 parameters."""

    M: float = Field(1.0, gt=0, description="mass of the base", json_schema_extra={"unit": "kg"})
    m: float = Field(0.1, gt=0, description="mass of the pendulum", json_schema_extra={"unit": "kg"})
    l: float = Field(
        0.3,
        gt=0,
        description="pivot to pendulum centre of mass (half the rod)",
        json_schema_extra={"unit": "m"},
    )
    g: float = Field(
        9.8, gt=0, description="acceleration due to gravity", json_schema_extra={"unit": "m/s^2"}
    )


@njit(RHS_SIG, cache=True)
def x_pendulum_rhs(t, x, u, p, dx):  # pragma: no cover - compiled
    """Eqs. 2.8-2.11 with p = (M, m, l, g) and u = (F_x,)."""
    M, m, l, g = p[0], p[1], p[2], p[3]
    theta, theta_dot = x[2], x[3]
    F = u[0]
    s = math.sin(theta)
    c = math.cos(theta)
    den = M + m * s * s
    dx[0] = x[1]  # eq. 2.8
    dx[1] = (-m * g * c * s + m * l * s * theta_dot * theta_dot + F) / den  # eq. 2.9
    dx[2] = theta_dot  # eq. 2.10
    dx[3] = (-m * l * c * s * theta_dot * theta_dot - c * F + (M + m) * g * s) / (l * den)  # eq. 2.11


class XPendulum(PlantModel):
    """x inverted pendulum, eqs. 2.8-2.11 (Table 2.1 parameters)."""

    Params = XPendulumParams
    states = (
        Signal("x", "m", "Position x"),
        Signal("x_dot", "m/s", "Velocity x"),
        Signal("theta", "rad", "Angle θ"),
        Signal("theta_dot", "rad/s", "Angular velocity θ"),
    )
    inputs = (Signal("F_x", "N", "Force F_x"),)
    loop_inputs = MappingProxyType({"x": "F_x", "theta": "F_x"})
    outputs = ("x", "theta")
    velocity_states = ("x_dot", "theta_dot")
    default_bounds = MappingProxyType({"theta": math.pi / 2})
    rhs = staticmethod(x_pendulum_rhs)

    def parameter_vector(self, params: XPendulumParams) -> np.ndarray:
        return np.array([params.M, params.m, params.l, params.g])

    def energy(self, params: XPendulumParams) -> Callable[[np.ndarray], np.ndarray]:
        """V of eq. 2.24 with z = 0: kinetic plus potential energy (the Lyapunov function)."""
        M, m, l, g = params.M, params.m, params.l, params.g

        def energy(x: np.ndarray) -> np.ndarray:
            x_dot, theta, theta_dot = x[..., 1], x[..., 2], x[..., 3]
            xp_dot = x_dot + l * np.cos(theta) * theta_dot  # eq. 2.1c
            zp_dot = -l * np.sin(theta) * theta_dot  # eq. 2.1d with z_dot = 0
            return 0.5 * M * x_dot**2 + 0.5 * m * (xp_dot**2 + zp_dot**2) + m * g * l * np.cos(theta)

        return energy

    def power(self, params: XPendulumParams) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        """F_x x_dot, the right-hand side of eq. 2.31."""

        def power(x: np.ndarray, u: np.ndarray) -> np.ndarray:
            return u[..., 0] * x[..., 1]

        return power

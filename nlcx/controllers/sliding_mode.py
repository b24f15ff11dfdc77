"""Sliding-mode control of the x pendulum: the hierarchical design of Wang et al. (2004).

W. Wang, J. Yi, D. Zhao and D. Liu, "Design of a stable sliding-mode controller for a class of
second-order underactuated systems", IEE Proceedings - Control Theory and Applications
151(6), 683-690, 2004: the cart (x_1 = x - r, x_2 = dx/dt) and the pendulum (x_3 = θ,
x_4 = dθ/dt) are two subsystems of the form dx_2/dt = f_1 + b_1 F, dx_4/dt = f_2 + b_2 F, with
a first-level sliding surface each and a second-level surface that joins them,

    s_1 = c_1 x_1 + x_2,      s_2 = c_2 x_3 + x_4,      S = α s_1 + s_2,            (1)

and the control that makes dS/dt = -κ S - η sgn(S),

    F = -(α (c_1 x_2 + f_1) + c_2 x_4 + f_2 + κ S + η sat(S / φ)) / (α b_1 + b_2)    (2)

(the equivalent controls of both subsystems and the switching term in one expression). The
sign function is replaced by a saturation over a boundary layer of width φ against chattering
(Slotine and Li, Applied Nonlinear Control, 1991, section 7.2). f and b are those of the x
pendulum's state equations 2.8-2.11, with the design's own parameters M, m, l and g (the model
the design knows, which a sweep of the plant's parameters does not change); θ's reference is
the upright position (0), and x_3 = θ - θ_ref:

    f_1 = (-m g cos θ sin θ + m l sin θ θ'^2) / D,       b_1 = 1 / D,
    f_2 = (-m l cos θ sin θ θ'^2 + (M + m) g sin θ) / (l D),   b_2 = -cos θ / (l D),
    D = M + m sin^2 θ.

The law is written with :func:`nlcx.controllers.law.law_model` and logs the surface S. A
published design exists for this pendulum: the other pendulums and the CSTR have none here.
:func:`surface_for_poles` chooses (c_1, c_2, α) so that the motion on S = 0, linearised, has
three given poles (Ackermann's formula for sliding surfaces: J. Ackermann and V. Utkin,
"Sliding mode control design based on Ackermann's formula", IEEE Transactions on Automatic
Control 43(2), 234-237, 1998); docs/baselines.md states the rule the baselines choose by.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from nlcx.controllers.base import ControllerInstance
from nlcx.controllers.law import LawController, LawShape, law_config, law_model
from nlcx.errors import ConfigError
from nlcx.kernel.signatures import ControllerStep
from nlcx.plants.base import Plant

__all__ = ["SHAPE", "SlidingMode", "sliding_mode_law", "surface_for_poles"]

#: The plant the design is published for.
PLANT = "x_pendulum"

#: What the law reads and writes; the parameters named as Wang et al. (2004) name them.
SHAPE = LawShape(
    name="sliding_mode",
    measures=("x", "x_dot", "theta", "theta_dot"),
    references=("x", "theta"),
    inputs=("F_x",),
    params=(
        ("c1", 0.5, "1/s", "slope of the cart's surface s1 = c1 (x - r) + x_dot (eq. 1)"),
        ("c2", 5.0, "1/s", "slope of the pendulum's surface s2 = c2 theta + theta_dot (eq. 1)"),
        ("alpha", -0.5, "", "weight alpha of the cart's surface in S = alpha s1 + s2 (eq. 1)"),
        ("kappa", 2.0, "1/s", "proportional reaching rate kappa of dS/dt = -kappa S - eta sat(S/phi) (eq. 2)"),
        ("eta", 0.5, "1/s^2", "switching gain eta (eq. 2)"),
        ("phi", 0.05, "1/s", "width phi of the boundary layer around S = 0"),
        ("M", 1.0, "kg", "the design model's base mass"),
        ("m", 0.1, "kg", "the design model's pendulum mass"),
        ("l", 0.3, "m", "the design model's pivot to pendulum centre of mass"),
        ("g", 9.8, "m/s^2", "the design model's gravity"),
    ),
    signals=("S",),
)


def sliding_mode_law(
    t: float, dt: float, y: tuple[float, ...], r: tuple[float, ...], s: tuple[float, ...], p: Any
) -> tuple[tuple[float], tuple[()], tuple[float]]:  # pragma: no cover - compiled
    """Eqs. 1-2 for one variant: y = (x, x_dot, theta, theta_dot), r = (x_ref, theta_ref)."""
    e1, e2, e3, e4 = y[0] - r[0], y[1], y[2] - r[1], y[3]
    S = p.alpha * (p.c1 * e1 + e2) + p.c2 * e3 + e4  # eq. 1
    sn, cs = math.sin(y[2]), math.cos(y[2])
    D = p.M + p.m * sn * sn
    f1 = (-p.m * p.g * cs * sn + p.m * p.l * sn * e4 * e4) / D
    f2 = (-p.m * p.l * cs * sn * e4 * e4 + (p.M + p.m) * p.g * sn) / (p.l * D)
    b1, b2 = 1.0 / D, -cs / (p.l * D)
    sat = min(1.0, max(-1.0, S / p.phi))
    u = -(p.alpha * (p.c1 * e2 + f1) + p.c2 * e4 + f2 + p.kappa * S + p.eta * sat) / (p.alpha * b1 + b2)  # eq. 2
    return (u,), (), (S,)


class SlidingMode(LawController):
    """Sliding-mode control of the x pendulum (Wang et al. 2004, hierarchical; boundary layer phi)."""

    Config = law_config(SHAPE)
    shape = SHAPE

    @property
    def step(self) -> ControllerStep:  # compiled on first use, not when listed
        return _compiled().step

    def compiled(self) -> LawController:
        return _compiled()

    def build(self, label: str, cfg: Any, plant: Plant, path: str, dt: float | None = None) -> ControllerInstance:
        if plant.name != PLANT:
            raise ConfigError(path, "sliding_mode", f"a published design exists for the x pendulum only (Wang et al. "
                              f"2004); allowed plants: {PLANT}, not {plant.name}")  # fmt: skip
        if abs(cfg.alpha - 1.0 / cfg.l) < 1e-12 * max(1.0, abs(cfg.alpha)):
            raise ConfigError(
                f"{path}.alpha", cfg.alpha, "alpha b1 + b2 vanishes upright (alpha = 1/l); choose another"
            )
        return super().build(label, cfg, plant, path, dt)


@functools.cache
def _compiled() -> LawController:
    """The law compiled and checked once per process (:func:`nlcx.controllers.law.law_model`)."""
    return law_model(sliding_mode_law, SHAPE, doc=SlidingMode.__doc__)


def surface_for_poles(A: np.ndarray, B: np.ndarray, poles: ArrayLike) -> dict[str, float]:
    """(c1, c2, alpha) of eq. 1 for which the motion on S = 0 of the linear model dx/dt = A x +
    B u (states x - r, x_dot, theta, theta_dot; one input) has the three ``poles``: Ackermann's
    formula for sliding surfaces, sᵀ = e_nᵀ W_c⁻¹ P(A), P the monic polynomial of the poles and
    W_c the controllability matrix (Ackermann and Utkin 1998), scaled so that theta_dot's
    coefficient is 1 as in S = alpha (c1 x_1 + x_2) + c2 x_3 + x_4."""
    n = A.shape[0]
    W = np.column_stack([np.linalg.matrix_power(A, k) @ B[:, 0] for k in range(n)])
    e = np.linalg.solve(W.T, np.eye(n)[-1])  # last row of W^-1
    coefficients = np.real(np.poly(np.asarray(poles, dtype=complex)))
    P = sum(c * np.linalg.matrix_power(A, len(coefficients) - 1 - k) for k, c in enumerate(coefficients))
    sigma = e @ P
    sigma = sigma / sigma[3]
    return {"c1": float(sigma[0] / sigma[1]), "c2": float(sigma[2]), "alpha": float(sigma[1])}

"""Stick-slip friction of Appendix A: the plant-force element acting on each input's axis.

Appendix A (after Campbell et al.): at rest the friction holds the axis up to the breakaway
force mu_s F_N; sliding, the simple model gives Coulomb plus viscous friction,
-mu_c F_N sgn(v) - eps v, and the exponential model
-[mu_c + (mu_s - mu_c) exp(-(|v|/v_s)^gamma)] F_N sgn(v) - eps v.

A variant with friction is stepped on its own (:func:`nlcx.kernel.friction_path.step_with_friction`):
a sliding axis whose velocity reaches zero inside a step is stopped there (the step is split at
that instant) and sticks; a stuck axis gets exactly the force that keeps its acceleration zero
(no chattering from sgn(0)) while that force is at most mu_s F_N (:func:`friction_forces`), and
breaks away in the direction of the net force otherwise (:func:`update_friction_modes`). The
parameters of each axis are a :data:`FRICTION_AXIS` block; the configuration lives in
:mod:`nlcx.uncertainty.friction`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from nlcx._numba_compat import inner_njit
from nlcx.kernel.signatures import FloatArray, IntArray, RightHandSide
from nlcx.layout import Layout

if TYPE_CHECKING:
    from nlcx.kernel.structures import FrictionScratch, OneColumn

#: Friction parameters of one input's axis: model (FRICTION_NONE, _SIMPLE, _EXPONENTIAL),
#: mu_s, mu_c, viscous coefficient eps (N s/m), normal force F_N (N), Stribeck velocity v_s
#: (m/s), form factor gamma, and the indices of the axis's velocity and position states.
FRICTION_AXIS = Layout(
    "FrictionAxis",
    (
        "model", "mu_s", "mu_c", "viscous", "normal_force",
        "stribeck_velocity", "form_factor", "velocity_index", "position_index",
    ),
)  # fmt: skip
FA = FRICTION_AXIS.at
FRICTION_NONE = 0
FRICTION_SIMPLE = 1
FRICTION_EXPONENTIAL = 2
#: Mode of an axis during a step.
SLIP = 1
STUCK = 2


@inner_njit(cache=True, error_model="numpy")
def _derivative(
    rhs: RightHandSide,
    t: float,
    x: FloatArray,
    u: FloatArray,
    dist_row: FloatArray,
    dist_map: IntArray,
    dx: FloatArray,
    one: OneColumn,
) -> None:  # pragma: no cover - compiled
    """dx = f(t, x, u; p) + dist_map @ d for one variant (eqs. 2.13/2.15: d enters the
    state derivatives). ``one``: the variant as a batch of one column
    (:class:`~nlcx.kernel.structures.OneColumn`, :data:`nlcx.kernel.abi.RHS_SIG`); its p is set."""
    for i in range(x.shape[0]):
        one.x[i, 0] = x[i]
    for j in range(u.shape[0]):
        one.u[j, 0] = u[j]
    rhs(t, one.x, one.u, one.p, one.dx, 1)
    n_d = dist_row.shape[0]
    for i in range(dx.shape[0]):
        dx[i] = one.dx[i, 0]
        if n_d > 0:
            acc = 0.0
            for j in range(n_d):
                acc += dist_map[i, j] * dist_row[j]
            dx[i] += acc


@inner_njit(cache=True, error_model="numpy")
def slip_friction(fric_row: FloatArray, v: float, direction: float) -> float:  # pragma: no cover - compiled
    """Friction while sliding in ``direction`` at velocity v (Appendix A).

    simple:      F = -mu_c F_N sgn - eps v
    exponential: F = -[mu_c + (mu_s - mu_c) exp(-(|v|/v_s)^gamma)] F_N sgn - eps v
    The sign is the direction of the slip, fixed over a step, so the Runge-Kutta stages
    never chatter on sgn(v).
    """
    model = int(fric_row[FA.model])
    mu_s, mu_c, eps, f_n = fric_row[FA.mu_s], fric_row[FA.mu_c], fric_row[FA.viscous], fric_row[FA.normal_force]
    if model == FRICTION_SIMPLE:
        mu = mu_c
    else:
        mu = mu_c + (mu_s - mu_c) * math.exp(-((abs(v) / fric_row[FA.stribeck_velocity]) ** fric_row[FA.form_factor]))
    return -mu * f_n * direction - eps * v


@inner_njit(cache=True, error_model="numpy")
def _solve_small(A: FloatArray, b: FloatArray, n: int) -> None:  # pragma: no cover - compiled
    """Solve A[:n, :n] z = b[:n] in place (Gaussian elimination, partial pivoting)."""
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(A[r, col]) > abs(A[piv, col]):
                piv = r
        if piv != col:
            for c in range(n):
                A[col, c], A[piv, c] = A[piv, c], A[col, c]
            b[col], b[piv] = b[piv], b[col]
        for r in range(col + 1, n):
            factor = A[r, col] / A[col, col]
            for c in range(col, n):
                A[r, c] -= factor * A[col, c]
            b[r] -= factor * b[col]
    for col in range(n - 1, -1, -1):
        acc = b[col]
        for c in range(col + 1, n):
            acc -= A[col, c] * b[c]
        b[col] = acc / A[col, col]


@inner_njit(cache=True, error_model="numpy")
def friction_forces(
    rhs: RightHandSide,
    t: float,
    x: FloatArray,
    u: FloatArray,
    dist_row: FloatArray,
    dist_map: IntArray,
    fric_b: FloatArray,
    mode: IntArray,
    direction: FloatArray,
    scratch: FrictionScratch,
) -> None:  # pragma: no cover - compiled
    """Friction force on every input's axis at state x (written to ``scratch.f``; ``scratch``:
    a :class:`~nlcx.kernel.structures.FrictionScratch`).

    Sliding axes get :func:`slip_friction`. Stuck axes get the force that keeps their
    acceleration exactly zero: accelerations are affine in the generalised forces, so with
    a0 the accelerations of the stuck axes under the other forces and B their response to
    unit forces on the stuck axes, f_S = -B^{-1} a0 (solved jointly when several stick).
    """
    f_out, work, A, rhs_s, dx, one = scratch.f, scratch.work, scratch.A, scratch.rhs_s, scratch.dx, scratch.one
    n_u = u.shape[0]
    n_stuck = 0
    for j in range(n_u):
        f_out[j] = 0.0
        if mode[j] == SLIP:
            vi = int(fric_b[j, FA.velocity_index])
            f_out[j] = slip_friction(fric_b[j], x[vi], direction[j])
        elif mode[j] == STUCK:
            n_stuck += 1
    if n_stuck == 0:
        return
    for j in range(n_u):
        work[j] = u[j] + f_out[j]
    _derivative(rhs, t, x, work, dist_row, dist_map, dx, one)
    k = 0
    for j in range(n_u):
        if mode[j] == STUCK:
            rhs_s[k] = -dx[int(fric_b[j, FA.velocity_index])]
            k += 1
    col = 0
    for jc in range(n_u):
        if mode[jc] != STUCK:
            continue
        work[jc] += 1.0
        _derivative(rhs, t, x, work, dist_row, dist_map, dx, one)
        work[jc] -= 1.0
        row = 0
        for jr in range(n_u):
            if mode[jr] == STUCK:
                A[row, col] = dx[int(fric_b[jr, FA.velocity_index])] + rhs_s[row]
                row += 1
        col += 1
    _solve_small(A, rhs_s, n_stuck)
    k = 0
    for j in range(n_u):
        if mode[j] == STUCK:
            f_out[j] = rhs_s[k]
            k += 1


@inner_njit(cache=True, error_model="numpy")
def update_friction_modes(
    rhs: RightHandSide,
    t: float,
    x: FloatArray,
    u: FloatArray,
    dist_row: FloatArray,
    dist_map: IntArray,
    fric_b: FloatArray,
    mode: IntArray,
    direction: FloatArray,
    scratch: FrictionScratch,
) -> None:  # pragma: no cover
    """Breakaway at the start of a step: a stuck axis whose holding force would exceed
    mu_s F_N starts to slide in the direction of the net force (Appendix A's static case)."""
    f_tmp = scratch.f
    for _ in range(u.shape[0]):
        friction_forces(rhs, t, x, u, dist_row, dist_map, fric_b, mode, direction, scratch)
        released = False
        for j in range(u.shape[0]):
            if mode[j] == STUCK and abs(f_tmp[j]) > fric_b[j, FA.mu_s] * fric_b[j, FA.normal_force]:
                mode[j] = SLIP
                direction[j] = -1.0 if f_tmp[j] > 0 else 1.0
                released = True
        if not released:
            return


@inner_njit(cache=True, error_model="numpy")
def disturbance_at(
    drow: FloatArray, c: FloatArray, position: float, out: FloatArray
) -> None:  # pragma: no cover - compiled
    """d at fraction ``position`` of the step, interpolated linearly between the stage nodes c."""
    n_stage = c.shape[0]
    lo, hi = 0, 0
    for s in range(n_stage):
        if c[s] <= position and c[s] >= c[lo]:
            lo = s
        if c[s] >= position and (c[hi] < position or c[s] <= c[hi]):
            hi = s
    if c[hi] < position:
        hi = lo
    w = 0.0 if c[hi] == c[lo] else (position - c[lo]) / (c[hi] - c[lo])
    for j in range(out.shape[0]):
        out[j] = (1.0 - w) * drow[lo, j] + w * drow[hi, j]


def any_friction(axes: FloatArray | None) -> bool:
    """Whether friction axes (FRICTION_AXIS rows: an item's, or a call's with a leading row axis;
    None: none) hold a friction model anywhere, as :func:`has_friction` decides per row."""
    return axes is not None and bool(np.any(axes[..., FA.model].astype(np.int64) != FRICTION_NONE))


@inner_njit(cache=True, error_model="numpy")
def has_friction(axes: FloatArray) -> bool:  # pragma: no cover - compiled
    """Whether any input's axis (rows of ``axes``, FRICTION_AXIS blocks) has a friction model."""
    for j in range(axes.shape[0]):  # noqa: SIM110 - compiled: numba has no any() over a generator
        if int(axes[j, FA.model]) != FRICTION_NONE:
            return True
    return False


@inner_njit(cache=True, error_model="numpy")
def initial_modes(
    axes: FloatArray, x: FloatArray, mode: IntArray, direction: FloatArray, hold: FloatArray
) -> None:  # pragma: no cover - compiled
    """Mode of each axis at the start: stuck if its velocity is exactly zero, else sliding
    in the direction of the velocity; a stuck axis is held at its initial position."""
    for j in range(axes.shape[0]):
        if int(axes[j, FA.model]) != FRICTION_NONE:
            v0 = x[int(axes[j, FA.velocity_index])]
            mode[j] = STUCK if v0 == 0.0 else SLIP
            direction[j] = 1.0 if v0 > 0.0 else -1.0
            hold[j] = x[int(axes[j, FA.position_index])]

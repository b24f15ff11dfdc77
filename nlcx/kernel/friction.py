"""Stick-slip friction of Appendix A: the plant-force element acting on each input's axis.

Appendix A (after Campbell et al.): at rest the friction holds the axis up to the breakaway
force mu_s F_N; sliding, the simple model gives Coulomb plus viscous friction,
-mu_c F_N sgn(v) - eps v, and the exponential model
-[mu_c + (mu_s - mu_c) exp(-(|v|/v_s)^gamma)] F_N sgn(v) - eps v.

A variant with friction is stepped on its own (:func:`step_with_friction`): a sliding axis
whose velocity reaches zero inside a step is stopped there (the step is split at that
instant) and sticks; a stuck axis gets exactly the force that keeps its acceleration zero
(no chattering from sgn(0)) while that force is at most mu_s F_N, and breaks away in the
direction of the net force otherwise. The parameters of each axis are a
:data:`FRICTION_AXIS` block; the configuration lives in :mod:`nlcx.uncertainty.friction`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from nlcx.kernel.abi import Padding, shared_row
from nlcx.kernel.structures import FRICTION_SAMPLE_SIG, FRICTION_STEP_SIG, FrictionPath
from nlcx.layout import Layout

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


@njit(cache=True, error_model="numpy")
def _derivative(rhs, t, x, u, dist_row, dist_map, dx, one):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def slip_friction(fric_row, v, direction):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _solve_small(A, b, n):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def friction_forces(rhs, t, x, u, dist_row, dist_map, fric_b, mode, direction, scratch):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def update_friction_modes(rhs, t, x, u, dist_row, dist_map, fric_b, mode, direction, scratch):  # pragma: no cover
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


@njit(cache=True, error_model="numpy")
def _disturbance_at(drow, c, position, out):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _rk_step_one(
    rhs, t, h, frac0, h_frac, x_in, x_out, u, drow, c, dist_map, fb, mode, direction, integration, scratch
):  # pragma: no cover - compiled
    """One explicit Runge-Kutta step of one variant with friction, size h from x_in at t
    (u held) into x_out, with the tableau of ``integration``.

    The step covers the fraction [frac0, frac0 + h_frac] of the sampling step; the
    disturbance is exact at the stage nodes of a full step and interpolated between them
    for a partial step (one that ends where a sliding axis stops). ``scratch`` is the
    friction path's work space (:class:`~nlcx.kernel.structures.FrictionScratch`).
    """
    rk_a, rk_b = integration.rk_a, integration.rk_b
    k_stage, xs, f, u_total, d_tmp = scratch.k_stage, scratch.xs, scratch.f, scratch.u_total, scratch.d_tmp
    n = x_in.shape[0]
    n_stage = rk_b.shape[0]
    partial = frac0 != 0.0 or h_frac != 1.0
    for s in range(n_stage):
        for i in range(x_in.shape[0]):
            xs[i] = x_in[i]
        for j in range(s):
            if rk_a[s, j] != 0.0:
                for i in range(n):
                    xs[i] += h * rk_a[s, j] * k_stage[j, i]
        ts = t + c[s] * h
        if partial:
            _disturbance_at(drow, c, frac0 + c[s] * h_frac, d_tmp)
            d_s = d_tmp
        else:
            d_s = drow[s]
        friction_forces(rhs, ts, xs, u, d_s, dist_map, fb, mode, direction, scratch)
        for j in range(u.shape[0]):
            u_total[j] = u[j] + f[j]
        _derivative(rhs, ts, xs, u_total, d_s, dist_map, k_stage[s], scratch.one)
    for i in range(x_in.shape[0]):
        x_out[i] = x_in[i]
    for s in range(n_stage):
        for i in range(n):
            x_out[i] += h * rk_b[s] * k_stage[s, i]


@njit(cache=True, error_model="numpy")
def step_with_friction(rhs, t, work, drow, c, dist_map, fb, mode, direction, hold, integration):  # pragma: no cover
    """One sampling step of one variant with friction (Appendix A), from ``work.x`` held
    ``work.u`` into ``work.x_new`` (``work``: a :class:`~nlcx.kernel.structures.FrictionWork`,
    allocated once per :func:`~nlcx.kernel.integrator.simulate` call): a sliding axis whose
    velocity reaches zero inside the step is stopped there (the step is split at that instant,
    ``work.x_mid``); a stuck axis is held at its position until it breaks away."""
    x, x_new, x_mid, u, scratch = work.x, work.x_new, work.x_mid, work.u, work.scratch
    dt = integration.dt
    n_u = u.shape[0]
    _rk_step_one(rhs, t, dt, 0.0, 1.0, x, x_new, u, drow, c, dist_map, fb, mode, direction, integration, scratch)
    frac = 1.0
    for j in range(n_u):
        vi = int(fb[j, FA.velocity_index])
        if mode[j] == SLIP and x_new[vi] * direction[j] <= 0.0 and x[vi] != x_new[vi]:
            frac = min(frac, x[vi] / (x[vi] - x_new[vi]))
    if frac < 1.0:
        h1 = frac * dt
        _rk_step_one(rhs, t, h1, 0.0, frac, x, x_mid, u, drow, c, dist_map, fb, mode, direction, integration, scratch)
        for j in range(n_u):
            vi = int(fb[j, FA.velocity_index])
            if mode[j] == SLIP and x_new[vi] * direction[j] <= 0.0:
                x_mid[vi] = 0.0
                mode[j] = STUCK
                hold[j] = x_mid[int(fb[j, FA.position_index])]
        _disturbance_at(drow, c, frac, scratch.d_tmp)
        update_friction_modes(rhs, t + h1, x_mid, u, scratch.d_tmp, dist_map, fb, mode, direction, scratch)
        _rk_step_one(
            rhs, t + h1, dt - h1, frac, 1.0 - frac, x_mid, x_new, u, drow, c, dist_map, fb, mode, direction,
            integration, scratch,
        )  # fmt: skip
    for j in range(n_u):
        vi = int(fb[j, FA.velocity_index])
        if mode[j] == SLIP and x_new[vi] * direction[j] <= 0.0:  # a second stop: rare
            mode[j] = STUCK
            hold[j] = x_new[int(fb[j, FA.position_index])]
        if mode[j] == STUCK:
            x_new[vi] = 0.0
            x_new[int(fb[j, FA.position_index])] = hold[j]


def any_friction(axes: Any) -> bool:
    """Whether friction axes (FRICTION_AXIS rows: an item's, or a call's with a leading row axis;
    None: none) hold a friction model anywhere, as :func:`has_friction` decides per row."""
    return axes is not None and bool(np.any(axes[..., FA.model].astype(np.int64) != FRICTION_NONE))


@njit(cache=True, error_model="numpy")
def has_friction(axes):  # pragma: no cover - compiled
    """Whether any input's axis (rows of ``axes``, FRICTION_AXIS blocks) has a friction model."""
    for j in range(axes.shape[0]):  # noqa: SIM110 - compiled: numba has no any() over a generator
        if int(axes[j, FA.model]) != FRICTION_NONE:
            return True
    return False


@njit(cache=True, error_model="numpy")
def initial_modes(axes, x, mode, direction, hold):  # pragma: no cover - compiled
    """Mode of each axis at the start: stuck if its velocity is exactly zero, else sliding
    in the direction of the velocity; a stuck axis is held at its initial position."""
    for j in range(axes.shape[0]):
        if int(axes[j, FA.model]) != FRICTION_NONE:
            v0 = x[int(axes[j, FA.velocity_index])]
            mode[j] = STUCK if v0 == 0.0 else SLIP
            direction[j] = 1.0 if v0 > 0.0 else -1.0
            hold[j] = x[int(axes[j, FA.position_index])]


# ----------------------------------------------------------------------------- the kernel's friction path
# (:class:`nlcx.kernel.structures.FrictionPath`: compiled when a batch with friction first reaches the kernel)


@njit(cache=True, error_model="numpy")
def frictional_sample(rhs, t, k, nb, n_free, slots, u, forces, work, records):  # pragma: no cover - compiled
    """Breakaway at t_k for the frictional variants (Appendix A's static case), and the friction
    force on each axis at t_k when it is recorded (the step evaluates its own). ``slots``: the
    working slots (:class:`~nlcx.kernel.structures.Slots`), u by rows."""
    dist, dist_map, FRICTION = forces.dist, forces.dist_map, records.FRICTION
    record = FRICTION.shape[1] > 1
    scratch = work.scratch
    for b in range(nb):
        if slots.stopped[b]:
            continue
        v = slots.vid[b]
        if b < n_free:
            if record:
                for j in range(u.shape[1]):
                    FRICTION[v, k, j] = 0.0
            continue
        _load_one(b, slots, u, work)
        d_k = _disturbance_at_sample(dist[shared_row(dist.shape[0], v)], k)
        axes, mode, direction = slots.axes[b], slots.mode[b], slots.direction[b]
        update_friction_modes(rhs, t, work.x, work.u, d_k, dist_map, axes, mode, direction, scratch)
        if record:
            friction_forces(rhs, t, work.x, work.u, d_k, dist_map, axes, mode, direction, scratch)
            for j in range(u.shape[1]):
                FRICTION[v, k, j] = scratch.f[j]


@njit(cache=True, inline="always", error_model="numpy")
def _disturbance_at_sample(drows, k):  # pragma: no cover - compiled
    """d at the sample t_k from one variant's stage table ``drows`` (steps, stages, n_d; one
    row when shared over time): the first stage of step k (c = 0, t_k), and at the final sample
    t_K, which begins no step, the last stage of the last step (t_K itself for RK4 and Heun,
    whose last node is c = 1; t_{K-1} for Euler, which has no later node)."""
    step, stage = sample_stage(drows, k)
    return drows[step, stage]


@njit(cache=True, inline="always", error_model="numpy")
def sample_stage(drows, k):  # pragma: no cover - compiled
    """(step, stage) of the row of ``drows`` that holds d at the sample t_k
    (:func:`_disturbance_at_sample`)."""
    if drows.shape[0] == 1:
        return 0, 0
    if k < drows.shape[0]:
        return k, 0
    return drows.shape[0] - 1, drows.shape[1] - 1


@njit(cache=True, inline="always", error_model="numpy")
def _load_one(b, slots, u, work):  # pragma: no cover - compiled
    """Copy working slot b's state and plant parameters (columns b of ``slots.x`` and
    ``slots.p``) and its input (row b of u) into the one-variant work space."""
    for i in range(slots.x.shape[0]):
        work.x[i] = slots.x[i, b]
    for j in range(u.shape[1]):
        work.u[j] = u[b, j]
    for i in range(slots.p.shape[0]):
        work.scratch.one.p[i, 0] = slots.p[i, b]


@njit(cache=True, error_model="numpy")
def frictional_step(rhs, t, kd, nb, n_free, slots, x_new, u, forces, work, integration, c):  # pragma: no cover
    """One sampling step of each frictional variant, one at a time, into x_new (by columns)."""
    dist, dist_map = forces.dist, forces.dist_map
    for b in range(n_free, nb):
        if slots.stopped[b]:
            continue
        v = slots.vid[b]
        _load_one(b, slots, u, work)
        step_with_friction(
            rhs, t, work, dist[shared_row(dist.shape[0], v), kd], c, dist_map,
            slots.axes[b], slots.mode[b], slots.direction[b], slots.hold[b], integration,
        )  # fmt: skip
        for i in range(x_new.shape[0]):
            x_new[i, b] = work.x_new[i]


def _no_frictional_sample(rhs, t, k, nb, n_free, slots, u, forces, work, records):  # pragma: no cover - compiled
    return


def _no_frictional_step(rhs, t, kd, nb, n_free, slots, x_new, u, forces, work, integration, c):  # pragma: no cover
    return


#: The friction path of a batch without friction: never called.
no_frictional_sample = Padding(FRICTION_SAMPLE_SIG, _no_frictional_sample, __name__, "no_frictional_sample")
no_frictional_step = Padding(FRICTION_STEP_SIG, _no_frictional_step, __name__, "no_frictional_step")
#: The friction path handed to the kernel, with and without friction.
FRICTIONAL = FrictionPath(sample=frictional_sample, step=frictional_step)
FRICTIONLESS = FrictionPath(sample=no_frictional_sample, step=no_frictional_step)

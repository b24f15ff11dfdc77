"""The steps of the closed loop, written once: sampling, holding the input, the Runge-Kutta step, acceptance.

Every function here works on a batch of columns (the plant's view, :mod:`nlcx.kernel.abi`) or
rows (the controller's), the first ``nb`` of them active. The CPU kernel
(:mod:`nlcx.kernel.integrator`) calls them over its working slots; the GPU kernel
(:mod:`nlcx.kernel.cuda_loop`) compiles the same source for one thread's variant
(:class:`nlcx.kernel.device.Retarget`) and calls them with a batch of one. One sampling step,
at t_k = k dt::

    sample_signals: x_k -> y_k = C x_k, r_k        (then SENSOR elements, controller, ACTUATOR)
    hold_input:     u_k held over the step
    rk_step:        x_{k+1} from x_k, u_k held, disturbances at the stage times (friction: Appendix A)
    first_failing_state: a state not finite or past its bound stops the run

:func:`rk_step` is the one Runge-Kutta body, for any explicit tableau, friction or not. The CPU
kernel steps the classic RK4 of a batch without friction in a specialised copy of it (flat loops
over every column, in :func:`nlcx.kernel.integrator.simulate`), which tests/test_stepping.py
holds bit-identical to :func:`rk_step` with :data:`CLASSIC`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numba import njit

from nlcx.kernel.abi import shared_row
from nlcx.kernel.friction import disturbance_at, friction_forces
from nlcx.kernel.signatures import FloatArray, IntArray, RightHandSide

if TYPE_CHECKING:
    from nlcx.kernel.structures import FrictionScratch

#: How :func:`rk_step` adds up its stages: a running sum x + h b_1 k_1 + h b_2 k_2 + ... (any
#: tableau; the steps of variants with friction), or the classic RK4's
#: x + h/6 (k_1 + 2 (k_2 + k_3) + k_4).
SEQUENTIAL, CLASSIC = 0, 1


def stage_nodes(rk_a: FloatArray) -> FloatArray:
    """c_i = sum_j a_ij: the stage times t_k + c_i dt (added in the order of j, from 0)."""
    n_stage = rk_a.shape[0]
    c = np.zeros(n_stage)
    for i in range(n_stage):
        for j in range(n_stage):
            c[i] += rk_a[i, j]
    return c


def output_picks(C: FloatArray) -> IntArray:
    """picked[i] = j where row i of C is the unit vector e_j (y_i = x_j exactly), else -1."""
    n_y, n = C.shape
    picked = np.full(n_y, -1, dtype=np.int64)
    for i in range(n_y):
        for j in range(n):
            if C[i, j] == 1.0 and picked[i] == -1:
                picked[i] = j
            elif C[i, j] != 0.0:
                picked[i] = -2
    for i in range(n_y):
        if picked[i] == -2:
            picked[i] = -1
    return picked


@njit(cache=True, inline="always", error_model="numpy")
def sample_signals(
    nb: int,
    vid: IntArray,
    x: FloatArray,
    xrow: FloatArray,
    C: FloatArray,
    picked: IntArray,
    y: FloatArray,
    ref: FloatArray,
    kr: int,
    r: FloatArray,
    u: FloatArray,
) -> None:  # pragma: no cover - compiled
    """At t_k, for the first nb variants: x_k (columns of x) into the controller's rows xrow,
    y_k = C x_k (a row of C that selects one state copies it), r_k (sample kr of each
    variant's references, rows ``ref``), u cleared."""
    n = x.shape[0]
    for b in range(nb):
        for i in range(n):
            xrow[b, i] = x[i, b]
        for i in range(y.shape[1]):
            if picked[i] >= 0:
                y[b, i] = x[picked[i], b]
            else:
                acc = 0.0
                for j in range(n):
                    acc += C[i, j] * x[j, b]
                y[b, i] = acc
        br = shared_row(ref.shape[0], vid[b])
        for i in range(r.shape[1]):
            r[b, i] = ref[br, kr, i]
        for j in range(u.shape[1]):
            u[b, j] = 0.0


@njit(cache=True, inline="always", error_model="numpy")
def hold_input(b: int, u: FloatArray, uc: FloatArray) -> int:  # pragma: no cover - compiled
    """Hold row b of the input u_k over the step (column b of uc, the plant's); the first input
    that is not finite, or -1."""
    bad = -1
    for j in range(u.shape[1]):
        uc[j, b] = u[b, j]
        if bad < 0 and not math.isfinite(u[b, j]):
            bad = j
    return bad


@njit(cache=True, inline="always", error_model="numpy")
def first_failing_state(x: FloatArray, b: int, bounds: FloatArray) -> int:  # pragma: no cover - compiled
    """The first state of column b of x that is not finite or past its bound (column b of
    ``bounds``), or -1."""
    for i in range(x.shape[0]):
        if not (math.isfinite(x[i, b]) and abs(x[i, b]) <= bounds[i, b]):
            return i
    return -1


@njit(cache=True, inline="always", error_model="numpy")
def add_disturbances(
    dx: FloatArray, nb: int, dist: FloatArray, vid: IntArray, kd: int, stage: int, dist_map: IntArray
) -> None:  # pragma: no cover - compiled
    """dx[:, b] += dist_map @ d for the first nb columns, d the disturbance of column b's
    variant at step kd and ``stage`` (eqs. 2.13/2.15: d enters the state derivatives)."""
    n_d = dist.shape[3]
    if n_d == 0:
        return
    for b in range(nb):
        bd = shared_row(dist.shape[0], vid[b])
        for i in range(dx.shape[0]):
            acc = 0.0
            for j in range(n_d):
                acc += dist_map[i, j] * dist[bd, kd, stage, j]
            dx[i, b] += acc


@njit(cache=True, error_model="numpy")
def rk_step(
    rhs: RightHandSide,
    t: float,
    h: float,
    nb: int,
    x: FloatArray,
    x_out: FloatArray,
    u: FloatArray,
    p: FloatArray,
    ks: FloatArray,
    xs: FloatArray,
    rk_a: FloatArray,
    rk_b: FloatArray,
    c: FloatArray,
    combination: int,
    dist: FloatArray,
    vid: IntArray,
    kd: int,
    dist_map: IntArray,
    friction: FrictionStage | None,
) -> None:  # pragma: no cover - compiled
    """One explicit Runge-Kutta step of size h from x at t into x_out, for the first nb columns,
    the input u held: the stages

        xs = x + h sum_{j<s} a_sj k_j,    k_s = f(t + c_s h, xs, u; p) + dist_map d_s,

    then x_out by ``combination`` (:data:`SEQUENTIAL` or :data:`CLASSIC`). ``ks`` (stages, n, B)
    and ``xs`` (n, B) are work arrays. Without ``friction`` (None), d_s is the disturbance of
    each column's variant at step kd and stage s (``dist``). With it (one variant, nb = 1: a
    :class:`nlcx.kernel.friction.FrictionStage`), the input of each stage adds the friction
    forces at its state, and d_s is taken at the stage's time within a possibly partial step
    (Appendix A)."""
    n = x.shape[0]
    n_stage = rk_b.shape[0]
    for s in range(n_stage):
        for i in range(n):
            for b in range(nb):
                acc = x[i, b]
                for j in range(s):
                    if rk_a[s, j] != 0.0:
                        acc += h * rk_a[s, j] * ks[j, i, b]
                xs[i, b] = acc
        if friction is None:
            rhs(t + c[s] * h, xs, u, p, ks[s], nb)
            add_disturbances(ks[s], nb, dist, vid, kd, s, dist_map)
        else:
            frictional_stage(rhs, t + c[s] * h, s, xs, u, p, ks[s], c, dist_map, friction)
    if combination == CLASSIC:
        for i in range(n):
            for b in range(nb):
                x_out[i, b] = x[i, b] + h / 6.0 * (ks[0, i, b] + 2.0 * (ks[1, i, b] + ks[2, i, b]) + ks[3, i, b])
        return
    for i in range(n):
        for b in range(nb):
            acc = x[i, b]
            for s in range(n_stage):
                acc += h * rk_b[s] * ks[s, i, b]
            x_out[i, b] = acc


class FrictionStage(NamedTuple):
    """What a stage of a step with friction (:func:`rk_step`, one variant) needs besides the
    step's arguments: the variant's disturbance at the stage nodes of a full step ``drow``
    (stages, n_d), the fraction [frac0, frac0 + h_frac] of the sampling step this step covers,
    the friction axes and each axis's mode and slip direction, and the friction path's work
    space (:class:`~nlcx.kernel.structures.FrictionScratch`)."""

    drow: np.ndarray
    frac0: float
    h_frac: float
    axes: np.ndarray
    mode: np.ndarray
    direction: np.ndarray
    scratch: FrictionScratch


@njit(cache=True, error_model="numpy")
def frictional_stage(
    rhs: RightHandSide,
    ts: float,
    s: int,
    xs: FloatArray,
    u: FloatArray,
    p: FloatArray,
    dx: FloatArray,
    c: FloatArray,
    dist_map: IntArray,
    friction: FrictionStage,
) -> None:  # pragma: no cover - compiled
    """k_s = f(ts, xs, u + F(xs); p) + dist_map d_s of one variant with friction (column 0 of xs,
    dx and the held input u): F the friction forces at the stage's state
    (:func:`~nlcx.kernel.friction.friction_forces`), d_s the disturbance at the stage node of a
    full step, or interpolated between the nodes at the stage's time within a partial step."""
    scratch = friction.scratch
    if friction.frac0 != 0.0 or friction.h_frac != 1.0:
        disturbance_at(friction.drow, c, friction.frac0 + c[s] * friction.h_frac, scratch.d_tmp)
        d_s = scratch.d_tmp
    else:
        d_s = friction.drow[s]
    axes, mode, direction = friction.axes, friction.mode, friction.direction
    friction_forces(rhs, ts, xs[:, 0], u[:, 0], d_s, dist_map, axes, mode, direction, scratch)
    total = scratch.one.u
    for j in range(u.shape[0]):
        total[j, 0] = u[j, 0] + scratch.f[j]
    rhs(ts, xs, total, p, dx, 1)
    n_d = d_s.shape[0]
    if n_d > 0:
        for i in range(dx.shape[0]):
            acc = 0.0
            for j in range(n_d):
                acc += dist_map[i, j] * d_s[j]
            dx[i, 0] += acc

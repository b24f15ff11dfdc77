"""The kernel's friction path: the variants with friction of a batch, stepped one by one (Appendix A).

A variant with friction is stepped by :func:`step_with_friction`: the Runge-Kutta step of
:func:`nlcx.kernel.stepping.rk_step` with the friction forces in each stage's input; a sliding
axis whose velocity reaches zero inside the step is stopped there (the step is split at that
instant) and sticks; a stuck axis is held at its position until it breaks away
(:func:`nlcx.kernel.friction.update_friction_modes`, checked at each sample by
:func:`frictional_sample`). The CPU kernel calls the path through two function values
(:class:`~nlcx.kernel.structures.FrictionPath`), so that a batch without friction never
compiles it; the GPU compiles the same functions for a thread (:mod:`nlcx.kernel.cuda_friction`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

from numba import njit

from nlcx.kernel.abi import Padding, shared_row
from nlcx.kernel.friction import FA, SLIP, STUCK, disturbance_at, friction_forces, initial_modes, update_friction_modes
from nlcx.kernel.signatures import FloatArray, IntArray, RightHandSide
from nlcx.kernel.stepping import SEQUENTIAL, FrictionStage, rk_step
from nlcx.kernel.structures import FRICTION_SAMPLE_SIG, FRICTION_STEP_SIG, FrictionPath, FrictionSample, FrictionStep

if TYPE_CHECKING:
    from nlcx.kernel.structures import FrictionScratch, FrictionWork, Integration, PlantForces, Records, Slots


@njit(cache=True, error_model="numpy")
def _step_part(
    rhs: RightHandSide,
    t: float,
    h: float,
    frac0: float,
    h_frac: float,
    x_in: FloatArray,
    x_out: FloatArray,
    u: FloatArray,
    dist: FloatArray,
    bd: int,
    kd: int,
    c: FloatArray,
    dist_map: IntArray,
    axes: FloatArray,
    mode: IntArray,
    direction: FloatArray,
    integration: Integration,
    scratch: FrictionScratch,
) -> None:  # pragma: no cover - compiled
    """One Runge-Kutta step of size h from x_in at t into x_out (columns (n, 1)) covering the
    fraction [frac0, frac0 + h_frac] of the sampling step, friction in every stage's input;
    the variant's disturbance is row (bd, kd) of ``dist``. (rk_step types its frictionless
    stage too, never taken here: ``mode`` stands in for its variant ids.)"""
    friction = FrictionStage(dist[bd, kd], frac0, h_frac, axes, mode, direction, scratch)
    rk_step(
        rhs, t, h, 1, x_in, x_out, u, scratch.one.p, scratch.k_stage, scratch.xs, integration.rk_a, integration.rk_b,
        c, SEQUENTIAL, dist, mode, kd, dist_map, friction,
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def step_with_friction(
    rhs: RightHandSide,
    t: float,
    work: FrictionWork,
    dist: FloatArray,
    bd: int,
    kd: int,
    c: FloatArray,
    dist_map: IntArray,
    fb: FloatArray,
    mode: IntArray,
    direction: FloatArray,
    hold: FloatArray,
    integration: Integration,
) -> None:  # pragma: no cover - compiled
    """One sampling step of one variant with friction (Appendix A), its disturbance row (bd, kd)
    of ``dist``, from ``work.x`` held ``work.u`` into ``work.x_new`` (``work``: a
    :class:`~nlcx.kernel.structures.FrictionWork`, allocated once per kernel call): a sliding
    axis whose velocity reaches zero inside the step is stopped there (the step is split at
    that instant, ``work.x_mid``); a stuck axis is held at its position until it breaks away."""
    x, x_new, x_mid, u, scratch = work.x, work.x_new, work.x_mid, work.u, work.scratch
    dt = integration.dt
    n_u = u.shape[0]
    drow = dist[bd, kd]
    _step_part(rhs, t, dt, 0.0, 1.0, x, x_new, u, dist, bd, kd, c, dist_map, fb, mode, direction, integration, scratch)
    frac = 1.0
    for j in range(n_u):
        vi = int(fb[j, FA.velocity_index])
        if mode[j] == SLIP and x_new[vi, 0] * direction[j] <= 0.0 and x[vi, 0] != x_new[vi, 0]:
            frac = min(frac, x[vi, 0] / (x[vi, 0] - x_new[vi, 0]))
    if frac < 1.0:
        h1 = frac * dt
        _step_part(rhs, t, h1, 0.0, frac, x, x_mid, u, dist, bd, kd, c, dist_map, fb, mode, direction, integration,
                   scratch)  # fmt: skip
        for j in range(n_u):
            vi = int(fb[j, FA.velocity_index])
            if mode[j] == SLIP and x_new[vi, 0] * direction[j] <= 0.0:
                x_mid[vi, 0] = 0.0
                mode[j] = STUCK
                hold[j] = x_mid[int(fb[j, FA.position_index]), 0]
        disturbance_at(drow, c, frac, scratch.d_tmp)
        update_friction_modes(rhs, t + h1, x_mid[:, 0], u[:, 0], scratch.d_tmp, dist_map, fb, mode, direction, scratch)
        _step_part(
            rhs, t + h1, dt - h1, frac, 1.0 - frac, x_mid, x_new, u, dist, bd, kd, c, dist_map, fb, mode, direction,
            integration, scratch,
        )  # fmt: skip
    for j in range(n_u):
        vi = int(fb[j, FA.velocity_index])
        if mode[j] == SLIP and x_new[vi, 0] * direction[j] <= 0.0:  # a second stop: rare
            mode[j] = STUCK
            hold[j] = x_new[int(fb[j, FA.position_index]), 0]
        if mode[j] == STUCK:
            x_new[vi, 0] = 0.0
            x_new[int(fb[j, FA.position_index]), 0] = hold[j]


@njit(cache=True, error_model="numpy")
def frictional_sample(
    rhs: RightHandSide,
    t: float,
    k: int,
    nb: int,
    n_free: int,
    slots: Slots,
    u: FloatArray,
    forces: PlantForces,
    work: FrictionWork,
    records: Records,
) -> None:  # pragma: no cover - compiled
    """Breakaway at t_k for the frictional variants (Appendix A's static case), and the friction
    force on each axis at t_k when it is recorded (the step evaluates its own); at t_0, first
    each axis's mode (:func:`~nlcx.kernel.friction.initial_modes`). ``slots``: the
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
        if k == 0:  # the modes at t_0, from x_0
            initial_modes(axes, work.x[:, 0], mode, direction, slots.hold[b])
        update_friction_modes(rhs, t, work.x[:, 0], work.u[:, 0], d_k, dist_map, axes, mode, direction, scratch)
        if record:
            friction_forces(rhs, t, work.x[:, 0], work.u[:, 0], d_k, dist_map, axes, mode, direction, scratch)
            for j in range(u.shape[1]):
                FRICTION[v, k, j] = scratch.f[j]


@njit(cache=True, inline="always", error_model="numpy")
def _disturbance_at_sample(drows: FloatArray, k: int) -> FloatArray:  # pragma: no cover - compiled
    """d at the sample t_k from one variant's stage table ``drows`` (steps, stages, n_d; one
    row when shared over time): the first stage of step k (c = 0, t_k), and at the final sample
    t_K, which begins no step, the last stage of the last step (t_K itself for RK4 and Heun,
    whose last node is c = 1; t_{K-1} for Euler, which has no later node)."""
    step, stage = sample_stage(drows, k)
    return drows[step, stage]


@njit(cache=True, inline="always", error_model="numpy")
def sample_stage(drows: FloatArray, k: int) -> tuple[int, int]:  # pragma: no cover - compiled
    """(step, stage) of the row of ``drows`` that holds d at the sample t_k
    (:func:`_disturbance_at_sample`)."""
    if drows.shape[0] == 1:
        return 0, 0
    if k < drows.shape[0]:
        return k, 0
    return drows.shape[0] - 1, drows.shape[1] - 1


@njit(cache=True, inline="always", error_model="numpy")
def _load_one(b: int, slots: Slots, u: FloatArray, work: FrictionWork) -> None:  # pragma: no cover - compiled
    """Copy working slot b's state and plant parameters (columns b of ``slots.x`` and
    ``slots.p``) and its input (row b of u) into the one-variant work space."""
    for i in range(slots.x.shape[0]):
        work.x[i, 0] = slots.x[i, b]
    for j in range(u.shape[1]):
        work.u[j, 0] = u[b, j]
    for i in range(slots.p.shape[0]):
        work.scratch.one.p[i, 0] = slots.p[i, b]


@njit(cache=True, error_model="numpy")
def frictional_step(
    rhs: RightHandSide,
    t: float,
    kd: int,
    nb: int,
    n_free: int,
    slots: Slots,
    x_new: FloatArray,
    u: FloatArray,
    forces: PlantForces,
    work: FrictionWork,
    integration: Integration,
    c: FloatArray,
) -> None:  # pragma: no cover
    """One sampling step of each frictional variant, one at a time, into x_new (by columns)."""
    dist, dist_map = forces.dist, forces.dist_map
    for b in range(n_free, nb):
        if slots.stopped[b]:
            continue
        v = slots.vid[b]
        _load_one(b, slots, u, work)
        step_with_friction(
            rhs, t, work, dist, shared_row(dist.shape[0], v), kd, c, dist_map,
            slots.axes[b], slots.mode[b], slots.direction[b], slots.hold[b], integration,
        )  # fmt: skip
        for i in range(x_new.shape[0]):
            x_new[i, b] = work.x_new[i, 0]


def _no_frictional_sample(
    rhs: RightHandSide,
    t: float,
    k: int,
    nb: int,
    n_free: int,
    slots: Slots,
    u: FloatArray,
    forces: PlantForces,
    work: FrictionWork,
    records: Records,
) -> None:  # pragma: no cover - compiled
    return


def _no_frictional_step(
    rhs: RightHandSide,
    t: float,
    kd: int,
    nb: int,
    n_free: int,
    slots: Slots,
    x_new: FloatArray,
    u: FloatArray,
    forces: PlantForces,
    work: FrictionWork,
    integration: Integration,
    c: FloatArray,
) -> None:  # pragma: no cover
    return


#: The friction path of a batch without friction: never called.
no_frictional_sample = Padding(FRICTION_SAMPLE_SIG, _no_frictional_sample, __name__, "no_frictional_sample")
no_frictional_step = Padding(FRICTION_STEP_SIG, _no_frictional_step, __name__, "no_frictional_step")
#: The friction path handed to the kernel, with and without friction.
FRICTIONAL = FrictionPath(sample=frictional_sample, step=frictional_step)
#: (numba hands a padding over as a function of its slot's signature.)
FRICTIONLESS = FrictionPath(
    sample=cast(FrictionSample, no_frictional_sample), step=cast(FrictionStep, no_frictional_step)
)

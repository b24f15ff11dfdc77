"""The working storage of a batched kernel call (:func:`nlcx.kernel.integrator.simulate`).

:func:`working_storage` copies the batch's arrays into working slots before the call, the
variants without friction first (slot b holds variant ``vid[b]``): the plant's state,
parameters and bounds by columns, the controller's by rows; and allocates the signals of a
sample, the Runge-Kutta stage columns and their flat views and the friction path's work space.
It is plain numpy: what runs once per call costs nothing to compile. (The friction modes at t_0
are set by the friction path, at its first sample: :func:`nlcx.kernel.friction_path.frictional_sample`.)

During the call, :func:`compact` moves stopped variants behind the active ones. Only the kernel
calls it: it is compiled without the wrappers that would let Python call it
(:func:`nlcx._numba_compat.inner_njit`), as are the kernel's other parts that only compiled code
calls (:mod:`nlcx.kernel.friction`, the sampling step's helpers).
"""

from __future__ import annotations

import numpy as np

from nlcx._numba_compat import inner_njit
from nlcx.kernel.abi import ACTUATOR, ELEMENT_ENTRY, MAX_STAGES, SENSOR, STATUS_OK
from nlcx.kernel.friction import FA, FRICTION_NONE
from nlcx.kernel.signatures import FloatArray
from nlcx.kernel.stepping import output_picks, stage_nodes
from nlcx.kernel.structures import (
    ControllerCall,
    FlatViews,
    FrictionScratch,
    FrictionWork,
    Integration,
    LoopElements,
    OneColumn,
    Outcome,
    PlantCall,
    PlantForces,
    Records,
    Signals,
    Slots,
    StageColumns,
    Working,
)


def working_storage(
    integration: Integration,
    plant: PlantCall,
    controller: ControllerCall,
    elements: LoopElements,
    forces: PlantForces,
    records: Records,
    outcome: Outcome,
) -> Working:
    """The working storage of a kernel call (:class:`~nlcx.kernel.structures.Working`), and
    every variant's ``outcome`` set to ok until it stops."""
    n_steps, n_u = records.X.shape[1] - 1, records.U.shape[2]
    slots, n_free = working_slots(plant, controller, forces.friction, n_u, records.LOG.shape[2])
    xrow = np.ascontiguousarray(slots.x.T)
    n_batch, n = xrow.shape
    signals = Signals(
        xrow=xrow, y=np.empty((n_batch, plant.C.shape[0])), r=np.empty((n_batch, controller.ref.shape[2])),
        u=np.empty((n_batch, n_u)), log=slots.log, uc=np.empty((n_u, n_batch)),
    )  # fmt: skip
    stages = StageColumns(x_new=np.empty((n, n_batch)), xs=np.empty((n, n_batch)), k=np.zeros((MAX_STAGES, n, n_batch)))
    hooks = elements.table[:, ELEMENT_ENTRY.at.hook].astype(np.int64)
    outcome.status[:], outcome.fail_index[:], outcome.n_valid[:] = STATUS_OK, -1, n_steps + 1
    return Working(
        slots=slots, n_free=n_free, signals=signals, stages=stages, flat=flat_views(slots, stages),
        friction=friction_work(n, n_u, plant.p.shape[1], integration.rk_b.shape[0], forces.dist.shape[3]),
        c=stage_nodes(integration.rk_a), picked=output_picks(plant.C), es=elements.es0.copy(),
        n_sensor=int(np.sum(hooks == SENSOR)), n_actuator=int(np.sum(hooks == ACTUATOR)),
    )  # fmt: skip


def slots_rows(a: np.ndarray, vid: np.ndarray) -> np.ndarray:
    """Row vid[b] of ``a`` (B|1, ...) in row b, a copy (an axis of length 1 is every variant's)."""
    return np.ascontiguousarray(a[vid if a.shape[0] > 1 else np.zeros_like(vid)])


def slots_columns(a: np.ndarray, vid: np.ndarray) -> np.ndarray:
    """Row vid[b] of ``a`` (B|1, m) in column b (m, B), a copy."""
    return np.ascontiguousarray(slots_rows(a, vid).T)


def working_slots(
    plant: PlantCall, controller: ControllerCall, friction: np.ndarray, n_u: int, n_log: int
) -> tuple[Slots, int]:
    """(slots, n_free): the working slots (:class:`~nlcx.kernel.structures.Slots`), the variants
    without friction first (the first n_free, stepped together), then those with friction
    (stepped one by one, their friction modes set at t_0 by the friction path); no slot stopped,
    the log NaN until written."""
    n_batch = plant.x0.shape[0]
    frictional = np.any(friction[:, :, FA.model].astype(np.int64) != FRICTION_NONE, axis=1)
    frictional = np.broadcast_to(frictional, (n_batch,))
    vid = np.concatenate([np.flatnonzero(~frictional), np.flatnonzero(frictional)]).astype(np.int64)
    slots = Slots(
        vid=vid, stopped=np.zeros(n_batch, dtype=np.bool_), x=slots_columns(plant.x0, vid),
        p=slots_columns(plant.p, vid), bounds=slots_columns(plant.bounds, vid), cp=slots_rows(controller.cp, vid),
        cs=slots_rows(controller.cs0, vid), log=np.full((n_batch, n_log), np.nan),
        axes=slots_rows(friction[:, :n_u, : len(FA)], vid), mode=np.zeros((n_batch, n_u), dtype=np.int64),
        direction=np.zeros((n_batch, n_u)), hold=np.zeros((n_batch, n_u)),
    )  # fmt: skip
    return slots, int(n_batch - np.sum(frictional))


def flat_views(slots: Slots, stages: StageColumns) -> FlatViews:
    """Flat views on the (n, B) arrays of a step (:class:`~nlcx.kernel.structures.FlatViews`)."""
    k = stages.k
    return FlatViews(
        x=slots.x.reshape(-1), xs=stages.xs.reshape(-1), x_new=stages.x_new.reshape(-1),
        bounds=slots.bounds.reshape(-1), k1=k[0].reshape(-1), k2=k[1].reshape(-1), k3=k[2].reshape(-1),
        k4=k[3].reshape(-1),
    )  # fmt: skip


def friction_work(n: int, n_u: int, n_p: int, n_stage: int, n_d: int) -> FrictionWork:
    """Work space of the one-variant friction path (:class:`~nlcx.kernel.structures.FrictionWork`)."""
    one = OneColumn(x=np.empty((n, 1)), u=np.empty((n_u, 1)), p=np.empty((n_p, 1)), dx=np.empty((n, 1)))
    scratch = FrictionScratch(
        k_stage=np.empty((n_stage, n, 1)), xs=np.empty((n, 1)), f=np.empty(n_u), work=np.empty(n_u),
        A=np.empty((n_u, n_u)), rhs_s=np.empty(n_u), dx=np.empty(n), d_tmp=np.empty(n_d), one=one,
    )  # fmt: skip
    column = (n, 1)
    return FrictionWork(x=np.empty(column), x_new=np.empty(column), x_mid=np.empty(column), u=np.empty((n_u, 1)),
                        scratch=scratch)  # fmt: skip


@inner_njit(cache=True, error_model="numpy")
def swap_variants(i: int, j: int, slots: Slots) -> None:  # pragma: no cover - compiled
    """Exchange the working slots i and j (two variants' state, parameters and bookkeeping):
    columns of the plant's state, parameters and bounds, rows of the rest."""
    if i == j:
        return
    vid, stopped, mode = slots.vid, slots.stopped, slots.mode
    vid[i], vid[j] = vid[j], vid[i]
    stopped[i], stopped[j] = stopped[j], stopped[i]
    for a in (slots.x, slots.p, slots.bounds):
        _swap_columns(a, i, j)
    for a in (slots.cp, slots.cs, slots.log, slots.direction, slots.hold):
        _swap_rows(a, i, j)
    _swap_rows3(slots.axes, i, j)
    for c in range(mode.shape[1]):
        mode[i, c], mode[j, c] = mode[j, c], mode[i, c]


@inner_njit(cache=True, error_model="numpy")
def _swap_rows(a: FloatArray, i: int, j: int) -> None:  # pragma: no cover - compiled
    """Exchange rows i and j of a 2-D array."""
    for c in range(a.shape[1]):
        a[i, c], a[j, c] = a[j, c], a[i, c]


@inner_njit(cache=True, error_model="numpy")
def _swap_columns(a: FloatArray, i: int, j: int) -> None:  # pragma: no cover - compiled
    """Exchange columns i and j of a 2-D array."""
    for r in range(a.shape[0]):
        a[r, i], a[r, j] = a[r, j], a[r, i]


@inner_njit(cache=True, error_model="numpy")
def _swap_rows3(a: FloatArray, i: int, j: int) -> None:  # pragma: no cover - compiled
    """Exchange rows i and j of a 3-D array."""
    for c in range(a.shape[1]):
        for d in range(a.shape[2]):
            a[i, c, d], a[j, c, d] = a[j, c, d], a[i, c, d]


@inner_njit(cache=True, error_model="numpy")
def clear_columns(start: int, stop: int, arrays: tuple[FloatArray, ...]) -> None:  # pragma: no cover - compiled
    """Zero columns start..stop-1 (variants that just left the batch) of ``arrays``: the state,
    x_{k+1} and the stage derivatives. The flat loops over every column then keep them zero and
    within bounds, whichever tableau integrates."""
    for a in arrays:
        for i in range(a.shape[0]):
            for b in range(start, stop):
                a[i, b] = 0.0


@inner_njit(cache=True, error_model="numpy")
def compact(nb: int, n_free: int, slots: Slots) -> tuple[int, int]:  # pragma: no cover - compiled
    """Move the stopped variants behind the active ones, keeping the frictionless slots in
    front: a stopped frictionless slot trades places with the last frictionless one, which
    then trades with the last active one. Returns the new (nb, n_free)."""
    stopped = slots.stopped
    b = np.int64(0)  # int64 from the start: a literal 0 would compile swap_variants once more, for Literal[int](0)
    while b < nb:
        if not stopped[b]:
            b += 1
            continue
        if b < n_free:
            swap_variants(b, n_free - 1, slots)
            swap_variants(n_free - 1, nb - 1, slots)
            n_free -= 1
        else:
            swap_variants(b, nb - 1, slots)
        nb -= 1
    return nb, n_free

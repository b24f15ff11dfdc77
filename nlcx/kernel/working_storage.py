"""The working storage of a batched kernel call (:func:`nlcx.kernel.integrator.simulate`).

The batch's arrays copied into working slots, the variants without friction first (slot b
holds variant ``vid[b]``): the plant's state, parameters and bounds by columns, the
controller's by rows; the signals of a sample, the Runge-Kutta stage columns and their flat
views, the friction work space; and the compaction that moves stopped variants behind the
active ones.

Only the kernel calls these functions: they are compiled without the wrappers that would let
Python call them (:func:`nlcx._numba_compat.inner_njit`), as are the kernel's other parts
that only compiled code calls (:mod:`nlcx.kernel.friction`, the sampling step's helpers).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from nlcx._numba_compat import inner_njit
from nlcx.kernel.abi import MAX_STAGES, STATUS_OK, shared_row
from nlcx.kernel.friction import FA, has_friction, initial_modes
from nlcx.kernel.signatures import FloatArray, IntArray
from nlcx.kernel.structures import FrictionScratch, FrictionWork, OneColumn, Slots

if TYPE_CHECKING:
    from nlcx.kernel.structures import ControllerCall, Outcome, PlantCall


class WorkingRows(NamedTuple):
    """The working copies of a batch's arrays, in the order of its working slots (slot b holds
    variant vid[b]): the plant's state x, parameters p and bounds by columns; the controller's
    copy of the state xrow, its parameters cp and state cs and the friction axes by rows."""

    vid: np.ndarray
    x: np.ndarray
    xrow: np.ndarray
    p: np.ndarray
    cp: np.ndarray
    cs: np.ndarray
    axes: np.ndarray
    bounds: np.ndarray


class FrictionModes(NamedTuple):
    """Each slot's friction axes (B, n_u): mode, slip direction and the position a stuck axis
    holds; and whether the slot's variant stopped (B,)."""

    mode: np.ndarray
    direction: np.ndarray
    hold: np.ndarray
    stopped: np.ndarray


class Signals(NamedTuple):
    """The signals of a sample, written anew at every sample: by rows, the controller's copy
    of the state xrow (B, n), the outputs y (B, n_y), the references r (B, n_r), the input u
    (B, n_u) and the controller's log (B, n_log, NaN until written); by columns, the input held
    over the step uc (n_u, B) (the plant's)."""

    xrow: np.ndarray
    y: np.ndarray
    r: np.ndarray
    u: np.ndarray
    log: np.ndarray
    uc: np.ndarray


class StageColumns(NamedTuple):
    """Work arrays of a Runge-Kutta step: x_{k+1} and a stage's state xs (n, B), and the stage
    derivatives k (MAX_STAGES, n, B; zero where no right-hand side writes them: the columns of
    variants with friction)."""

    x_new: np.ndarray
    xs: np.ndarray
    k: np.ndarray


class FlatViews(NamedTuple):
    """Flat views (n B,), made once, on the (n, B) arrays of a step (:func:`flat_views`)."""

    x: np.ndarray
    xs: np.ndarray
    x_new: np.ndarray
    bounds: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray


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
def _row_order(friction: FloatArray, n_batch: int) -> tuple[IntArray, int]:  # pragma: no cover - compiled
    """(vid, n_free): the variants without friction first (stepped together), then those with
    friction (stepped one by one); vid maps a working row to its variant."""
    vid = np.empty(n_batch, dtype=np.int64)
    n_free = 0
    for v in range(n_batch):
        if not has_friction(friction[shared_row(friction.shape[0], v)]):
            vid[n_free] = v
            n_free += 1
    b = n_free
    for v in range(n_batch):
        if has_friction(friction[shared_row(friction.shape[0], v)]):
            vid[b] = v
            b += 1
    return vid, n_free


@inner_njit(cache=True, error_model="numpy")
def working_rows(
    plant: PlantCall, controller: ControllerCall, friction: FloatArray, n_u: int
) -> tuple[WorkingRows, int]:  # pragma: no cover - compiled
    """(rows, n_free): the working copies (:class:`WorkingRows`), the variants without friction
    first (the first n_free, stepped together), then those with friction (stepped one by one)."""
    x0, p, bounds, cp, cs0 = plant.x0, plant.p, plant.bounds, controller.cp, controller.cs0
    n_batch, n = x0.shape
    vid, n_free = _row_order(friction, n_batch)
    x = np.empty((n, n_batch))
    xrow = np.empty((n_batch, n))
    pw = np.empty((p.shape[1], n_batch))
    cpw = np.empty((n_batch, cp.shape[1]))
    cs = np.empty((n_batch, cs0.shape[1]))
    fw = np.empty((n_batch, n_u, len(FA)))
    bw = np.empty((n, n_batch))
    for b in range(n_batch):
        v = vid[b]
        _copy_row(x0, v, xrow, b)
        bp = shared_row(p.shape[0], v)
        for i in range(n):
            x[i, b] = x0[v, i]
        for i in range(p.shape[1]):
            pw[i, b] = p[bp, i]
        _copy_row(cp, v, cpw, b)
        _copy_row(cs0, v, cs, b)
        bb = shared_row(bounds.shape[0], v)
        for i in range(n):
            bw[i, b] = bounds[bb, i]
        fr = shared_row(friction.shape[0], v)
        for j in range(n_u):
            for c in range(len(FA)):
                fw[b, j, c] = friction[fr, j, c]
    return WorkingRows(vid=vid, x=x, xrow=xrow, p=pw, cp=cpw, cs=cs, axes=fw, bounds=bw), n_free


@inner_njit(cache=True, error_model="numpy")
def friction_modes(axes: FloatArray, xrow: FloatArray) -> FrictionModes:  # pragma: no cover - compiled
    """The friction modes of every slot's axes at t_0 (Appendix A) from the initial states by
    rows, xrow; no slot stopped (:class:`FrictionModes`)."""
    n_batch, n_u = axes.shape[0], axes.shape[1]
    modes = FrictionModes(
        mode=np.zeros((n_batch, n_u), dtype=np.int64), direction=np.zeros((n_batch, n_u)),
        hold=np.zeros((n_batch, n_u)), stopped=np.zeros(n_batch, dtype=np.bool_),
    )  # fmt: skip
    for b in range(n_batch):
        initial_modes(axes[b], xrow[b], modes.mode[b], modes.direction[b], modes.hold[b])
    return modes


@inner_njit(cache=True, error_model="numpy")
def working_slots(rows: WorkingRows, modes: FrictionModes, log: FloatArray) -> Slots:  # pragma: no cover - compiled
    """The working slots (:class:`~nlcx.kernel.structures.Slots`) of the working rows, the
    friction modes and the controller's log."""
    return Slots(
        vid=rows.vid, stopped=modes.stopped, x=rows.x, p=rows.p, bounds=rows.bounds, cp=rows.cp, cs=rows.cs, log=log,
        axes=rows.axes, mode=modes.mode, direction=modes.direction, hold=modes.hold,
    )  # fmt: skip


@inner_njit(cache=True, error_model="numpy")
def _copy_row(src: FloatArray, i: int, dst: FloatArray, j: int) -> None:  # pragma: no cover - compiled
    """dst[j, :] = src[i, :] element by element (a slice assignment compiles a shape check)."""
    for c in range(src.shape[1]):
        dst[j, c] = src[i, c]


@inner_njit(cache=True, error_model="numpy")
def friction_work(n: int, n_u: int, n_p: int, n_stage: int, n_d: int) -> FrictionWork:  # pragma: no cover - compiled
    """Work space of the one-variant friction path (:class:`~nlcx.kernel.structures.FrictionWork`),
    allocated once per :func:`~nlcx.kernel.integrator.simulate` call."""
    one = OneColumn(x=np.empty((n, 1)), u=np.empty((n_u, 1)), p=np.empty((n_p, 1)), dx=np.empty((n, 1)))
    scratch = FrictionScratch(
        k_stage=np.empty((n_stage, n, 1)), xs=np.empty((n, 1)), f=np.empty(n_u), work=np.empty(n_u),
        A=np.empty((n_u, n_u)), rhs_s=np.empty(n_u), dx=np.empty(n), d_tmp=np.empty(n_d), one=one,
    )  # fmt: skip
    column = (n, 1)
    return FrictionWork(x=np.empty(column), x_new=np.empty(column), x_mid=np.empty(column), u=np.empty((n_u, 1)),
                        scratch=scratch)  # fmt: skip


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


@inner_njit(cache=True, error_model="numpy")
def signal_rows(xrow: FloatArray, n_y: int, n_r: int, n_u: int, n_log: int) -> Signals:  # pragma: no cover - compiled
    """The work arrays of the signals (:class:`Signals`) beside the controller's copy of the
    state, xrow."""
    n_batch = xrow.shape[0]
    return Signals(
        xrow=xrow, y=np.empty((n_batch, n_y)), r=np.empty((n_batch, n_r)), u=np.empty((n_batch, n_u)),
        log=np.full((n_batch, n_log), np.nan), uc=np.empty((n_u, n_batch)),
    )  # fmt: skip


@inner_njit(cache=True, error_model="numpy")
def stage_columns(n_batch: int, n: int) -> StageColumns:  # pragma: no cover - compiled
    """The work arrays of a Runge-Kutta step (:class:`StageColumns`)."""
    return StageColumns(x_new=np.empty((n, n_batch)), xs=np.empty((n, n_batch)), k=np.zeros((MAX_STAGES, n, n_batch)))


@inner_njit(cache=True, error_model="numpy")
def flat_views(slots: Slots, stages: StageColumns) -> FlatViews:  # pragma: no cover - compiled
    """Flat views, made once, on the (n, B) arrays of a step: x, a stage's input, x_{k+1}, the
    bounds and the stage derivatives. The RK4 sums and the acceptance of x_{k+1} are one loop
    over every column, the inactive ones included (their values are never read again): a loop
    per state costs more than its work in a batch of a few variants."""
    size = slots.x.size
    k1, k2, k3, k4 = stages.k[0], stages.k[1], stages.k[2], stages.k[3]
    return FlatViews(
        x=slots.x.reshape(size), xs=stages.xs.reshape(size), x_new=stages.x_new.reshape(size),
        bounds=slots.bounds.reshape(size), k1=k1.reshape(size), k2=k2.reshape(size), k3=k3.reshape(size),
        k4=k4.reshape(size),
    )  # fmt: skip


@inner_njit(cache=True, error_model="numpy")
def init_outcome(n_steps: int, outcome: Outcome) -> None:  # pragma: no cover - compiled
    """Every variant ok until it stops."""
    status, n_valid, fail_index = outcome.status, outcome.n_valid, outcome.fail_index
    for v in range(status.shape[0]):
        status[v] = STATUS_OK
        fail_index[v] = -1
        n_valid[v] = n_steps + 1

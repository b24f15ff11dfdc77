"""The closed loop, stepped in lock step over a batch of variants.

Plants, controllers, controller callbacks and loop elements are numba-compiled functions
with the signatures of :mod:`nlcx.kernel.abi`. They are passed to :func:`simulate` as
first-class function values, so a single compiled (and disk-cached) kernel serves every
plant, controller and element, including those registered by third-party packages. The
engine hands them over with the batch's arrays in the named structures of
:mod:`nlcx.kernel.structures`.

Every sampling instant, one call of the controller, one call of each loop element and one
call of the right-hand side per Runge-Kutta stage serve every variant of the batch. A
single trajectory is a chain of dependent operations (each stage needs the one before);
stepping many variants together lets the processor overlap independent chains, and the
cost of a call is shared by the whole batch. Variants with friction (Appendix A,
:mod:`nlcx.kernel.friction`) are stepped one by one behind the frictionless ones.

The plant's state, parameters, input and stage derivatives are held by columns (column b:
the variant of working slot b, :data:`nlcx.kernel.abi.RHS_SIG`), so that the equations and
the Runge-Kutta sums run in vector code over the batch; the signals the controller and the
loop elements see (y, r, u, a copy of x, the controller's parameters and state) by rows.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from nlcx.kernel.abi import (
    ACTUATOR,
    ELEMENT_ENTRY,
    MAX_STAGES,
    SENSOR,
    STATUS_BOUND,
    STATUS_NONFINITE,
    STATUS_OK,
    shared_row,
)
from nlcx.kernel.friction import FA, has_friction, initial_modes
from nlcx.kernel.stepping import (
    SEQUENTIAL,
    add_disturbances,
    first_failing_state,
    hold_input,
    output_picks,
    rk_step,
    sample_signals,
    stage_nodes,
)
from nlcx.kernel.structures import (
    CLASSIC_RK4,
    SIMULATE_SIG,
    FrictionScratch,
    FrictionWork,
    OneColumn,
    Slots,
)

EE = ELEMENT_ENTRY.at


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
    """Flat views (n B,), made once, on the (n, B) arrays of a step (:func:`_flat_views`)."""

    x: np.ndarray
    xs: np.ndarray
    x_new: np.ndarray
    bounds: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray


@njit(cache=True, error_model="numpy")
def _swap_variants(i, j, slots):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _swap_rows(a, i, j):  # pragma: no cover - compiled
    """Exchange rows i and j of a 2-D array."""
    for c in range(a.shape[1]):
        a[i, c], a[j, c] = a[j, c], a[i, c]


@njit(cache=True, error_model="numpy")
def _swap_columns(a, i, j):  # pragma: no cover - compiled
    """Exchange columns i and j of a 2-D array."""
    for r in range(a.shape[0]):
        a[r, i], a[r, j] = a[r, j], a[r, i]


@njit(cache=True, error_model="numpy")
def _swap_rows3(a, i, j):  # pragma: no cover - compiled
    """Exchange rows i and j of a 3-D array."""
    for c in range(a.shape[1]):
        for d in range(a.shape[2]):
            a[i, c, d], a[j, c, d] = a[j, c, d], a[i, c, d]


@njit(cache=True, error_model="numpy")
def _row_order(friction, n_batch):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _working_rows(plant, controller, friction, n_u):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _friction_modes(axes, xrow):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _slots(rows, modes, log):  # pragma: no cover - compiled
    """The working slots (:class:`~nlcx.kernel.structures.Slots`) of the working rows, the
    friction modes and the controller's log."""
    return Slots(
        vid=rows.vid, stopped=modes.stopped, x=rows.x, p=rows.p, bounds=rows.bounds, cp=rows.cp, cs=rows.cs, log=log,
        axes=rows.axes, mode=modes.mode, direction=modes.direction, hold=modes.hold,
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def _copy_row(src, i, dst, j):  # pragma: no cover - compiled
    """dst[j, :] = src[i, :] element by element (a slice assignment compiles a shape check)."""
    for c in range(src.shape[1]):
        dst[j, c] = src[i, c]


@njit(cache=True, error_model="numpy")
def _friction_work(n, n_u, n_p, n_stage, n_d):  # pragma: no cover - compiled
    """Work space of the one-variant friction path (:class:`~nlcx.kernel.structures.FrictionWork`),
    allocated once per :func:`simulate` call."""
    one = OneColumn(x=np.empty((n, 1)), u=np.empty((n_u, 1)), p=np.empty((n_p, 1)), dx=np.empty((n, 1)))
    scratch = FrictionScratch(
        k_stage=np.empty((n_stage, n, 1)), xs=np.empty((n, 1)), f=np.empty(n_u), work=np.empty(n_u),
        A=np.empty((n_u, n_u)), rhs_s=np.empty(n_u), dx=np.empty(n), d_tmp=np.empty(n_d), one=one,
    )  # fmt: skip
    column = (n, 1)
    return FrictionWork(x=np.empty(column), x_new=np.empty(column), x_mid=np.empty(column), u=np.empty((n_u, 1)),
                        scratch=scratch)  # fmt: skip


@njit(cache=True, inline="always", error_model="numpy")
def _apply_elements(hook, t, dt, k, signal, vid, fns, table, ep, es, data):  # pragma: no cover - compiled
    """Every loop element at ``hook`` acts on ``signal`` (the active rows), in table order
    (:class:`~nlcx.kernel.structures.LoopElements`; ``es``: the elements' state)."""
    for e in range(table.shape[0]):
        if int(table[e, EE.hook]) == hook:
            fn = fns[int(table[e, EE.slot])]
            fn(
                t, dt, k, signal, vid, ep, es, data,
                int(table[e, EE.param_offset]), int(table[e, EE.state_offset]), int(table[e, EE.data_offset]),
            )  # fmt: skip


@njit(cache=True, error_model="numpy")
def _hook_counts(table):  # pragma: no cover - compiled
    """(number of sensor elements, number of actuator elements) in the element table."""
    n_sensor = 0
    n_actuator = 0
    for e in range(table.shape[0]):
        if int(table[e, EE.hook]) == SENSOR:
            n_sensor += 1
        elif int(table[e, EE.hook]) == ACTUATOR:
            n_actuator += 1
    return n_sensor, n_actuator


@njit(cache=True, inline="always", error_model="numpy")
def _record_states(k, nb, vid, x, X):  # pragma: no cover - compiled
    """Record x_k of every active variant."""
    for b in range(nb):
        v = vid[b]
        for i in range(x.shape[0]):
            X[v, k, i] = x[i, b]


@njit(cache=True, inline="always", error_model="numpy")
def _record_inputs(k, nb, n, vid, u, uc, log, stopped, U, LOG, status, n_valid, fail_index):  # pragma: no cover
    """Record the logs and the applied input u_k of every active row and hold it by columns
    in uc (the plant's input over the step); a row whose input is not finite stops (its
    outcome: status, failing input). Returns the number of rows stopped."""
    record = LOG.shape[1] > 1
    n_stop = 0
    for b in range(nb):
        v = vid[b]
        if record:
            for i in range(log.shape[1]):
                LOG[v, k, i] = log[b, i]
        for j in range(u.shape[1]):
            U[v, k, j] = u[b, j]
        bad_u = hold_input(b, u, uc)
        if bad_u >= 0:
            status[v] = STATUS_NONFINITE
            fail_index[v] = n + bad_u
            n_valid[v] = k + 1
            stopped[b] = True
            n_stop += 1
    return n_stop


@njit(cache=True, error_model="numpy")
def _clear_columns(start, stop, arrays):  # pragma: no cover - compiled
    """Zero columns start..stop-1 (variants that just left the batch) of ``arrays``: the state,
    x_{k+1} and the stage derivatives. The flat loops over every column then keep them zero and
    within bounds, whichever tableau integrates."""
    for a in arrays:
        for i in range(a.shape[0]):
            for b in range(start, stop):
                a[i, b] = 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _accept_states(k, nb, vid, x, bw, xf, xnf, bwf, stopped, status, n_valid, fail_index):  # pragma: no cover
    """x_{k+1} for every active variant; one whose state is non-finite or past its bound
    stops (its outcome: status and the first failing state). Returns the number of variants
    stopped.

    One loop over the flat views (:class:`FlatViews`) of x, x_new and the bounds, xf, xnf and
    bwf, takes the new states of every column and counts the states not finite or past their
    bounds (vector code); only if there are any are the active variants examined one by one.
    The columns from nb on hold zeros (:func:`_clear_columns`), and a variant its input stopped
    is not read again."""
    n_bad = 0
    for q in range(xf.shape[0]):
        v = xnf[q]
        xf[q] = v
        n_bad += (not abs(v) < np.inf) | (abs(v) > bwf[q])
    if n_bad == 0:
        return 0
    n_stop = 0
    for b in range(nb):
        if stopped[b]:
            continue
        bad = first_failing_state(x, b, bw)
        if bad < 0:
            continue
        v = vid[b]
        status[v] = STATUS_NONFINITE if not np.isfinite(x[bad, b]) else STATUS_BOUND
        fail_index[v] = bad
        n_valid[v] = k + 1
        stopped[b] = True
        n_stop += 1
    return n_stop


@njit(cache=True, error_model="numpy")
def _compact(nb, n_free, slots):  # pragma: no cover - compiled
    """Move the stopped variants behind the active ones, keeping the frictionless slots in
    front: a stopped frictionless slot trades places with the last frictionless one, which
    then trades with the last active one. Returns the new (nb, n_free)."""
    stopped = slots.stopped
    b = 0
    while b < nb:
        if not stopped[b]:
            b += 1
            continue
        if b < n_free:
            _swap_variants(b, n_free - 1, slots)
            _swap_variants(n_free - 1, nb - 1, slots)
            n_free -= 1
        else:
            _swap_variants(b, nb - 1, slots)
        nb -= 1
    return nb, n_free


@njit(cache=True, error_model="numpy")
def _signal_rows(xrow, n_y, n_r, n_u, n_log):  # pragma: no cover - compiled
    """The work arrays of the signals (:class:`Signals`) beside the controller's copy of the
    state, xrow."""
    n_batch = xrow.shape[0]
    return Signals(
        xrow=xrow, y=np.empty((n_batch, n_y)), r=np.empty((n_batch, n_r)), u=np.empty((n_batch, n_u)),
        log=np.full((n_batch, n_log), np.nan), uc=np.empty((n_u, n_batch)),
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def _stage_columns(n_batch, n):  # pragma: no cover - compiled
    """The work arrays of a Runge-Kutta step (:class:`StageColumns`)."""
    return StageColumns(x_new=np.empty((n, n_batch)), xs=np.empty((n, n_batch)), k=np.zeros((MAX_STAGES, n, n_batch)))


@njit(cache=True, error_model="numpy")
def _flat_views(slots, stages):  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _init_outcome(n_steps, outcome):  # pragma: no cover - compiled
    """Every variant ok until it stops."""
    status, n_valid, fail_index = outcome.status, outcome.n_valid, outcome.fail_index
    for v in range(status.shape[0]):
        status[v] = STATUS_OK
        fail_index[v] = -1
        n_valid[v] = n_steps + 1


@njit(cache=True, inline="always", error_model="numpy")
def _no_friction_recorded(k, nb, vid, stopped, FRICTION):  # pragma: no cover - compiled
    """Zero friction force at t_k for every active row of a batch without friction."""
    for b in range(nb):
        if stopped[b]:
            continue
        for j in range(FRICTION.shape[2]):
            FRICTION[vid[b], k, j] = 0.0


@njit(cache=True, error_model="numpy")
def _step_batch(
    integration, plant, controller, elements, forces, records, outcome, friction_path, slots, n_free, signals, stages,
    work,
):  # pragma: no cover - compiled  # fmt: skip
    """The sampling steps of :func:`simulate` over its working slots, signals, stage columns and
    friction work space, until every variant stopped or reached t_K."""
    rhs, C, ref, step, callbacks = plant.rhs, plant.C, controller.ref, controller.step, controller.callbacks
    X, U, LOG, FRICTION = records.X, records.U, records.LOG, records.FRICTION
    dist, dist_map, dt = forces.dist, forces.dist_map, integration.dt
    vid, stopped, x, pw, bw, cpw, cs = slots.vid, slots.stopped, slots.x, slots.p, slots.bounds, slots.cp, slots.cs
    log, status, n_valid, fail_index = slots.log, outcome.status, outcome.n_valid, outcome.fail_index
    xrow, y, r, u, uc = signals.xrow, signals.y, signals.r, signals.u, signals.uc
    x_new, xs, ks = stages.x_new, stages.xs, stages.k
    k1, k2, k3, k4 = ks[0], ks[1], ks[2], ks[3]
    flat = _flat_views(slots, stages)
    xf, xsf, xnf, bwf, k1f, k2f, k3f, k4f = flat.x, flat.xs, flat.x_new, flat.bounds, flat.k1, flat.k2, flat.k3, flat.k4
    rk_a, rk_b, classic = integration.rk_a, integration.rk_b, integration.method == CLASSIC_RK4
    c, picked = stage_nodes(rk_a), output_picks(C)
    fns, table, ep, es, data = elements.functions, elements.table, elements.ep, elements.es0.copy(), elements.data
    n_sensor, n_actuator = _hook_counts(table)
    n_steps, nb, m = X.shape[1] - 1, x.shape[1], x.size
    yv, rv, uv, xv, cpv, csv, logv = y, r, u, xrow, cpw, cs, log
    for k in range(n_steps + 1):
        t = k * dt
        _record_states(k, nb, vid, x, X)
        sample_signals(nb, vid, x, xrow, C, picked, y, ref, shared_row(ref.shape[1], k), r, u)
        if n_sensor > 0:  # (a call handing over the function table costs even when it does nothing)
            _apply_elements(SENSOR, t, dt, k, yv, vid, fns, table, ep, es, data)
        step(t, dt, xv, yv, rv, cpv, csv, uv, logv, callbacks)
        if n_actuator > 0:
            _apply_elements(ACTUATOR, t, dt, k, uv, vid, fns, table, ep, es, data)
        n_stop = _record_inputs(k, nb, x.shape[0], vid, u, uc, log, stopped, U, LOG, status, n_valid, fail_index)
        if nb > n_free:
            friction_path.sample(rhs, t, k, nb, n_free, slots, u, forces, work, records)
        elif FRICTION.shape[1] > 1:
            _no_friction_recorded(k, nb, vid, stopped, FRICTION)
        if k < n_steps and nb > n_stop:
            kd = shared_row(dist.shape[1], k)
            if n_free > 0 and classic:  # rk_step's CLASSIC written out in flat loops (the module docstring)
                rhs(t, x, uc, pw, k1, n_free)
                add_disturbances(k1, n_free, dist, vid, kd, 0, dist_map)
                for q in range(m):
                    xsf[q] = xf[q] + 0.5 * dt * k1f[q]
                rhs(t + 0.5 * dt, xs, uc, pw, k2, n_free)
                add_disturbances(k2, n_free, dist, vid, kd, 1, dist_map)
                for q in range(m):
                    xsf[q] = xf[q] + 0.5 * dt * k2f[q]
                rhs(t + 0.5 * dt, xs, uc, pw, k3, n_free)
                add_disturbances(k3, n_free, dist, vid, kd, 2, dist_map)
                for q in range(m):
                    xsf[q] = xf[q] + dt * k3f[q]
                rhs(t + dt, xs, uc, pw, k4, n_free)
                add_disturbances(k4, n_free, dist, vid, kd, 3, dist_map)
                for q in range(m):
                    xnf[q] = xf[q] + dt / 6.0 * (k1f[q] + 2.0 * (k2f[q] + k3f[q]) + k4f[q])
            elif n_free > 0:
                rk_step(
                    rhs, t, dt, n_free, x, x_new, uc, pw, ks, xs, rk_a, rk_b, c, SEQUENTIAL, dist, vid, kd, dist_map,
                    None,
                )  # fmt: skip
            if nb > n_free:
                friction_path.step(rhs, t, kd, nb, n_free, slots, x_new, u, forces, work, integration, c)
            n_stop += _accept_states(k, nb, vid, x, bw, xf, xnf, bwf, stopped, status, n_valid, fail_index)
        if n_stop > 0:
            nb_before = nb
            nb, n_free = _compact(nb, n_free, slots)
            _clear_columns(nb, nb_before, (x, x_new, k1, k2, k3, k4))
            if nb == 0:
                break
            yv, rv, uv, xv, cpv, csv, logv = y[:nb], r[:nb], u[:nb], xrow[:nb], cpw[:nb], cs[:nb], log[:nb]


@njit(SIMULATE_SIG, cache=True, error_model="numpy")
def simulate(integration, plant, controller, elements, forces, records, outcome, friction_path):  # pragma: no cover
    """Integrate a batch of closed loops in lock step (see the module docstring): at t_k = k dt
    y_k = C x_k, SENSOR elements, controller -> u_k, ACTUATOR elements; u_k held while the
    method of ``integration`` integrates to t_{k+1}, disturbances at the stage times, friction
    on each input's axis. A variant that goes non-finite or out of bounds stops and leaves the
    batch (active variants lead the working slots; ``slots.vid`` maps a slot to its variant).
    The arguments are the structures of :mod:`nlcx.kernel.structures`; the kernel writes
    ``records`` and ``outcome``."""
    n_batch, n = plant.x0.shape
    n_u = records.U.shape[2]
    rows, n_free = _working_rows(plant, controller, forces.friction, n_u)
    signals = _signal_rows(rows.xrow, plant.C.shape[0], controller.ref.shape[2], n_u, records.LOG.shape[2])
    stages = _stage_columns(n_batch, n)
    modes = _friction_modes(rows.axes, rows.xrow)
    _init_outcome(records.X.shape[1] - 1, outcome)
    work = _friction_work(n, n_u, plant.p.shape[1], integration.rk_b.shape[0], forces.dist.shape[3])
    _step_batch(integration, plant, controller, elements, forces, records, outcome, friction_path,
                _slots(rows, modes, signals.log), n_free, signals, stages, work)  # fmt: skip

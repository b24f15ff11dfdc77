"""The closed loop, stepped in lock step over a batch of variants.

Plants, controllers, controller callbacks and loop elements are numba-compiled functions
with the signatures of :mod:`nlcx.kernel.abi`. They are passed to :func:`simulate` as
first-class function values, so a single compiled (and disk-cached) kernel serves every
plant, controller and element, including those registered by third-party packages.

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

import numpy as np
from numba import njit, types

from nlcx.kernel.abi import (
    ACTUATOR,
    ARR3,
    ELEMENT_ENTRY,
    F64,
    IVEC,
    MAT,
    SENSOR,
    STATUS_BOUND,
    STATUS_NONFINITE,
    STATUS_OK,
    VEC,
    CallbackTuple,
    ControllerFn,
    ElementTuple,
    ForceArrays,
    FrictionPath,
    Records,
    RhsFn,
    shared_row,
)
from nlcx.kernel.friction import FA, has_friction, initial_modes

EE = ELEMENT_ENTRY.at

#: The arrays of one batch, grouped by what they describe (rows are variants; an axis of
#: length 1 is shared by every variant):
#: plant (x0 (B, n), p (B|1, n_p), C (n_y, n), bounds (B|1, n): |x_i| > bounds[i] stops a run)
PlantArrays = types.UniTuple(MAT, 4)
#: control (cp (B, n_cp), cs0 (B, n_cs), ref (B|1, K+1|1, n_r) reference at the sampling instants)
ControlArrays = types.Tuple((MAT, MAT, ARR3))
#: elements (table (n_el, ELEMENT_ENTRY), ep (B, n_ep), es0 (B, n_es), data (B|1, K+1|1, n_data))
ElementArrays = types.Tuple((MAT, MAT, MAT, ARR3))
#: plant forces (:data:`~nlcx.kernel.abi.ForceArrays`: dist (B|1, K|1, s, n_d) derivative terms
#: at the stage times, dist_map (n, n_d): dx += dist_map @ d, friction (B|1, n_u, FRICTION_AXIS)
#: of each input's axis)
#: records, written (:data:`~nlcx.kernel.abi.Records`: X (B, K+1, n), U (B, K+1, n_u), LOG
#: (B, K+1|1, n_log), FRICTION (B, K+1|1, n_u)); a time length of 1 for LOG and FRICTION: not recorded
#: outcome, written (status (B,), n_valid (B,), fail_index (B,): i < n state i, n + j input j, -1 none)
Outcome = types.UniTuple(IVEC, 3)

SIMULATE_SIG = types.void(
    RhsFn,
    ControllerFn,
    CallbackTuple,
    ElementTuple,
    types.Tuple((MAT, VEC)),  # Butcher tableau (rk_a (s, s), rk_b (s,))
    PlantArrays,
    ControlArrays,
    ElementArrays,
    ForceArrays,
    F64,  # dt
    Records,
    Outcome,
    FrictionPath,
)


@njit(cache=True, inline="always", error_model="numpy")
def _add_disturbances(dx, nb, dist, vid, kd, stage, dist_map):  # pragma: no cover - compiled
    """dx[:, b] += dist_map @ dist[variant of b, kd, stage] for the first nb columns."""
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
def _rk_step_batch(
    rhs, t, h, nb, x, x_out, u, p, dist, vid, kd, dist_map, rk_a, rk_b, c, stages, xs
):  # pragma: no cover - compiled
    """One explicit Runge-Kutta step of size h for the first nb columns, any tableau of at most
    :data:`MAX_STAGES` stages (u held, no friction). ``stages`` holds one (n, B) array per stage."""
    n = x.shape[0]
    n_stage = rk_b.shape[0]
    for s in range(n_stage):
        for i in range(n):
            for b in range(nb):
                acc = x[i, b]
                for j in range(s):
                    if rk_a[s, j] != 0.0:
                        acc += h * rk_a[s, j] * stages[j][i, b]
                xs[i, b] = acc
        rhs(t + c[s] * h, xs, u, p, stages[s], nb)
        _add_disturbances(stages[s], nb, dist, vid, kd, s, dist_map)
    for i in range(n):
        for b in range(nb):
            acc = x[i, b]
            for s in range(n_stage):
                acc += h * rk_b[s] * stages[s][i, b]
            x_out[i, b] = acc


@njit(cache=True, error_model="numpy")
def _swap_variants(i, j, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode):  # pragma: no cover
    """Exchange the working slots i and j (two variants' state, parameters and bookkeeping):
    columns of the plant's state and parameters, rows of the rest."""
    if i == j:
        return
    vid[i], vid[j] = vid[j], vid[i]
    stopped[i], stopped[j] = stopped[j], stopped[i]
    for a in (x, pw, bw):
        _swap_columns(a, i, j)
    for a in (cpw, cs, log, direction, hold):
        _swap_rows(a, i, j)
    _swap_rows3(fw, i, j)
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
def _stage_nodes(rk_a):  # pragma: no cover - compiled
    """c_i = sum_j a_ij: the stage times t_k + c_i dt."""
    n_stage = rk_a.shape[0]
    c = np.zeros(n_stage)
    for i in range(n_stage):
        for j in range(n_stage):
            c[i] += rk_a[i, j]
    return c


@njit(cache=True, error_model="numpy")
def _is_classic_rk4(rk_a, rk_b):  # pragma: no cover - compiled
    """Whether the tableau is the classic fourth-order Runge-Kutta method (stepped written out)."""
    return (
        rk_b.shape[0] == 4
        and rk_a[1, 0] == 0.5 and rk_a[2, 1] == 0.5 and rk_a[3, 2] == 1.0
        and rk_a[2, 0] == 0.0 and rk_a[3, 0] == 0.0 and rk_a[3, 1] == 0.0
        and rk_b[0] == 1.0 / 6.0 and rk_b[1] == 2.0 / 6.0 and rk_b[2] == 2.0 / 6.0 and rk_b[3] == 1.0 / 6.0
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def _output_picks(C):  # pragma: no cover - compiled
    """picked[i] = j where row i of C is the unit vector e_j (y_i = x_j exactly), else -1."""
    n_y, n = C.shape
    picked = np.full(n_y, -1)
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
def _working_rows(vid, plant, control, friction, n_u):  # pragma: no cover - compiled
    """The working copies in the order of vid: the plant's state and parameters by columns
    and the bounds (x (n, B), pw (n_p, B), bw (n, B)); x0's rows (the controller's copy of the
    state), cp, cs and the friction axes by rows."""
    x0, p, _, bounds = plant
    cp, cs0, _ = control
    n_batch, n = x0.shape
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
    return x, xrow, pw, cpw, cs, fw, bw


@njit(cache=True, error_model="numpy")
def _copy_row(src, i, dst, j):  # pragma: no cover - compiled
    """dst[j, :] = src[i, :] element by element (a slice assignment compiles a shape check)."""
    for c in range(src.shape[1]):
        dst[j, c] = src[i, c]


@njit(cache=True, error_model="numpy")
def _friction_scratch(n, n_u, n_p, n_stage, n_d):  # pragma: no cover - compiled
    """Work space of the one-variant friction path, allocated once per :func:`simulate` call:
    (x, x_new, x_mid, u) of the variant and the scratch tuple of
    :func:`nlcx.kernel.friction.step_with_friction` (its ``one``: the variant as the single
    column the plant's right-hand side takes)."""
    one = (np.empty((n, 1)), np.empty((n_u, 1)), np.empty((n_p, 1)), np.empty((n, 1)))
    k_stage = np.empty((n_stage, n))
    scratch = (
        k_stage, np.empty(n), np.empty(n_u), np.empty(n_u), np.empty(n_u),
        np.empty((n_u, n_u)), np.empty(n_u), np.empty(n), np.empty(n_d), one,
    )  # fmt: skip
    return (np.empty(n), np.empty(n), np.empty(n), np.empty(n_u)), scratch


@njit(cache=True, inline="always", error_model="numpy")
def _apply_elements(hook, t, dt, k, signal, vid, fns, table, ep, es, data):  # pragma: no cover - compiled
    """Every loop element at ``hook`` acts on ``signal`` (the active rows), in table order."""
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
def _sample(k, nb, vid, x, xrow, C, picked, y, ref, r, u, X):  # pragma: no cover - compiled
    """At t_k, for every active variant: record x_k, copy it into its row of xrow (the
    controller's), measure y_k = C x_k, read r_k, clear u."""
    n = x.shape[0]
    kr = shared_row(ref.shape[1], k)
    for b in range(nb):
        v = vid[b]
        for i in range(n):
            X[v, k, i] = x[i, b]
            xrow[b, i] = x[i, b]
        for i in range(y.shape[1]):
            if picked[i] >= 0:  # a row of C that selects one state
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
def _record_inputs(k, nb, n, vid, u, uc, log, stopped, U, LOG, status, n_valid, fail_index):  # pragma: no cover
    """Record the logs and the applied input u_k of every active row and hold it by columns
    in uc (the plant's input over the step); a row whose input is not finite stops (status,
    failing input). Returns the number of rows stopped."""
    record = LOG.shape[1] > 1
    n_stop = 0
    for b in range(nb):
        v = vid[b]
        if record:
            for i in range(log.shape[1]):
                LOG[v, k, i] = log[b, i]
        bad_u = -1
        for j in range(u.shape[1]):
            U[v, k, j] = u[b, j]
            uc[j, b] = u[b, j]
            if bad_u < 0 and not np.isfinite(u[b, j]):
                bad_u = j
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
def _accept_states(k, nb, vid, x, x_new, bw, flat, stopped, status, n_valid, fail_index):  # pragma: no cover
    """x_{k+1} for every active variant; one whose state is non-finite or past its bound
    stops (status and the first failing state). Returns the number of variants stopped.

    One loop over the flat views ``flat`` = (x, x_new, bw) takes the new states of every column
    and counts the states not finite or past their bounds (vector code); only if there are any
    are the active variants examined one by one. The columns from nb on hold zeros
    (:func:`_clear_columns`), and a variant its input stopped is not read again."""
    xf, xnf, bwf = flat
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
        bad = 0
        while bad < x.shape[0] and np.isfinite(x[bad, b]) and abs(x[bad, b]) <= bw[bad, b]:
            bad += 1
        if bad == x.shape[0]:
            continue
        v = vid[b]
        status[v] = STATUS_NONFINITE if not np.isfinite(x[bad, b]) else STATUS_BOUND
        fail_index[v] = bad
        n_valid[v] = k + 1
        stopped[b] = True
        n_stop += 1
    return n_stop


@njit(cache=True, error_model="numpy")
def _compact(nb, n_free, vid, rows, fw, state):  # pragma: no cover - compiled
    """Move the stopped variants behind the active ones, keeping the frictionless rows in
    front: a stopped frictionless row trades places with the last frictionless row, which
    then trades with the last active row. Returns the new (nb, n_free)."""
    x, pw, cpw, cs, log, bw = rows
    mode, direction, hold, stopped = state
    b = 0
    while b < nb:
        if not stopped[b]:
            b += 1
            continue
        if b < n_free:
            _swap_variants(b, n_free - 1, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode)
            _swap_variants(n_free - 1, nb - 1, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode)
            n_free -= 1
        else:
            _swap_variants(b, nb - 1, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode)
        nb -= 1
    return nb, n_free


@njit(cache=True, error_model="numpy")
def _signal_rows(n_batch, n_y, n_r, n_u, n_log):  # pragma: no cover - compiled
    """Work arrays of the signals: y, r, u and the controller log (NaN until written) by rows,
    and u by columns (the plant's input)."""
    return (
        np.empty((n_batch, n_y)),
        np.empty((n_batch, n_r)),
        np.empty((n_batch, n_u)),
        np.full((n_batch, n_log), np.nan),
        np.empty((n_u, n_batch)),
    )


@njit(cache=True, error_model="numpy")
def _stage_columns(n_batch, n):  # pragma: no cover - compiled
    """Work arrays (n, B) of a Runge-Kutta step: x_{k+1}, a stage's input and (up to) four
    stage derivatives, the latter zero where no right-hand side writes them (the columns of
    variants with friction)."""
    stages = (np.zeros((n, n_batch)), np.zeros((n, n_batch)), np.zeros((n, n_batch)), np.zeros((n, n_batch)))
    return np.empty((n, n_batch)), np.empty((n, n_batch)), stages


@njit(cache=True, error_model="numpy")
def _friction_state(fw, x):  # pragma: no cover - compiled
    """(mode, direction, hold, stopped) of every row's friction axes at t_0 (Appendix A);
    x: the initial states by rows."""
    n_batch, n_u = fw.shape[0], fw.shape[1]
    state = (np.zeros((n_batch, n_u), dtype=np.int64), np.zeros((n_batch, n_u)), np.zeros((n_batch, n_u)),
             np.zeros(n_batch, dtype=np.bool_))  # fmt: skip
    for b in range(n_batch):
        initial_modes(fw[b], x[b], state[0][b], state[1][b], state[2][b])
    return state


@njit(cache=True, error_model="numpy")
def _flat_views(x, xs, x_new, bw, stages):  # pragma: no cover - compiled
    """Flat views, made once, on the (n, B) arrays of a step: x, a stage's input, x_{k+1}, the
    bounds and the stage derivatives. The RK4 sums and the acceptance of x_{k+1} are one loop
    over every column, the inactive ones included (their values are never read again): a loop
    per state costs more than its work in a batch of a few variants."""
    size = x.size
    k1, k2, k3, k4 = stages
    return (x.reshape(size), xs.reshape(size), x_new.reshape(size), bw.reshape(size),
            k1.reshape(size), k2.reshape(size), k3.reshape(size), k4.reshape(size))  # fmt: skip


@njit(cache=True, error_model="numpy")
def _init_outcome(n_steps, outcome):  # pragma: no cover - compiled
    """Every variant ok until it stops."""
    status, n_valid, fail_index = outcome
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


@njit(SIMULATE_SIG, cache=True, error_model="numpy")
def simulate(
    rhs, controller, callbacks, element_fns, tableau, plant, control, elements, forces, dt, records, outcome, frictional
):  # pragma: no cover - compiled
    """Integrate a batch of closed loops in lock step (see the module docstring): at t_k = k dt
    y_k = C x_k, SENSOR elements, controller -> u_k, ACTUATOR elements; u_k held while the
    tableau (rk_a, rk_b) integrates to t_{k+1}, disturbances at the stage times, friction on
    each input's axis. A variant that goes non-finite or out of bounds stops and leaves the
    batch (active variants lead the working rows; ``vid`` maps a row to its variant)."""
    rk_a, rk_b = tableau
    x0, p, C, _ = plant
    ref = control[2]
    X, U, LOG, _ = records
    dist, dist_map, friction = forces
    n_batch, n = x0.shape
    n_u, n_steps = U.shape[2], X.shape[1] - 1
    c = _stage_nodes(rk_a)
    classic = _is_classic_rk4(rk_a, rk_b)
    picked = _output_picks(C)
    vid, n_free = _row_order(friction, n_batch)
    x, xrow, pw, cpw, cs, fw, bw = _working_rows(vid, plant, control, friction, n_u)
    y, r, u, log, uc = _signal_rows(n_batch, C.shape[0], ref.shape[2], n_u, LOG.shape[2])
    x_new, xs, (k1, k2, k3, k4) = _stage_columns(n_batch, n)
    xf, xsf, xnf, bwf, k1f, k2f, k3f, k4f = _flat_views(x, xs, x_new, bw, (k1, k2, k3, k4))
    m = n * n_batch
    state = _friction_state(fw, xrow)
    _init_outcome(n_steps, outcome)
    one_path = _friction_scratch(n, n_u, p.shape[1], rk_b.shape[0], dist.shape[3])
    table, ep, es, data = elements[0], elements[1], elements[2].copy(), elements[3]
    n_sensor, n_actuator = _hook_counts(table)
    (status, n_valid, fail_index), FRICTION, stopped, nb = outcome, records[3], state[3], n_batch
    yv, rv, uv, xv, cpv, csv, logv = y, r, u, xrow, cpw, cs, log
    for k in range(n_steps + 1):
        t = k * dt
        _sample(k, nb, vid, x, xrow, C, picked, y, ref, r, u, X)
        if n_sensor > 0:  # (a call handing over the function table costs even when it does nothing)
            _apply_elements(SENSOR, t, dt, k, yv, vid, element_fns, table, ep, es, data)
        controller(t, dt, xv, yv, rv, cpv, csv, uv, logv, callbacks)
        if n_actuator > 0:
            _apply_elements(ACTUATOR, t, dt, k, uv, vid, element_fns, table, ep, es, data)
        n_stop = _record_inputs(k, nb, n, vid, u, uc, log, stopped, U, LOG, status, n_valid, fail_index)
        if nb > n_free:
            frictional[0](rhs, t, k, nb, n_free, vid, x, u, pw, fw, state, forces, one_path, records)
        elif FRICTION.shape[1] > 1:
            _no_friction_recorded(k, nb, vid, stopped, FRICTION)
        if k < n_steps and nb > n_stop:
            kd = shared_row(dist.shape[1], k)
            if n_free > 0 and classic:  # written out here: as a helper it cost a large share of a step
                rhs(t, x, uc, pw, k1, n_free)
                _add_disturbances(k1, n_free, dist, vid, kd, 0, dist_map)
                for q in range(m):
                    xsf[q] = xf[q] + 0.5 * dt * k1f[q]
                rhs(t + 0.5 * dt, xs, uc, pw, k2, n_free)
                _add_disturbances(k2, n_free, dist, vid, kd, 1, dist_map)
                for q in range(m):
                    xsf[q] = xf[q] + 0.5 * dt * k2f[q]
                rhs(t + 0.5 * dt, xs, uc, pw, k3, n_free)
                _add_disturbances(k3, n_free, dist, vid, kd, 2, dist_map)
                for q in range(m):
                    xsf[q] = xf[q] + dt * k3f[q]
                rhs(t + dt, xs, uc, pw, k4, n_free)
                _add_disturbances(k4, n_free, dist, vid, kd, 3, dist_map)
                for q in range(m):
                    xnf[q] = xf[q] + dt / 6.0 * (k1f[q] + 2.0 * (k2f[q] + k3f[q]) + k4f[q])
            elif n_free > 0:
                _rk_step_batch(rhs, t, dt, n_free, x, x_new, uc, pw, dist, vid, kd, dist_map, rk_a, rk_b, c,
                               (k1, k2, k3, k4), xs)  # fmt: skip
            if nb > n_free:
                frictional[1](rhs, t, dt, kd, nb, n_free, vid, x, x_new, u, pw, fw, state, forces, one_path,
                              tableau, c)  # fmt: skip
            n_stop += _accept_states(k, nb, vid, x, x_new, bw, (xf, xnf, bwf), stopped, status, n_valid, fail_index)
        if n_stop > 0:
            nb_before = nb
            nb, n_free = _compact(nb, n_free, vid, (x, pw, cpw, cs, log, bw), fw, state)
            _clear_columns(nb, nb_before, (x, x_new, k1, k2, k3, k4))
            if nb == 0:
                break
            yv, rv, uv, xv, cpv, csv, logv = y[:nb], r[:nb], u[:nb], xrow[:nb], cpw[:nb], cs[:nb], log[:nb]

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
loop elements see (y, r, u, a copy of x, the controller's parameters and state) by rows. The
working slots, signals and stage columns of a call (``working``) are built before it, in numpy
(:func:`nlcx.kernel.working_storage.working_storage`): what runs once per call is not compiled.

One sampling step of :func:`simulate`, at t_k = k dt: y_k = C x_k, the SENSOR elements, the
controller (u_k), the ACTUATOR elements; u_k is held while the method of ``integration``
integrates to t_{k+1}, with the disturbances at the stage times and friction on each input's
axis. A variant that goes non-finite or out of bounds stops and leaves the batch (the active
variants lead the working slots; ``slots.vid`` maps a slot to its variant). The arguments are
the structures of :mod:`nlcx.kernel.structures`; the kernel writes ``records`` and ``outcome``.

:func:`simulate` is one compiled function: the sampling steps until every variant stopped or
reached t_K. numba compiles a function called by another into a
module of its own and then again into its caller's, so the steps, the bulk of the kernel,
written as a function of their own would be optimised and compiled twice.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from nlcx.kernel.abi import ACTUATOR, ELEMENT_ENTRY, SENSOR, STATUS_BOUND, STATUS_NONFINITE, shared_row
from nlcx.kernel.friction_path import FRICTIONAL, FRICTIONLESS
from nlcx.kernel.signatures import BoolArray, ElementFunctions, FloatArray, IntArray
from nlcx.kernel.stepping import SEQUENTIAL, add_disturbances, first_failing_state, hold_input, rk_step, sample_signals
from nlcx.kernel.structures import CLASSIC_RK4, SIMULATE_SIG
from nlcx.kernel.working_storage import clear_columns, compact, working_storage

if TYPE_CHECKING:
    from nlcx.kernel.structures import (
        ControllerCall,
        FrictionPath,
        Integration,
        LoopElements,
        Outcome,
        PlantCall,
        PlantForces,
        Records,
        Working,
    )

EE = ELEMENT_ENTRY.at


@njit(cache=True, inline="always", error_model="numpy")
def _apply_elements(
    hook: int,
    t: float,
    dt: float,
    k: int,
    signal: FloatArray,
    vid: IntArray,
    fns: ElementFunctions,
    table: FloatArray,
    ep: FloatArray,
    es: FloatArray,
    data: FloatArray,
) -> None:  # pragma: no cover - compiled
    """Every loop element at ``hook`` acts on ``signal`` (the active rows), in table order
    (:class:`~nlcx.kernel.structures.LoopElements`; ``es``: the elements' state)."""
    for e in range(table.shape[0]):
        if int(table[e, EE.hook]) == hook:
            fn = fns[int(table[e, EE.slot])]
            fn(
                t, dt, k, signal, vid, ep, es, data,
                int(table[e, EE.param_offset]), int(table[e, EE.state_offset]), int(table[e, EE.data_offset]),
            )  # fmt: skip


@njit(cache=True, inline="always", error_model="numpy")
def _record_states(k: int, nb: int, vid: IntArray, x: FloatArray, X: FloatArray) -> None:  # pragma: no cover - compiled
    """Record x_k of every active variant."""
    for b in range(nb):
        v = vid[b]
        for i in range(x.shape[0]):
            X[v, k, i] = x[i, b]


@njit(cache=True, inline="always", error_model="numpy")
def _record_inputs(
    k: int,
    nb: int,
    n: int,
    vid: IntArray,
    u: FloatArray,
    uc: FloatArray,
    log: FloatArray,
    stopped: BoolArray,
    U: FloatArray,
    LOG: FloatArray,
    status: IntArray,
    n_valid: IntArray,
    fail_index: IntArray,
) -> int:  # pragma: no cover
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


@njit(cache=True, inline="always", error_model="numpy")
def _accept_states(
    k: int,
    nb: int,
    vid: IntArray,
    x: FloatArray,
    bw: FloatArray,
    xf: FloatArray,
    xnf: FloatArray,
    bwf: FloatArray,
    stopped: BoolArray,
    status: IntArray,
    n_valid: IntArray,
    fail_index: IntArray,
) -> int:  # pragma: no cover
    """x_{k+1} for every active variant; one whose state is non-finite or past its bound
    stops (its outcome: status and the first failing state). Returns the number of variants
    stopped.

    One loop over the flat views (:class:`~nlcx.kernel.structures.FlatViews`) of x, x_new
    and the bounds, xf, xnf and bwf, takes the new states of every column and counts the states
    not finite or past their bounds (vector code); only if there are any are the active variants
    examined one by one. The columns from nb on hold zeros
    (:func:`~nlcx.kernel.working_storage.clear_columns`), and a variant its input stopped is not
    read again."""
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


@njit(cache=True, inline="always", error_model="numpy")
def _no_friction_recorded(
    k: int, nb: int, vid: IntArray, stopped: BoolArray, FRICTION: FloatArray
) -> None:  # pragma: no cover - compiled
    """Zero friction force at t_k for every active row of a batch without friction."""
    for b in range(nb):
        if stopped[b]:
            continue
        for j in range(FRICTION.shape[2]):
            FRICTION[vid[b], k, j] = 0.0


@njit(SIMULATE_SIG, cache=True, error_model="numpy")
def simulate(
    integration: Integration,
    plant: PlantCall,
    controller: ControllerCall,
    elements: LoopElements,
    forces: PlantForces,
    records: Records,
    outcome: Outcome,
    friction_path: FrictionPath,
    working: Working,
) -> None:  # pragma: no cover
    """Integrate a batch of closed loops in lock step into ``records`` and ``outcome`` (the module docstring)."""
    slots, signals, stages, flat, work = working.slots, working.signals, working.stages, working.flat, working.friction
    rhs, C, ref, step, callbacks = plant.rhs, plant.C, controller.ref, controller.step, controller.callbacks
    X, U, LOG, FRICTION = records.X, records.U, records.LOG, records.FRICTION
    dist, dist_map, dt = forces.dist, forces.dist_map, integration.dt
    vid, stopped, x, pw, bw, cpw, cs = slots.vid, slots.stopped, slots.x, slots.p, slots.bounds, slots.cp, slots.cs
    log, status, n_valid, fail_index = slots.log, outcome.status, outcome.n_valid, outcome.fail_index
    xrow, y, r, u, uc = signals.xrow, signals.y, signals.r, signals.u, signals.uc
    x_new, xs, ks = stages.x_new, stages.xs, stages.k
    k1, k2, k3, k4 = ks[0], ks[1], ks[2], ks[3]
    xf, xsf, xnf, bwf, k1f, k2f, k3f, k4f = flat.x, flat.xs, flat.x_new, flat.bounds, flat.k1, flat.k2, flat.k3, flat.k4
    rk_a, rk_b, classic = integration.rk_a, integration.rk_b, integration.method == CLASSIC_RK4
    c, picked, n_free = working.c, working.picked, working.n_free
    n_sensor, n_actuator = working.n_sensor, working.n_actuator
    fns, table, ep, es, data = elements.functions, elements.table, elements.ep, working.es, elements.data
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
            if n_free > 0 and classic:  # rk_step's CLASSIC written out in flat loops (nlcx.kernel.stepping)
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
                rk_step(rhs, t, dt, n_free, x, x_new, uc, pw, ks, xs, rk_a, rk_b, c, SEQUENTIAL, dist, vid, kd,
                        dist_map, None)  # fmt: skip
            if nb > n_free:
                friction_path.step(rhs, t, kd, nb, n_free, slots, x_new, u, forces, work, integration, c)
            n_stop += _accept_states(k, nb, vid, x, bw, xf, xnf, bwf, stopped, status, n_valid, fail_index)
        if n_stop > 0:
            nb_before, (nb, n_free) = nb, compact(nb, n_free, slots)
            clear_columns(nb, nb_before, (x, x_new, k1, k2, k3, k4))
            if nb == 0:
                break
            yv, rv, uv, xv, cpv, csv, logv = y[:nb], r[:nb], u[:nb], xrow[:nb], cpw[:nb], cs[:nb], log[:nb]


def integrate_batch(
    integration: Integration,
    plant: PlantCall,
    controller: ControllerCall,
    elements: LoopElements,
    forces: PlantForces,
    records: Records,
    outcome: Outcome,
) -> None:
    """One kernel call: its working storage built (:func:`~nlcx.kernel.working_storage.working_storage`),
    its friction path chosen (:data:`~nlcx.kernel.friction_path.FRICTIONAL` only where a variant
    has friction, so that a call without compiles none of it) and :func:`simulate` run."""
    working = working_storage(integration, plant, controller, elements, forces, records, outcome)
    path = FRICTIONAL if working.n_free < plant.x0.shape[0] else FRICTIONLESS
    simulate(integration, plant, controller, elements, forces, records, outcome, path, working)

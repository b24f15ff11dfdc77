"""The PID's compiled step: the layout of its parameter row and one loop body for every structure.

:mod:`nlcx.controllers.pid` packs a validated configuration into the parameter row ``cp``
declared here (:data:`HEAD`, :data:`INPUT`, :data:`LOOP`, then each loop's schedule block); the
kernel calls the step over the rows of a batch (:data:`nlcx.kernel.abi.CONTROLLER_SIG`):

    u_j = bias_j + sum_{loops i -> j} sign_i * [k_p e_i + k_i I_i + k_d D_i],   e_i = r_i - y_i

with (k_p, k_i, k_d) from the loop's gain schedule (constant, time-AGS eqs. 2.17-2.19,
error-AGS eqs. 2.20-2.22), I_i the backward-Euler integral of e_i, held within the loop's
integral limits [-L_i, L_i] where it has them, and D_i its derivative (of e_i or of -y_i), a
backward difference or filtered by N/(s + N); the saturation is the actuator's clamp
(:func:`nlcx.uncertainty.actuator_saturation.saturate`) with the anti-windup.

One body, two steps. The step is written once, :func:`_pid_rows`, over a loop structure
(:class:`Structure`: the loop count, each loop's indices, schedule, derivative, integral and
form, the sampling and saturation options) that is either read from each parameter row
(``structure`` None: :func:`pid_step`, for rows of any structure in one kernel call) or a
:class:`Structure` of compile-time constants (:func:`step_for`): numba removes the branches on
``structure is None`` before it types the body, and the compiler folds the constants, so the
step for a structure has no branch or index arithmetic on it and computes the same bits.
:func:`step_for` makes that step as a closure over its structure, once a structure, and names
it after a hash of the structure (:func:`structure_name`). The name matters: numba names a
compiled function's machine-code symbol after its qualified name and a counter that is unique
only within the process that compiled it. Closures sharing one name, compiled for different
structures by different processes (a sweep's or a study's workers) and saved to the disk
cache, can carry the same symbol; a process that then loads two of them runs one structure's
code for the other (seen as a fuzzy-PID loop that diverged or never moved). With the
structure in the name, different structures never share a symbol, and each has its own cache
files. :func:`nlcx._numba_compat.serialize_cache_access` keeps the processes that save at
once from overwriting each other's files.
"""

from __future__ import annotations

import functools
import hashlib
import math
from typing import NamedTuple

import numpy as np

from nlcx._numba_compat import hot_njit
from nlcx.controllers.schedules import constant_gains, error_ags_gains, time_ags_gains
from nlcx.kernel.abi import CONTROLLER_SIG
from nlcx.kernel.signatures import Callbacks, ControllerStep, FloatArray
from nlcx.layout import Layout
from nlcx.uncertainty.actuator_saturation import saturate

#: The head of the parameter row: number of loops and of inputs, the actuator saturation's
#: anti-windup (:data:`ANTI_WINDUP` code; -1: no saturation), back-calculation gain K_b and
#: the sampling period T_s of a discrete PID (0: sampled at every integration step).
HEAD = Layout("PIDHead", ("n_loops", "n_inputs", "anti_windup", "kb", "sample_time"))
H = HEAD.at
#: One block per input after the head: its constant bias and its limit |u_j| <= limit (inf: none).
INPUT = Layout("PIDInput", ("bias", "limit"))
I = INPUT.at
#: One loop's block, after the head and the biases: which output, reference and input it
#: uses, the sign of its contribution, its schedule (slot in the callback table, offset and
#: length of the schedule's parameters, built-in schedule called directly), the derivative
#: (filtered or backward, N, on the measurement or the error), the integral gain inside the
#: integral, the set-point weight b of the proportional term, the PID form (:data:`FORMS`),
#: the scale of the units the loop sees y and r in (e.g. 180/pi: an angle in degrees) and the
#: limit L of its integrator state, |I| <= L (inf: unlimited).
LOOP = Layout(
    "PIDLoop",
    (
        "y_index", "r_index", "u_index", "sign", "schedule_slot", "filtered", "N", "on_measurement",
        "gain_inside", "schedule_offset", "schedule_length", "setpoint_weight", "direct_schedule",
        "form", "scale", "integral_limit",
    ),
)  # fmt: skip
L = LOOP.at
#: The built-in schedules are called directly (the compiler inlines them; a call through the
#: slot table cannot be inlined, a sizeable share of a sweep's time); any other schedule,
#: including a third party's or a replaced built-in, goes through its slot.
VIA_SLOT, DIRECT_CONSTANT, DIRECT_TIME_AGS, DIRECT_ERROR_AGS = 0, 1, 2, 3
#: The built-in schedules' compiled functions and the way the step calls each directly.
DIRECT = {constant_gains: DIRECT_CONSTANT, time_ags_gains: DIRECT_TIME_AGS, error_ags_gains: DIRECT_ERROR_AGS}
#: One loop's controller state: integral, previous error, filtered derivative, previous y,
#: started, the integral's increment of the last sample (undone by clamping anti-windup), the
#: period of this step's update (dt, T_s, or 0 while a discrete PID holds its output), the
#: time of the next sample and the held output of a discrete PID.
LOOP_STATE = Layout(
    "PIDLoopState",
    ("integral", "e_prev", "d_filtered", "y_prev", "started", "increment", "period", "next_sample", "held"),
)
S = LOOP_STATE.at
#: One loop's logged values: k_p, k_i, k_d and the loop's signed contribution to its input.
LOOP_LOG = Layout("PIDLoopLog", ("kp", "ki", "kd", "u"))
G = LOOP_LOG.at
#: How the schedule's (k_p, k_i, k_d) act (Simulink's PID block forms): parallel
#: k_p + k_i/s + k_d s; ideal k_p (1 + k_i/s + k_d s); series k_p (1 + k_i/s)(1 + k_d s).
FORMS = {"parallel": 0, "ideal": 1, "series": 2}
#: Anti-windup of a saturated input (Simulink's PID block: none, clamping, back-calculation).
ANTI_WINDUP = {"off": -1, "none": 0, "clamping": 1, "back_calculation": 2}


@hot_njit(cache=True, inline="always", error_model="numpy")
def _within(value: float, limit: float) -> float:  # pragma: no cover - compiled
    """``value`` held within [-limit, limit], as a Simulink Integrator block's output limits hold
    its state: unchanged inside them and where it is NaN, so a limit of inf changes no bit."""
    if value > limit:
        return limit
    if value < -limit:
        return -limit
    return value


@hot_njit(cache=True, error_model="numpy")
def _saturate(
    row: int, cp: FloatArray, cs: FloatArray, u: FloatArray, log: FloatArray
) -> None:  # pragma: no cover - compiled
    """Clip each limited input to [-limit, limit] (:func:`~nlcx.uncertainty.actuator_saturation.saturate`)
    and correct the integrators of the loops on it that updated at this step (clamping: undo
    this sample's increment if it pushes further into the limit; back-calculation:
    I += K_b (u_sat - u) T through the loop's sign and integral gain, T the loop's update period,
    then held within the loop's integral limits)."""
    n_u = int(cp[row, H.n_inputs])
    base = len(H) + len(I) * n_u
    mode = int(cp[row, H.anti_windup])
    for i in range(int(cp[row, H.n_loops])):
        h = base + len(L) * i
        j = int(cp[row, h + L.u_index])
        excess = u[row, j] - saturate(u[row, j], cp[row, len(H) + len(I) * j + I.limit])
        if excess == 0.0:
            continue
        c = len(S) * i
        period = cs[row, c + S.period]
        if period == 0.0:
            continue
        sign = cp[row, h + L.sign]
        inside = cp[row, h + L.gain_inside] != 0.0
        ki = log[row, len(G) * i + G.ki]
        if mode == 1 and excess * sign * cs[row, c + S.increment] * (1.0 if inside else ki) > 0.0:
            cs[row, c + S.integral] -= cs[row, c + S.increment]
        elif mode == 2 and (inside or ki != 0.0):
            corrected = cs[row, c + S.integral] - sign * cp[row, H.kb] * excess * period / (1.0 if inside else ki)
            cs[row, c + S.integral] = _within(corrected, cp[row, h + L.integral_limit])
    for j in range(n_u):
        u[row, j] = saturate(u[row, j], cp[row, len(H) + len(I) * j + I.limit])


@hot_njit(cache=True, error_model="numpy")
def _update_period(
    t: float, dt: float, sample_time: float, cs: FloatArray, row: int, c: int
) -> float:  # pragma: no cover - compiled
    """The period a loop updates over at t: dt for a continuous PID (T_s = 0); T_s at a
    discrete PID's sampling instant (the next one scheduled T_s later); 0 while it holds."""
    if sample_time == 0.0:
        return dt
    if t < cs[row, c + S.next_sample] - 0.5 * dt:
        return 0.0
    cs[row, c + S.next_sample] += sample_time
    return sample_time


@hot_njit(cache=True, inline="always", error_model="numpy")
def _head_structure(
    structure: Structure | None, cp: FloatArray, row: int
) -> tuple[int, int, bool, bool]:  # pragma: no cover - compiled
    """(inputs, loops, sampled, saturated) of a row: read from its head (``structure`` None) or
    the constants of a :class:`Structure`. ``sampled``: whether its loops may hold their output
    between samples (a discrete PID); the step for any structure leaves it to
    :func:`_update_period`, which gives dt where T_s = 0."""
    if structure is None:
        return int(cp[row, H.n_inputs]), int(cp[row, H.n_loops]), True, cp[row, H.anti_windup] >= 0.0
    return structure.n_inputs, structure.n_loops, structure.discrete != 0, structure.saturated != 0


@hot_njit(cache=True, inline="always", error_model="numpy")
def _loop_signals(
    structure: Structure | None, cp: FloatArray, row: int, h: int, i: int
) -> tuple[int, int, int]:  # pragma: no cover - compiled
    """(output, reference, input) index of loop i: read from its :data:`LOOP` block at h
    (``structure`` None) or the constants of a :class:`Structure`."""
    if structure is None:
        return int(cp[row, h + L.y_index]), int(cp[row, h + L.r_index]), int(cp[row, h + L.u_index])
    return structure.y_index[i], structure.r_index[i], structure.u_index[i]


@hot_njit(cache=True, inline="always", error_model="numpy")
def _loop_options(
    structure: Structure | None, cp: FloatArray, row: int, h: int, i: int
) -> tuple[int, int, int, bool, bool, bool, int, bool]:  # pragma: no cover - compiled
    """(direct schedule, slot, schedule offset, filtered, on the measurement, gain inside, form,
    limited integral) of loop i: read from its :data:`LOOP` block at h (``structure`` None) or
    the constants of a :class:`Structure`, where the compiler drops the branches the loop does
    not take. The step for any structure holds every integral within its limits (inf where
    none is set, which changes no bit)."""
    if structure is None:
        return (
            int(cp[row, h + L.direct_schedule]), int(cp[row, h + L.schedule_slot]),
            int(cp[row, h + L.schedule_offset]), cp[row, h + L.filtered] != 0.0,
            cp[row, h + L.on_measurement] != 0.0, cp[row, h + L.gain_inside] != 0.0, int(cp[row, h + L.form]),
            True,
        )  # fmt: skip
    return (
        structure.direct[i], structure.slot[i], structure.offset[i], structure.filtered[i] != 0,
        structure.on_measurement[i] != 0, structure.inside[i] != 0, structure.form[i], structure.limited[i] != 0,
    )  # fmt: skip


@hot_njit(cache=True, inline="always", error_model="numpy")
def via_slot(
    callbacks: Callbacks, slot: int, t: float, e: float, edot: float, p: FloatArray, row: int, offset: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """The gains of the schedule in slot ``slot`` of the callback table (a registered schedule
    that is not built in): ``callbacks[slot](t, e, edot, p, row, offset)``. The GPU, which has
    no function values, replaces this function by a branch over the schedules in use
    (:mod:`nlcx.kernel.device`)."""
    return callbacks[slot](t, e, edot, p, row, offset)


@hot_njit(cache=True, inline="always", error_model="numpy")
def _loop_update(
    structure: Structure | None,
    i: int,
    t: float,
    period: float,
    y_i: float,
    r_i: float,
    cp: FloatArray,
    cs: FloatArray,
    log: FloatArray,
    row: int,
    h: int,
    c: int,
    callbacks: Callbacks,
) -> float:  # pragma: no cover - compiled
    """Loop i's sample (see :func:`pid_step`), its options by :func:`_loop_options`: its state
    updated, its gains logged; returns its signed contribution to its input."""
    direct, slot, off, filtered, on_measurement, inside, form, limited = _loop_options(structure, cp, row, h, i)
    e = r_i - y_i
    if cs[row, c + S.started] == 0.0:
        cs[row, c + S.e_prev] = e
        cs[row, c + S.y_prev] = y_i
        cs[row, c + S.started] = 1.0
    dv = (cs[row, c + S.y_prev] - y_i) if on_measurement else (e - cs[row, c + S.e_prev])
    if filtered:
        N = cp[row, h + L.N]
        d = (cs[row, c + S.d_filtered] + N * dv) / (1.0 + N * period)
        cs[row, c + S.d_filtered] = d
    else:
        d = dv / period
    if direct == DIRECT_ERROR_AGS:
        kp, ki, kd = error_ags_gains(t, e, d, cp, row, off)
    elif direct == DIRECT_TIME_AGS:
        kp, ki, kd = time_ags_gains(t, e, d, cp, row, off)
    elif direct == DIRECT_CONSTANT:
        kp, ki, kd = constant_gains(t, e, d, cp, row, off)
    else:
        kp, ki, kd = via_slot(callbacks, slot, t, e, d, cp, row, off)
    if form != 0:  # ideal: k_p (1, k_i, k_d); series: k_p (1 + k_i k_d, k_i, k_d)
        kp, ki, kd = (kp * (1.0 + ki * kd) if form == 2 else kp), kp * ki, kp * kd
    step = ki * e * period if inside else e * period
    integral = cs[row, c + S.integral] + step
    if limited:
        limit = cp[row, h + L.integral_limit]
        if integral > limit or integral < -limit:  # held at the limit: the increment is what I moved
            bounded = _within(integral, limit)
            step = bounded - cs[row, c + S.integral]
            integral = bounded
    cs[row, c + S.integral] = integral
    cs[row, c + S.increment] = step
    integral_term = cs[row, c + S.integral] * (1.0 if inside else ki)
    out = cp[row, h + L.sign] * (kp * (cp[row, h + L.setpoint_weight] * r_i - y_i) + integral_term + kd * d)
    g = len(G) * i
    log[row, g + G.kp] = kp
    log[row, g + G.ki] = ki
    log[row, g + G.kd] = kd
    log[row, g + G.u] = out
    cs[row, c + S.held] = out
    cs[row, c + S.e_prev] = e
    cs[row, c + S.y_prev] = y_i
    return out


@hot_njit(cache=True, inline="always", error_model="numpy")
def _pid_rows(
    structure: Structure | None,
    t: float,
    dt: float,
    x: FloatArray,
    y: FloatArray,
    r: FloatArray,
    cp: FloatArray,
    cs: FloatArray,
    u: FloatArray,
    log: FloatArray,
    callbacks: Callbacks,
) -> None:  # pragma: no cover - compiled
    """The PID's one body (see :func:`pid_step`), every row, with the loop structure read
    from each row (``structure`` None) or a :class:`Structure`'s constants (:func:`step_for`)."""
    for row in range(x.shape[0]):
        n_u, n_loops, sampled, saturated = _head_structure(structure, cp, row)
        for j in range(n_u):
            u[row, j] = cp[row, len(H) + len(I) * j + I.bias]
        base = len(H) + len(I) * n_u
        for i in range(n_loops):
            h = base + len(L) * i
            c = len(S) * i
            y_index, r_index, u_index = _loop_signals(structure, cp, row, h, i)
            period = _update_period(t, dt, cp[row, H.sample_time], cs, row, c) if sampled else dt
            cs[row, c + S.period] = period
            if sampled and period == 0.0:
                u[row, u_index] += cs[row, c + S.held]
                continue
            y_i = y[row, y_index] * cp[row, h + L.scale]
            r_i = r[row, r_index] * cp[row, h + L.scale]
            u[row, u_index] += _loop_update(structure, i, t, period, y_i, r_i, cp, cs, log, row, h, c, callbacks)
        if saturated:
            _saturate(row, cp, cs, u, log)


@hot_njit(CONTROLLER_SIG, cache=True, error_model="numpy")
def pid_step(
    t: float,
    dt: float,
    x: FloatArray,
    y: FloatArray,
    r: FloatArray,
    cp: FloatArray,
    cs: FloatArray,
    u: FloatArray,
    log: FloatArray,
    callbacks: Callbacks,
) -> None:  # pragma: no cover - compiled
    """The PID controller, every row; u[row, j] = bias_j + sum of its loops' outputs, clipped
    to the input's limit when saturated.

    Per loop i: e = r - y, I += e T (or k_i e T with the gain inside), then I held within the
    loop's integral limits [-L, L] (none: L = inf), D = de/dt by a backward difference or
    filtered by N/(s + N), (k_p, k_i, k_d) from the loop's schedule,
    u += sign (k_p (b r - y) + k_i I + k_d D), with y and r in the loop's units (scale) and
    (k_p, k_i, k_d) turned into parallel gains for the ideal or series form. T = dt, or the
    sampling period T_s of a discrete PID, which holds its output between samples.
    ``callbacks`` holds the registered schedules.

    This step reads each row's loop structure from its parameters, so rows of any structure
    can share a call; a built controller runs the step made for its structure
    (:func:`step_for`), the same body with the structure compiled in.
    """
    _pid_rows(None, t, dt, x, y, r, cp, cs, u, log, callbacks)


class Structure(NamedTuple):
    """What a PID's parameter row fixes beyond its numbers: the head's sizes and modes, and per
    loop (tuples, one entry a loop) its output, reference and input indices, schedule (built-in
    called directly, or its slot) and where its parameters start, its derivative, integral
    and PID-form options (0/1 flags, :data:`FORMS` code) and whether its integral is limited
    (a finite ``integral_limit``)."""

    n_inputs: int
    n_loops: int
    discrete: int
    saturated: int
    y_index: tuple[int, ...]
    r_index: tuple[int, ...]
    u_index: tuple[int, ...]
    direct: tuple[int, ...]
    slot: tuple[int, ...]
    offset: tuple[int, ...]
    filtered: tuple[int, ...]
    on_measurement: tuple[int, ...]
    inside: tuple[int, ...]
    form: tuple[int, ...]
    limited: tuple[int, ...]


def structure_of(cp: np.ndarray) -> Structure:
    """The :class:`Structure` of a PID parameter row, as :func:`pid_step` reads it."""
    head = HEAD.unpack(cp)
    n_inputs, n_loops = int(head["n_inputs"]), int(head["n_loops"])
    base = HEAD.size + INPUT.size * n_inputs
    loops = [LOOP.unpack(cp, base + LOOP.size * i) for i in range(n_loops)]

    def column(name: str) -> tuple[int, ...]:
        return tuple(int(loop[name] != 0.0) if name in _FLAGS else int(loop[name]) for loop in loops)

    return Structure(
        n_inputs=n_inputs, n_loops=n_loops, discrete=int(head["sample_time"] != 0.0),
        saturated=int(head["anti_windup"] >= 0.0), y_index=column("y_index"), r_index=column("r_index"),
        u_index=column("u_index"), direct=column("direct_schedule"), slot=column("schedule_slot"),
        offset=column("schedule_offset"), filtered=column("filtered"), on_measurement=column("on_measurement"),
        inside=column("gain_inside"), form=column("form"),
        limited=tuple(int(math.isfinite(loop["integral_limit"])) for loop in loops),
    )  # fmt: skip


#: The loop fields :class:`Structure` holds as 0/1 flags (the step tests them against 0).
_FLAGS = ("filtered", "on_measurement", "gain_inside")


@functools.cache
def step_for(structure: Structure | None) -> ControllerStep:
    """The PID step for rows of one :class:`Structure`: :func:`_pid_rows` with the structure
    compiled in as constants, the same operations on the same values as :func:`pid_step`, so
    the same bits, with the branches and index arithmetic on the structure gone
    (``benchmarks/components.py`` times both). ``None``: :func:`pid_step`, for rows of any
    structure. One compiled step a structure, made when a controller of that structure is
    first built and compiled when it first reaches the kernel (see the module docstring for
    how numba's disk cache keeps them apart)."""
    if structure is None:
        return pid_step

    def pid_step_for_structure(
        t: float,
        dt: float,
        x: FloatArray,
        y: FloatArray,
        r: FloatArray,
        cp: FloatArray,
        cs: FloatArray,
        u: FloatArray,
        log: FloatArray,
        callbacks: Callbacks,
    ) -> None:  # pragma: no cover - compiled
        _pid_rows(structure, t, dt, x, y, r, cp, cs, u, log, callbacks)

    # its own name, hence its own symbols and its own cache files (see the module docstring)
    pid_step_for_structure.__qualname__ = structure_name(structure)
    return hot_njit(cache=True, error_model="numpy")(pid_step_for_structure)


def structure_name(structure: Structure) -> str:
    """The qualified name of ``structure``'s step: a hash of its fields in the name."""
    digest = hashlib.sha256(repr(tuple(structure)).encode()).hexdigest()[:16]
    return f"pid_step_for_structure_{digest}"

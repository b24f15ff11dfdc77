"""One PID implementation for every loop structure and every gain schedule.

Each loop regulates one plant output to its reference and contributes a force to one plant
input; contributions to the same input are summed (Figs. 2.2, 3.2, 3.25, 4.2):

    u_j = bias_j + sum_{loops i -> j} sign_i * [k_p e_i + k_i I_i + k_d D_i],   e_i = r_i - y_i

with (k_p, k_i, k_d) from the loop's gain schedule (constant = conventional PID, time-AGS
eqs. 2.17-2.19, error-AGS eqs. 2.20-2.22). I_i = integral of e_i (backward Euler) and D_i
the derivative of e_i (or of -y_i), a backward difference or filtered by N/(s + N).
The derivative starts from the first sample (e_{-1} = e_0), so a step at t = 0 gives no kick.
With a set-point weight b the proportional term acts on b r - y instead of e.
"""

from __future__ import annotations

import functools
import hashlib
from typing import Any, Literal, NamedTuple

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field, SerializeAsAny

from nlcx import registry
from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel
from nlcx.controllers.schedules import (
    ScheduleConfig,
    constant_gains,
    error_ags_gains,
    schedule_index,
    schedule_slots,
    time_ags_gains,
)
from nlcx.errors import ConfigError
from nlcx.kernel.abi import CONTROLLER_SIG
from nlcx.layout import Layout
from nlcx.plants.base import Plant, equilibrium_input
from nlcx.validation import join, validate_model

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
#: integral, the set-point weight b of the proportional term, the PID form (:data:`FORMS`)
#: and the scale of the units the loop sees y and r in (e.g. 180/pi: an angle in degrees).
LOOP = Layout(
    "PIDLoop",
    (
        "y_index", "r_index", "u_index", "sign", "schedule_slot", "filtered", "N", "on_measurement",
        "gain_inside", "schedule_offset", "schedule_length", "setpoint_weight", "direct_schedule",
        "form", "scale",
    ),
)  # fmt: skip
L = LOOP.at
#: The built-in schedules are called directly (the compiler inlines them; a call through the
#: slot table cannot be inlined, a sizeable share of a sweep's time); any other schedule,
#: including a third party's or a replaced built-in, goes through its slot.
VIA_SLOT, DIRECT_CONSTANT, DIRECT_TIME_AGS, DIRECT_ERROR_AGS = 0, 1, 2, 3
_DIRECT = {constant_gains: DIRECT_CONSTANT, time_ags_gains: DIRECT_TIME_AGS, error_ags_gains: DIRECT_ERROR_AGS}
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


class DerivativeConfig(BaseModel):
    """How the derivative term is formed."""

    model_config = ConfigDict(extra="forbid")
    method: Literal["backward", "filtered"] = Field(
        "backward",
        description=(
            "backward: backward difference of the sampled error; filtered: N s / (s + N), discretised by backward Euler"
        ),
    )
    N: float = Field(
        100.0,
        gt=0,
        description="filter coefficient N of N s / (s + N), used when method is filtered",
        json_schema_extra={"unit": "1/s"},
    )
    on: Literal["error", "measurement"] = Field(
        "error",
        description="differentiate the error (textbook PID, eq. 5.11) or the negated measurement (no derivative kick)",
    )


class LoopConfig(BaseModel):
    """One loop: which output it regulates, which input it drives, with which schedule."""

    model_config = ConfigDict(extra="forbid")
    signal: str | None = Field(None, description="plant output regulated by this loop (default: the loop's key)")
    input: str | None = Field(
        None, description="plant input the loop drives (default: the plant's default input for this output)"
    )
    sign: Literal[-1, 1] = Field(
        1, description="sign of the loop's contribution to the summed input (the sum block of Fig. 2.2)"
    )
    schedule: dict[str, Any] | SerializeAsAny[ScheduleConfig] = Field(
        description=(
            "the gain schedule: a mapping whose kind names a registered schedule (constant, time_ags, error_ags, "
            "fuzzy, anfis), validated by that schedule's model"
        )
    )
    derivative: DerivativeConfig | None = Field(
        None, description="this loop's derivative term (default: the controller's derivative)"
    )
    scale: float = Field(
        1.0,
        gt=0,
        description=(
            "factor on y and r: the units the loop sees its output and reference in (the error, the schedule's "
            "argument and the gains' units follow); 1 as the plant gives them, 57.29577951308232 (180/pi) for an angle"
            " in degrees"
        ),
    )


class SaturationConfig(BaseModel):
    """Actuator limits |u_j| <= limit_j on the summed input, applied by the PID as Simulink's
    PID block applies its output saturation, and how the loops' integrators avoid windup:
    ``clamping`` holds a loop's integral while its input is saturated and the error would
    drive it further; ``back_calculation`` adds K_b (u_sat - u) to the integrator input of
    every loop on that input (Astrom & Hagglund's tracking anti-windup, K_b = 1 / T_t)."""

    model_config = ConfigDict(extra="forbid")
    limits: dict[str, float] = Field(
        min_length=1,
        description=(
            "limit of each saturated input, |u| <= limit, by input name (> 0; inputs not named are unlimited), in the "
            "input's unit"
        ),
    )
    anti_windup: Literal["none", "clamping", "back_calculation"] = Field(
        "none",
        description=(
            "none; clamping: a loop's integral holds while its input is saturated and the error would drive it "
            "further; back_calculation: K_b (u_sat - u) is added to the integrator input"
        ),
    )
    kb: float = Field(1.0, gt=0, description="back-calculation gain K_b = 1 / T_t", json_schema_extra={"unit": "1/s"})


class PIDConfig(ControllerConfig):
    kind: Literal["pid"] = Field(
        "pid", description="registered name of this controller; selects the model that validates this section"
    )
    loops: dict[str, LoopConfig] = Field(
        min_length=1,
        description=(
            "the loops by name (by default the name is the regulated output); the loops' outputs are summed per input"
        ),
    )
    derivative: DerivativeConfig = Field(
        default_factory=DerivativeConfig,
        description="how every loop forms its derivative term, unless a loop sets its own",
    )
    integral: Literal["outside", "inside"] = Field(
        "outside",
        description=(
            "outside: u = k_i(t) * integral(e), as eqs. 2.17-2.22 write it; inside: u = integral(k_i(t) e), bumpless "
            "when k_i varies"
        ),
    )
    bias: dict[str, float] = Field(
        default_factory=dict, description="constant feed-forward added to an input, by input name, in the input's unit"
    )
    feedforward: Literal["none", "equilibrium"] = Field(
        "none",
        description=(
            "equilibrium: add the input that holds the plant at its operating point, computed from the model (for the "
            "x-z and x-y-z pendulums the gravity compensation F_z = (M + m) g)"
        ),
    )
    setpoint_weight: float = Field(
        1.0, description="set-point weight b: the proportional term acts on b r - y (1: on the error)"
    )
    form: Literal["parallel", "ideal", "series"] = Field(
        "parallel",
        description=(
            "PID form of every loop, as Simulink's PID block names them: parallel k_p + k_i/s + k_d s; ideal k_p (1 + "
            "k_i/s + k_d s); series k_p (1 + k_i/s)(1 + k_d s); the schedule's gains are the form's parameters"
        ),
    )
    saturation: SaturationConfig | None = Field(
        None, description="actuator saturation with anti-windup (null: unlimited inputs)"
    )
    sample_time: float = Field(
        0.0,
        ge=0,
        description=(
            "sampling period T_s of a discrete PID: the loops update every T_s and hold their output in between (zero-"
            "order hold); 0: updated at every integration step dt"
        ),
        json_schema_extra={"unit": "s"},
    )


@njit(cache=True, error_model="numpy", _nrt=False)
def _saturate(row, dt, cp, cs, u, log):  # pragma: no cover - compiled
    """Clip each limited input to [-limit, limit] and correct the integrators of the loops on
    it that updated at this step (clamping: undo this sample's increment if it pushes further
    into the limit; back-calculation: I += K_b (u_sat - u) T through the loop's sign and
    integral gain, T the loop's update period)."""
    n_u = int(cp[row, H.n_inputs])
    base = len(H) + len(I) * n_u
    mode = int(cp[row, H.anti_windup])
    for i in range(int(cp[row, H.n_loops])):
        h = base + len(L) * i
        j = int(cp[row, h + L.u_index])
        limit = cp[row, len(H) + len(I) * j + I.limit]
        excess = u[row, j] - min(max(u[row, j], -limit), limit)
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
            cs[row, c + S.integral] -= sign * cp[row, H.kb] * excess * period / (1.0 if inside else ki)
    for j in range(n_u):
        limit = cp[row, len(H) + len(I) * j + I.limit]
        u[row, j] = min(max(u[row, j], -limit), limit)


@njit(cache=True, error_model="numpy", _nrt=False)
def _update_period(t, dt, sample_time, cs, row, c):  # pragma: no cover - compiled
    """The period a loop updates over at t: dt for a continuous PID (T_s = 0); T_s at a
    discrete PID's sampling instant (the next one scheduled T_s later); 0 while it holds."""
    if sample_time == 0.0:
        return dt
    if t < cs[row, c + S.next_sample] - 0.5 * dt:
        return 0.0
    cs[row, c + S.next_sample] += sample_time
    return sample_time


@njit(cache=True, inline="always", error_model="numpy", _nrt=False)
def _loop_update(
    t, period, y_i, r_i, cp, cs, log, row, h, c, g, callbacks, direct, slot, off, filtered, on_measurement, inside, form
):  # pragma: no cover - compiled
    """One loop's sample (see :func:`pid_step`): its state updated, its gains logged; returns
    its signed contribution to its input. The loop's structure (``direct`` .. ``form``) is
    passed in, read from the parameter row by :func:`pid_step` or a compile-time constant of a
    step made for one structure (:func:`step_for`), where the compiler drops the branches it
    does not take."""
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
        kp, ki, kd = callbacks[slot](t, e, d, cp, row, off)
    if form != 0:  # ideal: k_p (1, k_i, k_d); series: k_p (1 + k_i k_d, k_i, k_d)
        kp, ki, kd = (kp * (1.0 + ki * kd) if form == 2 else kp), kp * ki, kp * kd
    step = ki * e * period if inside else e * period
    cs[row, c + S.integral] += step
    cs[row, c + S.increment] = step
    integral_term = cs[row, c + S.integral] * (1.0 if inside else ki)
    out = cp[row, h + L.sign] * (kp * (cp[row, h + L.setpoint_weight] * r_i - y_i) + integral_term + kd * d)
    log[row, g + G.kp] = kp
    log[row, g + G.ki] = ki
    log[row, g + G.kd] = kd
    log[row, g + G.u] = out
    cs[row, c + S.held] = out
    cs[row, c + S.e_prev] = e
    cs[row, c + S.y_prev] = y_i
    return out


@njit(cache=True, inline="always", error_model="numpy", _nrt=False)
def _row_loop_update(t, period, y_i, r_i, cp, cs, log, row, h, c, g, callbacks):  # pragma: no cover - compiled
    """:func:`_loop_update` with the loop's structure read from its parameter row, as the
    general :func:`pid_step` does for rows of any structure."""
    return _loop_update(
        t, period, y_i, r_i, cp, cs, log, row, h, c, g, callbacks,
        int(cp[row, h + L.direct_schedule]), int(cp[row, h + L.schedule_slot]),
        int(cp[row, h + L.schedule_offset]), cp[row, h + L.filtered] != 0.0,
        cp[row, h + L.on_measurement] != 0.0, cp[row, h + L.gain_inside] != 0.0, int(cp[row, h + L.form]),
    )  # fmt: skip


@njit(CONTROLLER_SIG, cache=True, error_model="numpy", _nrt=False)
def pid_step(t, dt, x, y, r, cp, cs, u, log, callbacks):  # pragma: no cover - compiled
    """Multi-loop PID with pluggable gain schedules, one sample (zero-order hold), every row.

    Per loop i: e = r - y, I += e T (or k_i e T with the gain inside), D = de/dt by a
    backward difference or filtered by N/(s + N), (k_p, k_i, k_d) from the loop's schedule,
    u += sign (k_p (b r - y) + k_i I + k_d D), with y and r in the loop's units (scale) and
    (k_p, k_i, k_d) turned into parallel gains for the ideal or series form. T = dt, or the
    sampling period T_s of a discrete PID, which holds its output between samples.
    ``callbacks`` holds the registered schedules.

    This step reads each row's loop structure from its parameters, so rows of any structure
    can share a call; a built controller runs the step made for its structure
    (:func:`step_for`), the same arithmetic with the structure compiled in.
    """
    for row in range(x.shape[0]):
        n_u = int(cp[row, H.n_inputs])
        for j in range(n_u):
            u[row, j] = cp[row, len(H) + len(I) * j + I.bias]
        base = len(H) + len(I) * n_u
        for i in range(int(cp[row, H.n_loops])):
            h = base + len(L) * i
            c = len(S) * i
            period = _update_period(t, dt, cp[row, H.sample_time], cs, row, c)
            cs[row, c + S.period] = period
            if period == 0.0:
                u[row, int(cp[row, h + L.u_index])] += cs[row, c + S.held]
                continue
            y_i = y[row, int(cp[row, h + L.y_index])] * cp[row, h + L.scale]
            r_i = r[row, int(cp[row, h + L.r_index])] * cp[row, h + L.scale]
            u[row, int(cp[row, h + L.u_index])] += _row_loop_update(
                t, period, y_i, r_i, cp, cs, log, row, h, c, len(G) * i, callbacks
            )
        if cp[row, H.anti_windup] >= 0.0:
            _saturate(row, dt, cp, cs, u, log)


class Structure(NamedTuple):
    """What a PID's parameter row fixes beyond its numbers: the head's sizes and modes, and per
    loop (tuples, one entry a loop) its output, reference and input indices, schedule (built-in
    called directly, or its slot) and where its parameters start, and its derivative, integral
    and PID-form options (0/1 flags, :data:`FORMS` code)."""

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
    )  # fmt: skip


#: The loop fields :class:`Structure` holds as 0/1 flags (the step tests them against 0).
_FLAGS = ("filtered", "on_measurement", "gain_inside")


@functools.cache
def step_for(structure: Structure) -> Any:
    """:func:`pid_step` for rows of one :class:`Structure`, with that structure compiled in as
    constants: the same operations on the same values, so the same bits, with the branches and
    index arithmetic on the structure gone (``benchmarks/components.py`` times both steps). One
    compiled step a structure, made when a controller of that structure is first built and
    compiled when it first reaches the kernel (numba's disk cache keys it by the structure)."""
    n_inputs, n_loops, discrete, saturated = structure[:4]
    y_index, r_index, u_index, direct, slot, offset, filtered, on_measurement, inside, form = structure[4:]
    base = len(H) + len(I) * n_inputs

    def pid_step_for_structure(t, dt, x, y, r, cp, cs, u, log, callbacks):  # pragma: no cover - compiled
        for row in range(x.shape[0]):
            for j in range(n_inputs):
                u[row, j] = cp[row, len(H) + len(I) * j + I.bias]
            for i in range(n_loops):
                h = base + len(L) * i
                c = len(S) * i
                period = _update_period(t, dt, cp[row, H.sample_time], cs, row, c) if discrete else dt
                cs[row, c + S.period] = period
                if discrete and period == 0.0:
                    u[row, u_index[i]] += cs[row, c + S.held]
                    continue
                y_i = y[row, y_index[i]] * cp[row, h + L.scale]
                r_i = r[row, r_index[i]] * cp[row, h + L.scale]
                u[row, u_index[i]] += _loop_update(
                    t, period, y_i, r_i, cp, cs, log, row, h, c, len(G) * i, callbacks, direct[i], slot[i],
                    offset[i], filtered[i] != 0, on_measurement[i] != 0, inside[i] != 0, form[i],
                )  # fmt: skip
            if saturated:
                _saturate(row, dt, cp, cs, u, log)

    # numba's disk cache keeps one index file a function name, and processes that compile
    # different structures of one name at once (a pool's workers) can leave an index entry
    # pointing at another structure's code: so one name, and one index, a structure
    digest = hashlib.sha1(repr(tuple(structure)).encode(), usedforsecurity=False).hexdigest()[:12]
    pid_step_for_structure.__qualname__ = f"pid_step_for_structure_{digest}"
    return njit(cache=True, error_model="numpy", _nrt=False)(pid_step_for_structure)


#: Controllers built so far (:meth:`MultiLoopPID.build`), with the config each was built from.
_BUILT: dict[tuple[Any, ...], tuple[PIDConfig, ControllerInstance]] = {}
_BUILT_SIZE = 256


class MultiLoopPID(ControllerModel):
    """PID loops summed per input; gains from a schedule (constant, time_ags, error_ags, ...)."""

    Config = PIDConfig
    step = staticmethod(pid_step)

    def normalize(self, cfg: PIDConfig, path: str) -> PIDConfig:
        """Validate each loop's gain schedule by its registered model (once), defaults filled in."""
        loops = {}
        for key, loop in cfg.loops.items():
            if isinstance(loop.schedule, ScheduleConfig):
                loops[key] = loop
                continue
            spath = join(path, "loops", key, "schedule")
            model = registry.schedules.get(loop.schedule.get("kind"), path=join(spath, "kind"))
            loops[key] = loop.model_copy(update={"schedule": validate_model(model.Config, loop.schedule, spath)})
        return cfg.model_copy(update={"loops": loops})

    def build(self, label: str, cfg: PIDConfig, plant: Plant, path: str, dt: float | None = None) -> ControllerInstance:
        """The controller for ``plant``. A controller is built once for a validated config and
        the plant's signals and equilibrium bias: the variants of a sweep that change only the
        plant's numbers (their configs share the validated controller section, see
        ``config.build(raw, like=base)``) share it, as the arrays it holds are read-only."""
        bias = self._bias(cfg, plant, path)
        key = (label, path, dt, id(cfg), plant.name, tuple(plant.output_names), tuple(plant.input_names),
               bias.tobytes())  # fmt: skip
        built = _BUILT.get(key)
        if built is not None and built[0] is cfg:  # the entry holds cfg alive: its id is its own
            return built[1]
        controller = self._build(label, cfg, plant, path, dt, bias)
        if len(_BUILT) >= _BUILT_SIZE:
            _BUILT.clear()
        _BUILT[key] = (cfg, controller)
        return controller

    def _build(
        self, label: str, cfg: PIDConfig, plant: Plant, path: str, dt: float | None, bias: np.ndarray
    ) -> ControllerInstance:
        cfg = self.normalize(cfg, path)
        if dt is not None and 0.0 < cfg.sample_time < dt:
            allowed = f"allowed: 0 (updated every step) or a period >= simulation.dt = {dt:g} s"
            raise ConfigError(join(path, "sample_time"), cfg.sample_time, allowed)
        loops = self._resolve_loops(cfg, plant, path)
        sat = cfg.saturation
        inputs = zip(bias, self._limits(cfg, plant, path), strict=True)
        head = np.concatenate([
            HEAD.pack(
                n_loops=len(loops), n_inputs=len(plant.inputs),
                anti_windup=ANTI_WINDUP[sat.anti_windup if sat else "off"], kb=sat.kb if sat else 0.0,
                sample_time=cfg.sample_time,
            ),
            *(INPUT.pack(bias=bias, limit=limit) for bias, limit in inputs),
        ])  # fmt: skip
        blocks: list[np.ndarray] = []
        schedules: list[np.ndarray] = []
        offset = len(head) + LOOP.size * len(loops)
        log_names: list[str] = []
        log_units: list[str] = []
        for key, loop, signal, input_name in loops:
            sp = np.asarray(registry.schedules.get(loop.schedule.kind).pack(loop.schedule), dtype=float)
            blocks.append(self._loop_block(cfg, loop, plant, signal, input_name, offset, sp.size))
            schedules.append(sp)
            offset += sp.size
            log_names += [f"{key}.{name}" for name in LOOP_LOG.fields]
            log_units += _log_units(plant.unit_of(input_name), plant.unit_of(signal))
        cp = np.concatenate([head, *blocks, *schedules])
        return ControllerInstance(
            label=label,
            kind="pid",
            step=step_for(structure_of(cp)),
            general_step=pid_step,
            cp=cp,
            cs0=np.zeros(LOOP_STATE.size * len(loops)),
            reference_signals=tuple(plant.output_names),
            log_names=tuple(log_names),
            log_units=tuple(log_units),
            config=cfg.model_dump(),
            callbacks=schedule_slots(loop.schedule.kind for _, loop, _, _ in loops if _via_slot(loop)),
        )

    @staticmethod
    def _limits(cfg: PIDConfig, plant: Plant, path: str) -> np.ndarray:
        """|u_j| <= limit_j per input (inf where none is set)."""
        inputs = plant.input_names
        limits = np.full(len(inputs), np.inf)
        for name, value in (cfg.saturation.limits if cfg.saturation else {}).items():
            where = join(path, "saturation", "limits", name)
            if name not in inputs:
                raise ConfigError(where, value, f"unknown input; allowed: {', '.join(inputs)}")
            if not value > 0:
                raise ConfigError(where, value, "must be a limit > 0")
            limits[inputs.index(name)] = value
        return limits

    @staticmethod
    def _bias(cfg: PIDConfig, plant: Plant, path: str) -> np.ndarray:
        """The constant part of each input: the equilibrium feed-forward plus ``bias``."""
        inputs = plant.input_names
        bias = equilibrium_input(plant) if cfg.feedforward == "equilibrium" else np.zeros(len(inputs))
        for name, value in cfg.bias.items():
            if name not in inputs:
                raise ConfigError(join(path, "bias", name), value, f"unknown input; allowed: {', '.join(inputs)}")
            bias[inputs.index(name)] += value
        return bias

    @staticmethod
    def _loop_block(
        cfg: PIDConfig, loop: LoopConfig, plant: Plant, signal: str, input_name: str, offset: int, length: int
    ) -> np.ndarray:
        """One loop's :data:`LOOP` block; its schedule's parameters sit at ``offset``."""
        deriv = loop.derivative or cfg.derivative
        kind = loop.schedule.kind
        return LOOP.pack(
            y_index=plant.output_names.index(signal),
            r_index=plant.output_names.index(signal),
            u_index=plant.input_names.index(input_name),
            sign=loop.sign,
            schedule_slot=schedule_index(kind),
            filtered=deriv.method == "filtered",
            N=deriv.N,
            on_measurement=deriv.on == "measurement",
            gain_inside=cfg.integral == "inside",
            schedule_offset=offset,
            schedule_length=length,
            setpoint_weight=cfg.setpoint_weight,
            direct_schedule=_DIRECT.get(registry.schedules.get(kind).gains, VIA_SLOT),
            form=FORMS[cfg.form],
            scale=loop.scale,
        )

    @staticmethod
    def _resolve_loops(cfg: PIDConfig, plant: Plant, path: str) -> list[tuple[str, LoopConfig, str, str]]:
        """(key, loop, output, input) per loop; exactly one loop per plant output."""
        outputs = plant.output_names
        inputs = plant.input_names
        resolved = []
        for key, loop in cfg.loops.items():
            signal = loop.signal or key
            if signal not in outputs:
                where = join(path, "loops", key, "signal") if loop.signal else join(path, "loops", key)
                raise ConfigError(where, signal, f"not an output of {plant.name}; allowed: {', '.join(outputs)}")
            input_name = loop.input or plant.features.loop_inputs.get(signal)
            if input_name is None and len(inputs) == 1:
                input_name = inputs[0]
            if input_name not in inputs:
                raise ConfigError(
                    join(path, "loops", key, "input"),
                    loop.input,
                    f"must name an input of {plant.name}; allowed: {', '.join(inputs)}",
                )
            resolved.append((key, loop, signal, input_name))
        signals = [s for _, _, s, _ in resolved]
        if sorted(signals) != sorted(outputs):
            raise ConfigError(
                join(path, "loops"),
                list(cfg.loops),
                f"{plant.name} needs exactly one loop per output ({len(outputs)}: "
                f"{', '.join(outputs)}); got {len(signals)} loop(s) on {', '.join(signals)}",
            )
        return resolved


def _via_slot(loop: LoopConfig) -> bool:
    """Whether the PID calls the loop's schedule through its callback slot (not a built-in)."""
    return registry.schedules.get(loop.schedule.kind).gains not in _DIRECT


def input_blocks(cp: np.ndarray) -> list[dict[str, float]]:
    """Each input's :data:`INPUT` block (bias, limit) of a PID's parameter row."""
    head = HEAD.unpack(cp)
    return [INPUT.unpack(cp, HEAD.size + INPUT.size * j) for j in range(int(head["n_inputs"]))]


def _log_units(unit_in: str, unit_sig: str) -> list[str]:
    """Units of a loop's logged k_p, k_i, k_d and output (:data:`LOOP_LOG`)."""
    return [f"{unit_in}/{unit_sig}", f"{unit_in}/({unit_sig}*s)", f"{unit_in}*s/{unit_sig}", unit_in]

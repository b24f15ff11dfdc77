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

from typing import Any, Literal

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field

from nlcx import registry
from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel
from nlcx.controllers.schedules import constant_gains, error_ags_gains, schedule_index, time_ags_gains
from nlcx.errors import ConfigError
from nlcx.kernel import CONTROLLER_SIG
from nlcx.plants.base import Plant, equilibrium_input
from nlcx.validation import join, validate_model

#: Per-loop header in the parameter vector: y index, r index, u index, sign, schedule slot,
#: derivative method (0 backward, 1 filtered), N, derivative on measurement (0/1),
#: integral gain inside the integral (0/1), offset and length of the schedule parameters,
#: set-point weight b of the proportional term, built-in schedule called directly (below).
LOOP_FIELDS = 13
#: The built-in schedules are called directly (the compiler inlines them; a call through the
#: slot table cannot be inlined and cost ~15 % of a sweep's time); any other schedule,
#: including a third party's or a replaced built-in, goes through its slot.
VIA_SLOT, DIRECT_CONSTANT, DIRECT_TIME_AGS, DIRECT_ERROR_AGS = 0, 1, 2, 3
_DIRECT = {constant_gains: DIRECT_CONSTANT, time_ags_gains: DIRECT_TIME_AGS, error_ags_gains: DIRECT_ERROR_AGS}
#: Per-loop controller state: integral, previous error, filtered derivative, previous y, started.
LOOP_STATE = 5
#: Per-loop logged values: k_p, k_i, k_d and the loop's signed contribution to its input.
LOOP_LOG = ("kp", "ki", "kd", "u")


class DerivativeConfig(BaseModel):
    """How the derivative term is formed."""

    model_config = ConfigDict(extra="forbid")
    method: Literal["backward", "filtered"] = "backward"
    #: Filter coefficient of N s / (s + N), used when method is "filtered".
    N: float = Field(100.0, gt=0)
    #: Differentiate the error (textbook PID, eq. 5.11) or the negated measurement.
    on: Literal["error", "measurement"] = "error"


class LoopConfig(BaseModel):
    """One loop: which output it regulates, which input it drives, with which schedule."""

    model_config = ConfigDict(extra="forbid")
    #: Plant output regulated by this loop (default: the loop's key).
    signal: str | None = None
    #: Plant input the loop drives (default: the plant's default for this output).
    input: str | None = None
    #: Sign of the loop's contribution to the summed input (the sum block of Fig. 2.2).
    sign: Literal[-1, 1] = 1
    schedule: dict[str, Any]
    derivative: DerivativeConfig | None = None


class PIDConfig(ControllerConfig):
    kind: Literal["pid"] = "pid"
    loops: dict[str, LoopConfig] = Field(min_length=1)
    derivative: DerivativeConfig = DerivativeConfig()
    #: "outside": u = k_i(t) * integral(e) as eqs. 2.17-2.22 write it;
    #: "inside": u = integral(k_i(t) e), bumpless when k_i varies.
    integral: Literal["outside", "inside"] = "outside"
    #: Constant feed-forward added to an input, by input name.
    bias: dict[str, float] = Field(default_factory=dict)
    #: "equilibrium" adds the input that holds the plant at its operating point, computed
    #: from the model (for the x-z and x-y-z pendulums: gravity compensation F_z = (M + m) g).
    feedforward: Literal["none", "equilibrium"] = "none"
    #: Set-point weight b: the proportional term acts on b r - y (b = 1: on the error).
    setpoint_weight: float = 1.0


@njit(CONTROLLER_SIG, cache=True, error_model="numpy")
def pid_step(t, dt, x, y, r, cp, cs, u, log, schedules):  # pragma: no cover - compiled
    """Multi-loop PID with pluggable gain schedules, one sample (zero-order hold), every row.

    Per loop i: e = r - y, I += e dt (or k_i e dt with the gain inside), D = de/dt by a
    backward difference or filtered by N/(s + N), (k_p, k_i, k_d) from the loop's schedule,
    u += sign (k_p (b r - y) + k_i I + k_d D).
    """
    for row in range(x.shape[0]):
        n_loops = int(cp[row, 0])
        n_u = int(cp[row, 1])
        for j in range(n_u):
            u[row, j] = cp[row, 2 + j]
        base = 2 + n_u
        for i in range(n_loops):
            h = base + LOOP_FIELDS * i
            yi = int(cp[row, h])
            ri = int(cp[row, h + 1])
            ui = int(cp[row, h + 2])
            sign = cp[row, h + 3]
            slot = int(cp[row, h + 4])
            filtered = cp[row, h + 5] != 0.0
            N = cp[row, h + 6]
            on_measurement = cp[row, h + 7] != 0.0
            gain_inside = cp[row, h + 8] != 0.0
            off = int(cp[row, h + 9])
            b_weight = cp[row, h + 11]
            c = LOOP_STATE * i
            y_i = y[row, yi]
            r_i = r[row, ri]
            e = r_i - y_i
            if cs[row, c + 4] == 0.0:
                cs[row, c + 1] = e
                cs[row, c + 3] = y_i
                cs[row, c + 4] = 1.0
            dv = (cs[row, c + 3] - y_i) if on_measurement else (e - cs[row, c + 1])
            if filtered:
                d = (cs[row, c + 2] + N * dv) / (1.0 + N * dt)
                cs[row, c + 2] = d
            else:
                d = dv / dt
            direct = int(cp[row, h + 12])
            if direct == DIRECT_ERROR_AGS:
                kp, ki, kd = error_ags_gains(t, e, d, cp, row, off)
            elif direct == DIRECT_TIME_AGS:
                kp, ki, kd = time_ags_gains(t, e, d, cp, row, off)
            elif direct == DIRECT_CONSTANT:
                kp, ki, kd = constant_gains(t, e, d, cp, row, off)
            else:
                kp, ki, kd = schedules[slot](t, e, d, cp, row, off)
            if gain_inside:
                cs[row, c] += ki * e * dt
                integral_term = cs[row, c]
            else:
                cs[row, c] += e * dt
                integral_term = ki * cs[row, c]
            out = sign * (kp * (b_weight * r_i - y_i) + integral_term + kd * d)
            log[row, 4 * i] = kp
            log[row, 4 * i + 1] = ki
            log[row, 4 * i + 2] = kd
            log[row, 4 * i + 3] = out
            u[row, ui] += out
            cs[row, c + 1] = e
            cs[row, c + 3] = y_i


class MultiLoopPID(ControllerModel):
    """PID loops summed per input; gains from a schedule (constant, time_ags, error_ags, ...)."""

    Config = PIDConfig
    step = staticmethod(pid_step)

    def normalize(self, cfg: PIDConfig, path: str) -> PIDConfig:
        """Validate each loop's gain schedule by its registered model, defaults filled in."""
        loops = {}
        for key, loop in cfg.loops.items():
            spath = join(path, "loops", key, "schedule")
            model = registry.schedules.get(loop.schedule.get("kind"), path=join(spath, "kind"))
            sched = validate_model(model.Config, loop.schedule, spath)
            loops[key] = loop.model_copy(update={"schedule": sched.model_dump()})
        return cfg.model_copy(update={"loops": loops})

    def build(self, label: str, cfg: PIDConfig, plant: Plant, path: str, dt: float | None = None) -> ControllerInstance:
        outputs = plant.output_names
        inputs = plant.input_names
        loops = self._resolve_loops(cfg, plant, path)
        n_u = len(inputs)
        bias = equilibrium_input(plant) if cfg.feedforward == "equilibrium" else np.zeros(n_u)
        for name, value in cfg.bias.items():
            if name not in inputs:
                raise ConfigError(join(path, "bias", name), value, f"unknown input; allowed: {', '.join(inputs)}")
            bias[inputs.index(name)] += value
        header: list[float] = [len(loops), n_u, *bias]
        params: list[float] = []
        sched_start = len(header) + LOOP_FIELDS * len(loops)
        log_names: list[str] = []
        log_units: list[str] = []
        for key, loop, signal, input_name in loops:
            lpath = join(path, "loops", key)
            kind = loop.schedule.get("kind")
            model = registry.schedules.get(kind, path=join(lpath, "schedule", "kind"))
            sched_cfg = validate_model(model.Config, loop.schedule, join(lpath, "schedule"))
            sp = np.asarray(model.pack(sched_cfg), dtype=float)
            deriv = loop.derivative or cfg.derivative
            header += [
                outputs.index(signal),
                outputs.index(signal),
                inputs.index(input_name),
                loop.sign,
                schedule_index(kind),
                1.0 if deriv.method == "filtered" else 0.0,
                deriv.N,
                1.0 if deriv.on == "measurement" else 0.0,
                1.0 if cfg.integral == "inside" else 0.0,
                sched_start + len(params),
                sp.size,
                cfg.setpoint_weight,
                _DIRECT.get(model.gains, VIA_SLOT),
            ]
            params += list(sp)
            unit_in = plant.unit_of(input_name)
            unit_sig = plant.unit_of(signal)
            gain_units = (
                f"{unit_in}/{unit_sig}",
                f"{unit_in}/({unit_sig}*s)",
                f"{unit_in}*s/{unit_sig}",
                unit_in,
            )
            for suffix, unit in zip(LOOP_LOG, gain_units, strict=True):
                log_names.append(f"{key}.{suffix}")
                log_units.append(unit)
        return ControllerInstance(
            label=label,
            kind="pid",
            step=self.step,
            cp=np.array(header + params, dtype=float),
            cs0=np.zeros(LOOP_STATE * len(loops)),
            reference_signals=tuple(outputs),
            log_names=tuple(log_names),
            log_units=tuple(log_units),
            config=cfg.model_dump(),
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
            input_name = loop.input or plant.loop_inputs.get(signal)
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

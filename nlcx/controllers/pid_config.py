"""The configuration of the PID controller (``kind: pid``, :mod:`nlcx.controllers.pid`): its
loops and their gain schedules, the derivative and integral terms, the PID form, the actuator
saturation with its anti-windup, and the sampling period of a discrete PID.

:class:`~nlcx.controllers.pid.MultiLoopPID` validates each loop's schedule by its registered
model and packs the validated section into the parameter row its compiled step reads.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, SerializeAsAny

from nlcx import registry
from nlcx.controllers.base import ControllerConfig
from nlcx.controllers.schedules import ScheduleConfig
from nlcx.errors import ConfigError
from nlcx.validation import join, validate_model


class DerivativeConfig(BaseModel):
    """How the derivative term is formed."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
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
    """One loop: which output it regulates, which input it drives, with which schedule, and the
    limits of its integrator."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
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
    integral_limit: float | None = Field(
        None,
        gt=0,
        description=(
            "limit L > 0 of the loop's integrator state, held within [-L, L] after each update as a Simulink "
            "Integrator block's output limits hold it: the integral of e (integral: outside; in the loop's error "
            "unit times s) or of k_i e (integral: inside; in the input's unit); null: unlimited"
        ),
    )


class SaturationConfig(BaseModel):
    """Actuator limits |u_j| <= limit_j on the summed input, applied by the PID as Simulink's
    PID block applies its output saturation, and how the loops' integrators avoid windup:
    ``clamping`` holds a loop's integral while its input is saturated and the error would
    drive it further; ``back_calculation`` adds K_b (u_sat - u) to the integrator input of
    every loop on that input (Astrom & Hagglund's tracking anti-windup, K_b = 1 / T_t)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    limits: dict[str, Annotated[float, Field(gt=0)]] = Field(
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


def normalized(cfg: PIDConfig) -> bool:
    """Whether every loop's schedule is validated by its registered model (:func:`normalize`)."""
    return all(isinstance(loop.schedule, ScheduleConfig) for loop in cfg.loops.values())


def schedule_of(loop: LoopConfig) -> ScheduleConfig:
    """The loop's validated schedule; a loop is read only after :func:`normalize` validated it."""
    if not isinstance(loop.schedule, ScheduleConfig):
        raise TypeError("a PID loop's schedule is read before normalize() validated it")
    return loop.schedule


def normalize(cfg: PIDConfig, path: str) -> PIDConfig:
    """``cfg`` with each loop's gain schedule validated by its registered model (once), defaults
    filled in: what ``config.build`` leaves in an experiment (the PID plugin's ``normalize``)."""
    if normalized(cfg):
        return cfg
    loops = {}
    for key, loop in cfg.loops.items():
        if isinstance(loop.schedule, ScheduleConfig):
            loops[key] = loop
            continue
        spath = join(path, "loops", key, "schedule")
        kind = loop.schedule.get("kind")
        if not isinstance(kind, str):
            raise ConfigError(join(spath, "kind"), kind, registry.schedules.unknown_message(kind))
        model = registry.schedules.get(kind, path=join(spath, "kind"))
        loops[key] = loop.model_copy(update={"schedule": validate_model(model.Config, loop.schedule, spath)})
    return cfg.model_copy(update={"loops": loops})

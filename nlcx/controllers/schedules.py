"""Gain schedules of the PID controller: constant, time-AGS and error-AGS (thesis section 2.3).

A schedule maps (t, e, de/dt) and its parameters to the gains (k_p, k_i, k_d). It is a
numba function with :data:`nlcx.kernel.abi.CALLBACK_SIG`; the PID controller calls it once
per loop and sample. Every registered schedule occupies a slot of the PID's callback table,
so third-party schedules registered through the ``nlcx.schedules`` entry point group work
without touching the PID. The parameters of each built-in schedule are a named
:class:`~nlcx.layout.Layout` block.

The thesis prints each AGS range as (min, max) but does not order them: Table 3.6 gives the
z loop k_p from 25 ("min") to 15 ("max"). The formulas are applied literally to the two
printed end points, so a "min" above "max" simply reverses the direction of travel.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from functools import cache
from typing import Any, ClassVar, Literal, Protocol

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field

from nlcx import registry
from nlcx._numba_compat import hot_njit
from nlcx.errors import ConfigError
from nlcx.kernel.abi import CALLBACK_SIG, CALLBACK_SLOTS, FunctionTable, callback_slots, no_callback
from nlcx.kernel.signatures import FloatArray
from nlcx.layout import Layout

#: Conventional PID: the three constant gains.
CONSTANT = Layout("ConstantGains", ("kp", "ki", "kd"))
CG = CONSTANT.at
#: Time-AGS (eqs. 2.17-2.19): the printed range end points and the rate of each gain.
_AGS_FIELDS = ("kp_min", "kp_max", "ki_min", "ki_max", "kd_min", "kd_max", "kp_rate", "ki_rate", "kd_rate")
TIME_AGS = Layout("TimeAGS", _AGS_FIELDS)
TA = TIME_AGS.at
#: Error-AGS (eqs. 2.20-2.22): as time-AGS, and whether the schedule runs on |e| (1) or e (0).
ERROR_AGS = Layout("ErrorAGS", (*_AGS_FIELDS, "on_abs_error", "error_scale"))
EA = ERROR_AGS.at


class ScheduleConfig(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    kind: str


class GainRange(BaseModel):
    """The two end points of a scheduled gain, as the thesis's tables print them."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    min: float = Field(
        description="the range's printed min end point (a min above max reverses the direction of travel)"
    )
    max: float = Field(description="the range's printed max end point")


class Rates(BaseModel):
    """The rate constants k of the exponentials, one per gain (section 2.3)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    kp: float = Field(
        ge=0, description="rate constant k of k_p's exponential: 1/s for time_ags, 1/(unit of e) for error_ags"
    )
    ki: float = Field(ge=0, description="rate constant k of k_i's exponential (units as kp)")
    kd: float = Field(ge=0, description="rate constant k of k_d's exponential (units as kp)")


class ConstantConfig(ScheduleConfig):
    kind: Literal["constant"] = Field(
        "constant", description="registered name of this gain schedule; selects the model that validates this section"
    )
    kp: float = Field(0.0, description="proportional gain k_p (units: the loop's input per unit of its error)")
    ki: float = Field(0.0, description="integral gain k_i (per second of k_p's units)")
    kd: float = Field(0.0, description="derivative gain k_d (k_p's units times s)")


class AGSConfig(ScheduleConfig):
    kp: GainRange = Field(
        description=(
            "end points of k_p: time_ags moves it from max at t = 0 towards min (eq. 2.17); error_ags from min at "
            "e = 0 towards max as |e| grows (eq. 2.20)"
        )
    )
    ki: GainRange = Field(
        description=(
            "end points of k_i: time_ags moves it from min at t = 0 towards max (eq. 2.18); error_ags from max at "
            "e = 0 towards min as |e| grows (eq. 2.21)"
        )
    )
    kd: GainRange = Field(
        description=(
            "end points of k_d: time_ags moves it from max at t = 0 towards min (eq. 2.19); error_ags from min at "
            "e = 0 towards max as |e| grows (eq. 2.22)"
        )
    )
    rate: Rates = Field(description="rate constants k of the three exponentials (section 2.3)")


class TimeAGSConfig(AGSConfig):
    kind: Literal["time_ags"] = Field(
        "time_ags", description="registered name of this gain schedule; selects the model that validates this section"
    )


class ErrorAGSConfig(AGSConfig):
    kind: Literal["error_ags"] = Field(
        "error_ags", description="registered name of this gain schedule; selects the model that validates this section"
    )
    error: Literal["abs", "signed"] = Field(
        "abs", description="abs: schedule on |e(t)| (default); signed: on e(t) as eqs. 2.20-2.22 literally print it"
    )
    error_scale: float = Field(
        1.0,
        gt=0,
        description=(
            "factor c on the schedule's argument, s = |c e| (1: e as the loop sees it; 1/step size normalises it, "
            "180/pi takes an angle in degrees); only the schedule sees it"
        ),
    )


@njit(cache=True, error_model="numpy")
def _decays(k_p: float, k_i: float, k_d: float, s: float) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """(exp(-k_p s), exp(-k_i s), exp(-k_d s)), each exponential evaluated once per distinct
    rate (the thesis's schedules share k between k_p and k_i)."""
    a_p = math.exp(-k_p * s)
    a_i = a_p if k_i == k_p else math.exp(-k_i * s)
    if k_d == k_p:
        a_d = a_p
    elif k_d == k_i:
        a_d = a_i
    else:
        a_d = math.exp(-k_d * s)
    return a_p, a_i, a_d


@hot_njit(CALLBACK_SIG, cache=True, error_model="numpy")
def constant_gains(
    t: float, e: float, edot: float, p: FloatArray, row: int, o: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Conventional PID: fixed gains, a :data:`CONSTANT` block at p[row, o]."""
    return p[row, o + CG.kp], p[row, o + CG.ki], p[row, o + CG.kd]


@hot_njit(CALLBACK_SIG, cache=True, error_model="numpy")
def time_ags_gains(
    t: float, e: float, edot: float, p: FloatArray, row: int, o: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Eqs. 2.17-2.19 from a :data:`TIME_AGS` block at p[row, o].

    k_p(t) = kp_min + (kp_max - kp_min) exp(-k t)     (2.17)
    k_i(t) = ki_max - (ki_max - ki_min) exp(-k t)     (2.18)
    k_d(t) = kd_min + (kd_max - kd_min) exp(-k t)     (2.19)
    """
    kp_min, kp_max, ki_min, ki_max = (
        p[row, o + TA.kp_min],
        p[row, o + TA.kp_max],
        p[row, o + TA.ki_min],
        p[row, o + TA.ki_max],
    )
    kd_min, kd_max = p[row, o + TA.kd_min], p[row, o + TA.kd_max]
    a_p, a_i, a_d = _decays(p[row, o + TA.kp_rate], p[row, o + TA.ki_rate], p[row, o + TA.kd_rate], t)
    kp = kp_min + (kp_max - kp_min) * a_p
    ki = ki_max - (ki_max - ki_min) * a_i
    kd = kd_min + (kd_max - kd_min) * a_d
    return kp, ki, kd


@hot_njit(CALLBACK_SIG, cache=True, error_model="numpy")
def error_ags_gains(
    t: float, e: float, edot: float, p: FloatArray, row: int, o: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Eqs. 2.20-2.22 on s = |c e| (``on_abs_error`` = 1) or s = c e (0), c = ``error_scale``
    (1 as the loop sees e; 1/step size, or 180/pi for an angle in degrees), an
    :data:`ERROR_AGS` block at p[row, o].

    k_p = kp_max - (kp_max - kp_min) exp(-k s)     (2.20)
    k_i = ki_min - (ki_min - ki_max) exp(-k s)     (2.21)
    k_d = kd_max - (kd_max - kd_min) exp(-k s)     (2.22)
    """
    kp_min, kp_max, ki_min, ki_max = (
        p[row, o + EA.kp_min],
        p[row, o + EA.kp_max],
        p[row, o + EA.ki_min],
        p[row, o + EA.ki_max],
    )
    kd_min, kd_max = p[row, o + EA.kd_min], p[row, o + EA.kd_max]
    e = e * p[row, o + EA.error_scale]
    s = abs(e) if p[row, o + EA.on_abs_error] != 0.0 else e
    a_p, a_i, a_d = _decays(p[row, o + EA.kp_rate], p[row, o + EA.ki_rate], p[row, o + EA.kd_rate], s)
    kp = kp_max - (kp_max - kp_min) * a_p
    ki = ki_min - (ki_min - ki_max) * a_i
    kd = kd_max - (kd_max - kd_min) * a_d
    return kp, ki, kd


class ScheduleModel:
    """A registered gain schedule: its configuration model, packer and compiled function."""

    Config: ClassVar[type[ScheduleConfig]] = ScheduleConfig
    gains: ClassVar[Any] = None

    def pack(self, cfg: Any) -> np.ndarray:
        """The schedule parameter vector sp the compiled function reads."""
        raise NotImplementedError


class Constant(ScheduleModel):
    """Conventional PID: constant k_p, k_i, k_d."""

    Config = ConstantConfig
    gains = staticmethod(constant_gains)

    def pack(self, cfg: ConstantConfig) -> np.ndarray:
        return CONSTANT.pack(kp=cfg.kp, ki=cfg.ki, kd=cfg.kd)


class GainRanges(Protocol):
    """A schedule's configuration with the range of each gain (:class:`AGSConfig`, the fuzzy PID's)."""

    @property
    def kp(self) -> GainRange: ...
    @property
    def ki(self) -> GainRange: ...
    @property
    def kd(self) -> GainRange: ...


def gain_ranges(cfg: GainRanges) -> list[float]:
    """(kp_min, kp_max, ki_min, ki_max, kd_min, kd_max) of a schedule with kp/ki/kd ranges."""
    return [cfg.kp.min, cfg.kp.max, cfg.ki.min, cfg.ki.max, cfg.kd.min, cfg.kd.max]


def _ags_values(cfg: AGSConfig) -> dict[str, float]:
    """The fields shared by :data:`TIME_AGS` and :data:`ERROR_AGS`, by name."""
    ends = {f"{g}_{end}": getattr(getattr(cfg, g), end) for g in ("kp", "ki", "kd") for end in ("min", "max")}
    return {**ends, "kp_rate": cfg.rate.kp, "ki_rate": cfg.rate.ki, "kd_rate": cfg.rate.kd}


class TimeAGS(ScheduleModel):
    """Time adaptive gain scheduling, eqs. 2.17-2.19."""

    Config = TimeAGSConfig
    gains = staticmethod(time_ags_gains)

    def pack(self, cfg: TimeAGSConfig) -> np.ndarray:
        return TIME_AGS.pack(_ags_values(cfg))


class ErrorAGS(ScheduleModel):
    """Error adaptive gain scheduling, eqs. 2.20-2.22 (on |e| by default)."""

    Config = ErrorAGSConfig
    gains = staticmethod(error_ags_gains)

    def pack(self, cfg: ErrorAGSConfig) -> np.ndarray:
        return ERROR_AGS.pack(_ags_values(cfg), on_abs_error=cfg.error == "abs", error_scale=cfg.error_scale)


@cache
def _slots(names: tuple[str, ...], used: frozenset[str] | None) -> FunctionTable:
    return callback_slots(tuple(
        registry.schedules.get(name).gains if used is None or name in used else no_callback for name in names
    ))  # fmt: skip


def schedule_slots(used: Iterable[str] | None = None) -> FunctionTable:
    """The PID's callback table: the compiled function of each registered schedule in ``used``
    (default: every one) in its slot, registry order, the others padded. A schedule is compiled
    when its slot first reaches the kernel, so a table holding only the schedules a controller
    calls through it compiles nothing else."""
    names = tuple(registry.schedules.names())
    if len(names) > CALLBACK_SLOTS:
        raise ConfigError("schedules", len(names), f"at most {CALLBACK_SLOTS} gain schedules can be registered")
    return _slots(names, None if used is None else frozenset(used))


def schedule_index(name: str) -> int:
    """The slot of the schedule registered as ``name``."""
    return registry.schedules.names().index(name)

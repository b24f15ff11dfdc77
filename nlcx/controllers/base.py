"""What a controller is: a compiled step function plus the parameters it reads."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from nlcx.errors import ConfigError
from nlcx.kernel.signatures import ControllerStep
from nlcx.plants.base import Plant
from nlcx.validation import join


class ControllerConfig(BaseModel):
    """Base of every controller's configuration: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    kind: str


@dataclass(frozen=True)
class ControllerInstance:
    """A configured controller: the step function and the numbers it runs on."""

    label: str
    kind: str
    step: ControllerStep
    cp: np.ndarray
    cs0: np.ndarray
    #: Names of the reference channels the step function reads, in order.
    reference_signals: tuple[str, ...]
    #: Time shift of each reference channel, s: r_i(t) = reference(t + offset_i). A preview
    #: controller reads the same signal at several future times (default: no shift).
    reference_offsets: tuple[float, ...] | None = None
    #: Names and units of the values the step function logs every sample.
    log_names: tuple[str, ...] = ()
    log_units: tuple[str, ...] = ()
    config: dict[str, Any] = field(default_factory=dict)
    #: Values the controller's own design produced or uses (e.g. H-infinity gamma and gains,
    #: learning settings), recorded in tuning.csv.
    records: dict[str, object] = field(default_factory=dict)
    #: Logged values whose final value is a result (e.g. learned weights), recorded in tuning.csv.
    final_logs: tuple[str, ...] = ()
    #: The controller's own compiled callbacks (:data:`nlcx.kernel.abi.CALLBACK_SIG`), which
    #: the kernel hands its step function untouched: the PID's gain schedules.
    callbacks: tuple[object, ...] = ()
    #: Where ``step`` is compiled for this controller's structure (the PID's, ``pid.step_for``):
    #: the step of the same arithmetic for rows of any structure of its kind, which the engine
    #: runs when controllers of several structures share a kernel call of few rows.
    general_step: ControllerStep | None = None
    #: The law a controller written as one runs (:class:`~nlcx.controllers.law.LawController`:
    #: its compiled law, shape and parameters' type), which ``nlcx linearize`` differentiates.
    law: Any = None


class ControllerModel:
    """A registered controller. Subclasses set ``Config`` and ``step`` and implement build."""

    Config: ClassVar[type[ControllerConfig]] = ControllerConfig
    step: ClassVar[Any] = None

    def normalize(self, cfg: Any, path: str) -> ControllerConfig:
        """Validate nested plugin sections (e.g. gain schedules) and fill their defaults."""
        return cfg

    def build(self, label: str, cfg: Any, plant: Plant, path: str, dt: float | None = None) -> ControllerInstance:
        """The controller for ``plant``; ``dt`` is the simulation step (controller sampling)."""
        raise NotImplementedError


def check_sample_time(Ts: float, dt: float, path: str = "controller") -> int:
    """Number of simulation steps per controller sample; ConfigError unless Ts is a multiple of dt."""
    ratio = Ts / dt
    n_sub = round(ratio)
    if n_sub < 1 or abs(ratio - n_sub) > 1e-6 * ratio:
        raise ConfigError(
            join(path, "sample_time"),
            Ts,
            f"must be a whole multiple (>= 1) of the simulation step dt = {dt} (sample_time/dt = {ratio:.6g})",
        )
    return int(n_sub)

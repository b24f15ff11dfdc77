"""Constant, step and sinusoidal references (sections 2.3, 2.5.2, 3.5.2, 3.9.2, 4.5.2)."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from nlcx.references.base import ReferenceConfig, ReferenceModel, SignalPlan


class ConstantReferenceConfig(ReferenceConfig):
    kind: Literal["constant"] = Field(
        "constant", description="registered name of this reference; selects the model that validates this section"
    )
    value: float = Field(0.0, description="the constant reference, in the signal's unit")


class StepConfig(ReferenceConfig):
    kind: Literal["step"] = Field(
        "step", description="registered name of this reference; selects the model that validates this section"
    )
    initial: float = Field(0.0, description="reference before the step, in the signal's unit")
    final: float = Field(1.0, description="reference from the step on, in the signal's unit")
    time: float = Field(
        0.0, ge=0, description="time of the step; r = final for t >= time", json_schema_extra={"unit": "s"}
    )


class FilteredStepConfig(StepConfig):
    kind: Literal["filtered_step"] = Field(
        "filtered_step", description="registered name of this reference; selects the model that validates this section"
    )  # type: ignore[assignment]  # a subclass narrows the kind literal that selects its model
    time_constant: float = Field(
        gt=0,
        description="time constant T_f of the first-order prefilter 1 / (T_f s + 1) on the step",
        json_schema_extra={"unit": "s"},
    )


class SineConfig(ReferenceConfig):
    kind: Literal["sine"] = Field(
        "sine", description="registered name of this reference; selects the model that validates this section"
    )
    amplitude: float = Field(description="amplitude, in the signal's unit")
    frequency: float = Field(
        gt=0,
        description=(
            "frequency f of offset + amplitude sin(2 pi f t + phase): the thesis's x_r = 0.3 sin(0.05 pi t) has f = "
            "0.025 Hz"
        ),
        json_schema_extra={"unit": "Hz"},
    )
    phase: float = Field(0.0, description="phase", json_schema_extra={"unit": "rad"})
    offset: float = Field(0.0, description="constant added to the sine, in the signal's unit")


class ConstantReference(ReferenceModel):
    """r(t) = value; the signal is regulated (default for outputs without a reference)."""

    Config = ConstantReferenceConfig

    def values(self, cfg: ConstantReferenceConfig, t: np.ndarray) -> np.ndarray:
        return np.full(t.shape, cfg.value)

    def signal_plan(self, cfg: ConstantReferenceConfig) -> SignalPlan:
        return SignalPlan("regulation", final=cfg.value)


class Step(ReferenceModel):
    """r(t) = initial for t < time, final for t >= time."""

    Config = StepConfig

    def values(self, cfg: StepConfig, t: np.ndarray) -> np.ndarray:
        return np.where(t >= cfg.time, cfg.final, cfg.initial)

    def signal_plan(self, cfg: StepConfig) -> SignalPlan:
        if cfg.final == cfg.initial:
            return SignalPlan("regulation", final=cfg.final)
        return SignalPlan("step", final=cfg.final, t_step=cfg.time)


class FilteredStep(ReferenceModel):
    """A step through a first-order prefilter: r(t) = initial + (final - initial)
    (1 - exp(-(t - time) / T_f)) for t >= time. Measured as the step it filters (the metrics
    of the plain step: a prefilter is part of the loop, not of the specification)."""

    Config = FilteredStepConfig

    def values(self, cfg: FilteredStepConfig, t: np.ndarray) -> np.ndarray:
        rise = -np.expm1(-np.maximum(t - cfg.time, 0.0) / cfg.time_constant)
        return cfg.initial + (cfg.final - cfg.initial) * rise

    def signal_plan(self, cfg: FilteredStepConfig) -> SignalPlan:
        return Step().signal_plan(cfg)


class Sine(ReferenceModel):
    """r(t) = offset + amplitude sin(2 pi frequency t + phase), e.g. x_r = 0.3 sin(0.05 pi t)."""

    Config = SineConfig

    def values(self, cfg: SineConfig, t: np.ndarray) -> np.ndarray:
        return cfg.offset + cfg.amplitude * np.sin(2 * np.pi * cfg.frequency * t + cfg.phase)

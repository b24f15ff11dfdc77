"""Fast-acting external disturbance d = A sin(2 pi f t + phase) added to state derivatives.

The thesis adds d = 20 sin(20 pi t) (A = 20, f = 10 Hz) to every acceleration equation
(eqs. 2.13, 2.15, 3.20-3.26, 3.49-3.53, 4.29-4.37).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from nlcx.errors import ConfigError
from nlcx.uncertainty.base import Hooks, UncertaintyConfig, UncertaintyModel
from nlcx.validation import join


class DisturbanceConfig(UncertaintyConfig):
    kind: Literal["disturbance"] = Field(
        "disturbance", description="registered name of this uncertainty; selects the model that validates this section"
    )
    waveform: Literal["sine", "step"] = Field(
        "sine", description="sine: amplitude sin(2 pi frequency t + phase) (eq. 2.16); step: amplitude from t >= start"
    )
    amplitude: float = Field(
        20.0,
        description=(
            "amplitude of d, added to the derivative of each target state (for a velocity state: an acceleration, "
            "m/s^2 or rad/s^2)"
        ),
    )
    frequency: float = Field(
        10.0, ge=0, description="frequency of the sine; 20 pi t in eq. 2.16 is 10 Hz", json_schema_extra={"unit": "Hz"}
    )
    phase: float = Field(0.0, description="phase of the sine", json_schema_extra={"unit": "rad"})
    start: float = Field(
        0.0, ge=0, description="time the step starts (waveform: step)", json_schema_extra={"unit": "s"}
    )
    states: list[str] | None = Field(
        None, description="states whose derivative receives d; default: every velocity state (the accelerations)"
    )


class Disturbance(UncertaintyModel):
    """d(t) = amplitude sin(2 pi frequency t + phase), or a step, added to chosen state derivatives."""

    Config = DisturbanceConfig

    def apply(self, cfg: DisturbanceConfig, hooks: Hooks, path: str) -> None:
        plant = hooks.plant
        names = plant.state_names
        targets = cfg.states if cfg.states is not None else list(plant.features.velocity_states)
        column = np.zeros(len(names))
        for i, name in enumerate(targets):
            if name not in names:
                raise ConfigError(join(path, "states", i), name, f"unknown state; allowed: {', '.join(names)}")
            column[names.index(name)] = 1.0
        ts = hooks.stage_times
        if cfg.waveform == "step":
            values = np.where(ts >= cfg.start, cfg.amplitude, 0.0)
        else:
            values = cfg.amplitude * np.sin(2 * np.pi * cfg.frequency * ts + cfg.phase)
        hooks.add_disturbance(column, values)

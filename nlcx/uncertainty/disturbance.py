"""Fast-acting external disturbance d(t), added to state derivatives or to the plant's inputs.

The thesis adds d = 20 sin(20 pi t) (A = 20, f = 10 Hz) to every acceleration equation
(eqs. 2.13, 2.15, 3.20-3.26, 3.49-3.53, 4.29-4.37). From ``start`` on (0 before it):

    sine: d(t) = A sin(2 pi f (t - start) + phase),    step: d(t) = A,

added (``entry: accelerations``, the default) to the derivative of each chosen state, sampled
at the Runge-Kutta stage times, or (``entry: input``) to the chosen plant inputs as a force
after the controller and before the plant: an ACTUATOR loop element that adds d(t_k) to the
input held over each step, so the recorded input is the force the plant receives.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, ValidationInfo, field_validator

from nlcx.errors import ConfigError, did_you_mean
from nlcx.uncertainty.base import Element, Hooks, UncertaintyConfig, UncertaintyModel
from nlcx.uncertainty.noise import add_samples
from nlcx.validation import join


class DisturbanceConfig(UncertaintyConfig):
    kind: Literal["disturbance"] = Field(
        "disturbance", description="registered name of this uncertainty; selects the model that validates this section"
    )
    waveform: Literal["sine", "step"] = Field(
        "sine",
        description=(
            "sine: amplitude sin(2 pi frequency (t - start) + phase) from t >= start (eq. 2.16 with start = 0); "
            "step: amplitude from t >= start; d = 0 before start"
        ),
    )
    amplitude: float = Field(
        20.0,
        description=(
            "amplitude A of d: with entry accelerations, added to the derivative of each target state (for a velocity "
            "state an acceleration, m/s^2 or rad/s^2); with entry input, a force in the input's unit (N)"
        ),
    )
    frequency: float = Field(
        10.0, ge=0, description="frequency of the sine; 20 pi t in eq. 2.16 is 10 Hz", json_schema_extra={"unit": "Hz"}
    )
    phase: float = Field(
        0.0,
        description="phase of the sine at t = start: its argument is 2 pi f (t - start) + phase",
        json_schema_extra={"unit": "rad"},
    )
    start: float = Field(
        0.0,
        ge=0,
        description="time the disturbance starts, either waveform: d = 0 for t < start",
        json_schema_extra={"unit": "s"},
    )
    entry: Literal["accelerations", "input"] = Field(
        "accelerations",
        description=(
            "where d enters: accelerations: added to the derivatives of the states named in states, sampled at the "
            "integrator's stage times; input: added as a force to the plant inputs named in inputs, after the "
            "controller and before the plant, held over each step (the recorded input includes it)"
        ),
    )
    states: list[str] | None = Field(
        None,
        description=(
            "states whose derivative receives d, with entry accelerations; default: every velocity state (the "
            "accelerations)"
        ),
    )
    inputs: list[str] | None = Field(
        None, description="plant inputs that receive d, with entry input, by name; default: every input"
    )

    @field_validator("states")
    @classmethod
    def _states_need_accelerations(cls, states: list[str] | None, info: ValidationInfo) -> list[str] | None:
        if states is not None and info.data.get("entry") == "input":
            raise ValueError("allowed only with entry: accelerations (with entry: input, name the inputs in inputs)")
        return states

    @field_validator("inputs")
    @classmethod
    def _inputs_need_input_entry(cls, inputs: list[str] | None, info: ValidationInfo) -> list[str] | None:
        if inputs is not None and info.data.get("entry") != "input":
            raise ValueError("allowed only with entry: input (with entry: accelerations, name the states in states)")
        return inputs


def disturbance_values(cfg: DisturbanceConfig, t: np.ndarray) -> np.ndarray:
    """d at the times ``t``: 0 before ``start``; from it, the sine A sin(2 pi f (t - start) + phase)
    or the step A."""
    on = t >= cfg.start
    if cfg.waveform == "step":
        return np.where(on, cfg.amplitude, 0.0)
    return np.where(on, cfg.amplitude * np.sin(2 * np.pi * cfg.frequency * (t - cfg.start) + cfg.phase), 0.0)


class Disturbance(UncertaintyModel):
    """d(t) = amplitude sin(2 pi frequency (t - start) + phase), or a step, from ``start`` on,
    added to chosen state derivatives or to chosen plant inputs."""

    Config = DisturbanceConfig

    def apply(self, cfg: DisturbanceConfig, hooks: Hooks, path: str) -> None:
        if cfg.entry == "input":
            self._at_inputs(cfg, hooks, path)
        else:
            self._at_accelerations(cfg, hooks, path)

    @staticmethod
    def _at_accelerations(cfg: DisturbanceConfig, hooks: Hooks, path: str) -> None:
        """d at the stage times, added to the derivative of each target state."""
        plant = hooks.plant
        names = plant.state_names
        targets = cfg.states if cfg.states is not None else list(plant.features.velocity_states)
        column = np.zeros(len(names))
        for i, name in enumerate(targets):
            if name not in names:
                problem = f"unknown state{did_you_mean(name, names)}; allowed: {', '.join(names)}"
                raise ConfigError(join(path, "states", i), name, problem)
            column[names.index(name)] = 1.0
        hooks.add_disturbance(column, disturbance_values(cfg, hooks.stage_times))

    @staticmethod
    def _at_inputs(cfg: DisturbanceConfig, hooks: Hooks, path: str) -> None:
        """d at the sampling instants, added to each target input by an actuator element."""
        plant = hooks.plant
        names = plant.input_names
        values = np.zeros((hooks.t.size, len(names)))
        d = disturbance_values(cfg, hooks.t)
        for i, name in enumerate(cfg.inputs if cfg.inputs is not None else names):
            if name not in names:
                raise ConfigError(
                    join(path, "inputs", i),
                    name,
                    f"not an input of {plant.name}{did_you_mean(name, names)}; allowed: {', '.join(names)}",
                )
            values[:, names.index(name)] = d
        hooks.add_element(Element(hook="actuator", function=add_samples, data=values, name="disturbance at the inputs"))

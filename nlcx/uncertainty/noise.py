"""Band-limited white noise "in the controllers", as Simulink's block makes it.

Simulink's Band-Limited White Noise block holds a normally distributed sample for one
sample time T_s and scales it so that its power spectral density matches the requested
noise power P: each sample is N(0, P / T_s). nlcx draws the samples from the run's seeded
generator (numpy.random.SeedSequence) and adds them either to the measured outputs the
controllers read (default) or to the controllers' outputs.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field

from nlcx.errors import ConfigError
from nlcx.uncertainty.base import Perturbations, UncertaintyConfig, UncertaintyModel
from nlcx.validation import join


class NoiseConfig(UncertaintyConfig):
    kind: Literal["noise"] = "noise"
    #: Noise power P (the block's "Noise power"): sample variance is P / sample_time.
    power: float = Field(1e-7, ge=0)
    #: Hold time T_s of each sample, s (rounded to whole simulation steps).
    sample_time: float = Field(0.01, gt=0)
    #: "measurement": added to the outputs the controllers read (the errors they form);
    #: "controller_output": added to the forces the controllers command.
    injection: Literal["measurement", "controller_output"] = "measurement"
    #: Signals that receive noise (outputs or inputs by name); default: all of them.
    signals: list[str] | None = None


class Noise(UncertaintyModel):
    """Band-limited white noise: held Gaussian samples of variance power/sample_time."""

    Config = NoiseConfig

    def apply(self, cfg: NoiseConfig, perturbations: Perturbations, path: str) -> None:
        plant = perturbations.plant
        measured = cfg.injection == "measurement"
        names = plant.output_names if measured else plant.input_names
        chosen = cfg.signals if cfg.signals is not None else names
        t = perturbations.t
        dt = float(t[1] - t[0])
        hold = max(1, round(cfg.sample_time / dt))
        n_samples = -(-t.size // hold)
        draws = perturbations.rng.standard_normal((n_samples, len(chosen)))
        sigma = math.sqrt(cfg.power / (hold * dt))
        values = np.zeros((t.size, len(names)))
        held = np.repeat(draws, hold, axis=0)[: t.size] * sigma
        for i, name in enumerate(chosen):
            if name not in names:
                kind = "output" if measured else "input"
                raise ConfigError(
                    join(path, "signals", i),
                    name,
                    f"not an {kind} of {plant.name}; allowed: {', '.join(names)}",
                )
            values[:, names.index(name)] += held[:, i]
        perturbations.add_noise(cfg.injection, values)

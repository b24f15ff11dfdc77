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

from nlcx._numba_compat import hot_njit
from nlcx.errors import ConfigError, did_you_mean
from nlcx.kernel.signatures import FloatArray, IntArray
from nlcx.uncertainty.base import Element, Hooks, UncertaintyConfig, UncertaintyModel
from nlcx.validation import join


class NoiseConfig(UncertaintyConfig):
    kind: Literal["noise"] = Field(
        "noise", description="registered name of this uncertainty; selects the model that validates this section"
    )
    power: float = Field(
        1e-7,
        ge=0,
        description=(
            "noise power P of Simulink's Band-Limited White Noise block: the samples' variance is P / sample_time (in "
            "the signal's unit squared times s)"
        ),
    )
    sample_time: float = Field(
        0.01,
        gt=0,
        description="hold time T_s of each sample (rounded to whole simulation steps)",
        json_schema_extra={"unit": "s"},
    )
    injection: Literal["measurement", "controller_output"] = Field(
        "measurement",
        description=(
            "measurement: added to the outputs the controllers read; controller_output: added to the inputs the "
            "controllers command"
        ),
    )
    signals: list[str] | None = Field(
        None, description="signals that receive noise (outputs or inputs by name); default: all of them"
    )


class Noise(UncertaintyModel):
    """Band-limited white noise: held Gaussian samples of variance power/sample_time."""

    Config = NoiseConfig

    def apply(self, cfg: NoiseConfig, hooks: Hooks, path: str) -> None:
        plant = hooks.plant
        measured = cfg.injection == "measurement"
        names = plant.output_names if measured else plant.input_names
        chosen = cfg.signals if cfg.signals is not None else names
        t = hooks.t
        dt = float(t[1] - t[0])
        hold = max(1, round(cfg.sample_time / dt))
        n_samples = -(-t.size // hold)
        assert hooks.rng is not None  # set before each uncertainty's apply
        draws = hooks.rng.standard_normal((n_samples, len(chosen)))
        sigma = math.sqrt(cfg.power / (hold * dt))
        values = np.zeros((t.size, len(names)))
        held = np.repeat(draws, hold, axis=0)[: t.size] * sigma
        for i, name in enumerate(chosen):
            if name not in names:
                kind = "output" if measured else "input"
                raise ConfigError(
                    join(path, "signals", i),
                    name,
                    f"not an {kind} of {plant.name}{did_you_mean(name, names)}; allowed: {', '.join(names)}",
                )
            values[:, names.index(name)] += held[:, i]
        add_sequence(hooks, "sensor" if measured else "actuator", values)


@hot_njit(cache=True, error_model="numpy")
def add_samples(
    t: float,
    dt: float,
    k: int,
    signal: FloatArray,
    vid: IntArray,
    ep: FloatArray,
    es: FloatArray,
    data: FloatArray,
    p_off: int,
    s_off: int,
    d_off: int,
) -> None:  # pragma: no cover - compiled
    """signal[b, j] += data[variant of b, k, d_off + j]: a sampled sequence added to every
    channel of the signal (the noise sample of each output or input at t_k)."""
    kk = k if data.shape[1] > 1 else 0
    for b in range(signal.shape[0]):
        bv = vid[b] if data.shape[0] > 1 else 0
        for j in range(signal.shape[1]):
            signal[b, j] += data[bv, kk, d_off + j]


def add_sequence(hooks: Hooks, hook: str, values: np.ndarray) -> None:
    """Add ``values`` (K+1, n_signal) to the signal at ``hook``; a second sequence at the same
    hook is summed into the first (one element: the sum is added once)."""
    for element in hooks.elements:
        if element.function is add_samples and element.hook == hook and element.data is not None:
            element.data = element.data + values
            return
    hooks.add_element(Element(hook=hook, function=add_samples, data=values, name=f"noise at {hook}"))

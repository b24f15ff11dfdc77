"""Actuator saturation |u_j| <= u_max: the one clamp of nlcx, and the ACTUATOR loop element that applies it.

:func:`saturate` is the clamp; two things apply it:

- this element, to what any controller commands (a single neuron's, a preview controller's),
  as a physical actuator does: the controller does not see the clipped value;
- the PID's own ``saturation`` (:mod:`nlcx.controllers.pid`), which also guards its
  integrators against windup.

    u_j <- min(max(u_j, -u_max), u_max)   for every limited input j
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from nlcx._numba_compat import hot_njit
from nlcx.errors import ConfigError, did_you_mean
from nlcx.kernel.signatures import FloatArray, IntArray
from nlcx.layout import Layout
from nlcx.uncertainty.base import Element, Hooks, UncertaintyConfig, UncertaintyModel
from nlcx.validation import join

#: Per input: its limit u_max (inf: not limited).
LIMIT = Layout("ActuatorLimit", ("u_max",))
M = LIMIT.at


class ActuatorSaturationConfig(UncertaintyConfig):
    kind: Literal["actuator_saturation"] = Field(
        "actuator_saturation",
        description="registered name of this uncertainty; selects the model that validates this section",
    )
    limit: float = Field(gt=0, description="limit u_max of each limited input, |u| <= u_max, in the input's unit")
    inputs: list[str] | None = Field(None, description="inputs that are limited, by name; default: every input")


@hot_njit(cache=True, inline="always", error_model="numpy")
def saturate(u: float, limit: float) -> float:  # pragma: no cover - compiled
    """u clipped to [-limit, limit] (limit inf: u): the actuator's saturation, which this element
    and the PID's ``saturation`` apply."""
    return min(max(u, -limit), limit)


@hot_njit(cache=True, error_model="numpy")
def saturate_inputs(
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
    """Clip every limited input of every row to [-u_max, u_max] (:func:`saturate`)."""
    for b in range(signal.shape[0]):
        v_id = vid[b]
        for j in range(signal.shape[1]):
            signal[b, j] = saturate(signal[b, j], ep[v_id, p_off + len(M) * j + M.u_max])


class ActuatorSaturation(UncertaintyModel):
    """Saturation |u| <= u_max of the plant's inputs, whatever controller drives them."""

    Config = ActuatorSaturationConfig

    def apply(self, cfg: ActuatorSaturationConfig, hooks: Hooks, path: str) -> None:
        names = hooks.plant.input_names
        limits = np.full(len(names), np.inf)
        for i, name in enumerate(cfg.inputs if cfg.inputs is not None else names):
            if name not in names:
                problem = f"not an input{did_you_mean(name, names)}; allowed: {', '.join(names)}"
                raise ConfigError(join(path, "inputs", i), name, problem)
            limits[names.index(name)] = cfg.limit
        params = np.concatenate([LIMIT.pack(u_max=u) for u in limits])
        hooks.add_element(Element("actuator", saturate_inputs, params, np.zeros(0), None, "saturation"))

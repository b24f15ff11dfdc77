"""A first-order lag on the applied forces: an ACTUATOR loop element.

Each lagged input passes through 1 / (tau s + 1) sampled at the simulation step: with
alpha = 1 - exp(-dt / tau), the force applied over [t_k, t_k+1] is

    v_k = v_{k-1} + alpha (u_k - v_{k-1}),   v_{-1} = u_0 (the lag starts at rest),

the exact response of the lag to a held input, read at the end of each step. The element
acts after the controller (and after a PID's own saturation), before the plant.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field

from nlcx._numba_compat import hot_njit
from nlcx.errors import ConfigError, did_you_mean
from nlcx.kernel.signatures import FloatArray, IntArray
from nlcx.layout import Layout
from nlcx.uncertainty.base import Element, Hooks, UncertaintyConfig, UncertaintyModel
from nlcx.validation import join

#: Per input: alpha = 1 - exp(-dt / tau) (0: not lagged).
LAG = Layout("ActuatorLag", ("alpha",))
#: Per input: the lag's output v and whether it has started.
LAG_STATE = Layout("ActuatorLagState", ("v", "started"))
A = LAG.at
V = LAG_STATE.at


class ActuatorLagConfig(UncertaintyConfig):
    kind: Literal["actuator_lag"] = Field(
        "actuator_lag", description="registered name of this uncertainty; selects the model that validates this section"
    )
    tau: float = Field(
        gt=0, description="time constant tau of the first-order lag 1 / (tau s + 1)", json_schema_extra={"unit": "s"}
    )
    inputs: list[str] | None = Field(None, description="inputs that are lagged, by name; default: every input")


@hot_njit(cache=True, error_model="numpy")
def first_order_lag(
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
    """v = v + alpha (u - v) on every lagged input of every row; u becomes v."""
    for b in range(signal.shape[0]):
        v_id = vid[b]
        for j in range(signal.shape[1]):
            alpha = ep[v_id, p_off + len(A) * j + A.alpha]
            if alpha == 0.0:
                continue
            s = s_off + len(V) * j
            if es[v_id, s + V.started] == 0.0:
                es[v_id, s + V.v] = signal[b, j]
                es[v_id, s + V.started] = 1.0
            es[v_id, s + V.v] += alpha * (signal[b, j] - es[v_id, s + V.v])
            signal[b, j] = es[v_id, s + V.v]


class ActuatorLag(UncertaintyModel):
    """First-order actuator lag 1 / (tau s + 1) on the plant's inputs."""

    Config = ActuatorLagConfig

    def apply(self, cfg: ActuatorLagConfig, hooks: Hooks, path: str) -> None:
        names = hooks.plant.input_names
        dt = float(hooks.t[1] - hooks.t[0])
        alpha = np.zeros(len(names))
        for i, name in enumerate(cfg.inputs if cfg.inputs is not None else names):
            if name not in names:
                problem = f"not an input{did_you_mean(name, names)}; allowed: {', '.join(names)}"
                raise ConfigError(join(path, "inputs", i), name, problem)
            alpha[names.index(name)] = -math.expm1(-dt / cfg.tau)
        params = np.concatenate([LAG.pack(alpha=a) for a in alpha])
        hooks.add_element(
            Element("actuator", first_order_lag, params, np.zeros(LAG_STATE.size * len(names)), None, "lag")
        )

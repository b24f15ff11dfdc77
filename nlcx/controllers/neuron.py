"""Single-neuron adaptive PID (section 5.4.2, eqs. 5.15-5.19; Liu, 2008).

At each controller sample k (period ``sample_time``, the input held in between):

    x1(k) = e(k) - e(k-1)                       (eq. 5.15, proportional)
    x2(k) = e(k)                                (eq. 5.16, integral)
    x3(k) = e(k) - 2 e(k-1) + e(k-2)            (eq. 5.17; printed with - e(k-2))
    u(k)  = u(k-1) + K sum_i w_i'(k) x_i(k)     (eq. 5.18, K the neuron gain eta)

with the weights adapted by the supervised Hebbian rule of Liu (2008),
w_i(k) = w_i(k-1) + eta_i e(k) u(k-1) x_i(k), or literally as eq. 5.19 prints it,
w_i(k) = w_i(k-1) + eta_i e(k-1) u(k-1); w_i' = w_i / sum_j |w_j| when ``normalize``.
"""

from __future__ import annotations

from typing import Literal

from numba import njit
from pydantic import BaseModel, ConfigDict, Field

from nlcx._numba_compat import hot_njit
from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel, check_sample_time
from nlcx.errors import ConfigError
from nlcx.kernel.signatures import Callbacks, FloatArray
from nlcx.layout import Layout
from nlcx.plants.base import Plant, equilibrium_input
from nlcx.validation import join


class LearningRates(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    p: float = Field(0.4, ge=0, description="learning rate eta_P of the proportional weight w1")
    i: float = Field(0.35, ge=0, description="learning rate eta_I of the integral weight w2")
    d: float = Field(0.4, ge=0, description="learning rate eta_D of the derivative weight w3")


class NeuronConfig(ControllerConfig):
    kind: Literal["single_neuron"] = Field(
        "single_neuron", description="registered name of this controller; selects the model that validates this section"
    )
    signal: str | None = Field(None, description="plant output the neuron regulates (default: the plant's only output)")
    gain: float = Field(0.12, gt=0, description="neuron gain K (the eta of eq. 5.18)")
    learning: LearningRates = Field(LearningRates(), description="learning rates of the three weights")
    weights: tuple[float, float, float] = Field((0.1, 0.1, 0.1), description="initial weights (w1, w2, w3)")
    second_difference: Literal["standard", "printed"] = Field(
        "standard", description="eq. 5.17: standard e(k) - 2e(k-1) + e(k-2), or printed e(k) - 2e(k-1) - e(k-2)"
    )
    rule: Literal["hebbian", "printed"] = Field(
        "hebbian", description="hebbian: Liu's supervised Hebbian rule with x_i(k); printed: eq. 5.19 as printed"
    )
    normalize: bool = Field(
        True, description="use w_i / sum_j |w_j| in place of each weight w_i (Liu's normalised neuron PID)"
    )
    sample_time: float = Field(
        0.1,
        gt=0,
        description="controller sample period, a whole number of simulation steps",
        json_schema_extra={"unit": "s"},
    )
    feedforward: Literal["none", "equilibrium"] = Field(
        "none", description="equilibrium: add the input that holds the plant at its operating point"
    )


#: The parameter row cp (sample time rounded to whole simulation steps; bias the feed-forward).
NEURON = Layout(
    "SingleNeuron",
    ("y_index", "r_index", "u_index", "gain", "eta_p", "eta_i", "eta_d",
     "normalize", "printed_second_difference", "printed_rule", "sample_time", "bias"),
)  # fmt: skip
#: The state cs: step counter, e(k-1), e(k-2), u(k-1), the weights, whether it has started.
NEURON_STATE = Layout("SingleNeuronState", ("step", "e1", "e2", "u1", "w1", "w2", "w3", "started"))
#: The log row: the weights in use (normalised when ``normalize``) and the neuron's output u(k).
NEURON_LOG = Layout("SingleNeuronLog", ("w1", "w2", "w3", "u"))
N = NEURON.at
S = NEURON_STATE.at
G = NEURON_LOG.at


@njit(cache=True, error_model="numpy")
def _neuron_row(
    t: float, dt: float, y: FloatArray, r: FloatArray, cp: FloatArray, cs: FloatArray, u: FloatArray, log: FloatArray
) -> None:  # pragma: no cover - compiled
    """Eqs. 5.15-5.19 for one variant at every ``hold``-th simulation step; the input is
    held in between."""
    yi, ri, ui = int(cp[N.y_index]), int(cp[N.r_index]), int(cp[N.u_index])
    hold = max(1, round(cp[N.sample_time] / dt))
    if int(cs[S.step]) % hold == 0:
        e = r[ri] - y[yi]
        if cs[S.started] == 0.0:
            cs[S.e1] = e
            cs[S.e2] = e
            cs[S.started] = 1.0
        e1, e2, u1 = cs[S.e1], cs[S.e2], cs[S.u1]
        x1 = e - e1  # eq. 5.15
        x2 = e  # eq. 5.16
        x3 = e - 2.0 * e1 - e2 if cp[N.printed_second_difference] != 0.0 else e - 2.0 * e1 + e2  # eq. 5.17
        if cp[N.printed_rule] != 0.0:  # eq. 5.19 as printed
            cs[S.w1] += cp[N.eta_p] * e1 * u1
            cs[S.w2] += cp[N.eta_i] * e1 * u1
            cs[S.w3] += cp[N.eta_d] * e1 * u1
        else:  # supervised Hebbian learning (Liu, 2008)
            cs[S.w1] += cp[N.eta_p] * e * u1 * x1
            cs[S.w2] += cp[N.eta_i] * e * u1 * x2
            cs[S.w3] += cp[N.eta_d] * e * u1 * x3
        w1, w2, w3 = cs[S.w1], cs[S.w2], cs[S.w3]
        if cp[N.normalize] != 0.0:
            total = abs(w1) + abs(w2) + abs(w3)
            if total > 0.0:
                w1, w2, w3 = w1 / total, w2 / total, w3 / total
        cs[S.u1] = u1 + cp[N.gain] * (w1 * x1 + w2 * x2 + w3 * x3)  # eq. 5.18
        cs[S.e2] = e1
        cs[S.e1] = e
        log[G.w1] = w1
        log[G.w2] = w2
        log[G.w3] = w3
    else:
        log[G.w1] = cs[S.w1]
        log[G.w2] = cs[S.w2]
        log[G.w3] = cs[S.w3]
    cs[S.step] += 1.0
    u[ui] = cp[N.bias] + cs[S.u1]
    log[G.u] = cs[S.u1]


@hot_njit(cache=True, error_model="numpy")
def neuron_step(
    t: float,
    dt: float,
    x: FloatArray,
    y: FloatArray,
    r: FloatArray,
    cp: FloatArray,
    cs: FloatArray,
    u: FloatArray,
    log: FloatArray,
    callbacks: Callbacks,
) -> None:  # pragma: no cover - compiled
    """The single-neuron adaptive PID (eqs. 5.15-5.19), every row."""
    for b in range(y.shape[0]):
        _neuron_row(t, dt, y[b], r[b], cp[b], cs[b], u[b], log[b])


class SingleNeuron(ControllerModel):
    """Single-neuron adaptive PID (eqs. 5.15-5.19) for a SISO loop."""

    Config = NeuronConfig
    step = staticmethod(neuron_step)

    def build(
        self, label: str, cfg: NeuronConfig, plant: Plant, path: str, dt: float | None = None
    ) -> ControllerInstance:
        if dt is not None:
            check_sample_time(cfg.sample_time, dt, path)
        outputs, inputs = plant.output_names, plant.input_names
        signal = cfg.signal or (outputs[0] if len(outputs) == 1 else None)
        if signal not in outputs:
            raise ConfigError(
                join(path, "signal"), cfg.signal, f"name one output of {plant.name}: {', '.join(outputs)}"
            )
        if len(inputs) != 1:
            raise ConfigError(path, cfg.kind, f"the single neuron drives one input; {plant.name} has {len(inputs)}")
        bias = float(equilibrium_input(plant)[0]) if cfg.feedforward == "equilibrium" else 0.0
        index = outputs.index(signal)
        cp = NEURON.pack(
            y_index=index, r_index=index, u_index=0, gain=cfg.gain,
            eta_p=cfg.learning.p, eta_i=cfg.learning.i, eta_d=cfg.learning.d, normalize=cfg.normalize,
            printed_second_difference=cfg.second_difference == "printed", printed_rule=cfg.rule == "printed",
            sample_time=cfg.sample_time, bias=bias,
        )  # fmt: skip
        w1, w2, w3 = cfg.weights
        cs0 = NEURON_STATE.pack(step=0, e1=0, e2=0, u1=0, w1=w1, w2=w2, w3=w3, started=0)
        return ControllerInstance(
            label=label,
            kind="single_neuron",
            step=self.step,
            cp=cp,
            cs0=cs0,
            reference_signals=tuple(outputs),
            log_names=tuple(f"neuron.{name}" for name in NEURON_LOG.fields),
            log_units=("", "", "", plant.unit_of(inputs[0])),
            config=cfg.model_dump(),
            records={
                "gain_K": cfg.gain,
                "eta_p": cfg.learning.p,
                "eta_i": cfg.learning.i,
                "eta_d": cfg.learning.d,
                "w1_initial": cfg.weights[0],
                "w2_initial": cfg.weights[1],
                "w3_initial": cfg.weights[2],
                "sample_time": cfg.sample_time,
                "rule": cfg.rule,
                "second_difference": cfg.second_difference,
                "normalize": cfg.normalize,
            },
            final_logs=("neuron.w1", "neuron.w2", "neuron.w3"),
        )

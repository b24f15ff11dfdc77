"""A control law linearised numerically about the plant's operating point, as a state-space system.

A law written with :mod:`nlcx.controllers.law` (a user's :func:`nlcx.controller`, the
``lqr``, ``pole_placement``, ``state_feedback`` and ``sliding_mode`` controllers) maps, every
period T, its measures y, references r and states s to the inputs it drives and its next
states:

    u = h(y, r, s),       s_{k+1} = g(y, r, s_k).

Its derivatives at the operating point (y and r at the plant's operating point, s at the law's
initial states) by central differences give the linear law

    u = u_0 + H_y Δy + H_r Δr + H_s Δs,      dΔs/dt = ((G_s - I) Δs + G_y Δy + G_r Δr) / T,   (1)

the continuous model of a law updated every T (the forward-Euler integrator s + T e becomes
ds/dt = e). The inputs the law does not drive are 0. The law measures outputs and states: the
plant's linear model gains an output per measured state that is not already an output.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import control as ct
import numpy as np

from nlcx.analysis.linear import reference_name

if TYPE_CHECKING:
    import pandas as pd

    from nlcx.controllers.base import ControllerInstance
    from nlcx.plants.base import Plant

__all__ = ["law_closed_loop", "law_gains", "law_margins", "law_system", "measured_plant"]

#: Relative step of the central differences.
STEP = 1e-6


def _evaluate(
    model: Any, controller: ControllerInstance, period: float, y: np.ndarray, r: np.ndarray, s: np.ndarray
) -> np.ndarray:
    """(u, s_next) of the law of period ``period`` at (y, r, s), concatenated."""
    shape = model.shape
    params = controller.cp[shape.p0 : shape.p0 + shape.n_p]
    p = model.params_type(*params) if model.params_type is not None else tuple(float(v) for v in params)
    out = model.law(0.0, period, tuple(map(float, y)), tuple(map(float, r)), tuple(map(float, s)), p)
    return np.array([*out[0], *out[1]], dtype=float)


def _operating_point(controller: ControllerInstance, plant: Plant) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(y, r, s) at the plant's operating point: each measure and reference at its value there,
    the law's states at their initial values."""
    from nlcx.plants.base import equilibrium_input

    model = controller.law
    shape = model.shape
    x_op = plant.features.x_op if plant.features.x_op is not None else np.zeros(len(plant.states))
    values = dict(zip(plant.state_names, x_op, strict=True))
    values |= dict(zip(plant.output_names, plant.C @ x_op, strict=True))
    values |= dict(zip(plant.input_names, equilibrium_input(plant, x_op), strict=True))
    codes = controller.cp[: shape.n_y]
    y = np.array([x_op[int(c)] if c >= 0 else (plant.C @ x_op)[int(-c - 1)] for c in codes])
    r = np.array([values[name] for name in controller.reference_signals])
    s = np.array(controller.cs0[shape.s0 : shape.s0 + shape.n_s])
    return y, r, s


def _jacobian(f: Callable[[np.ndarray], np.ndarray], at: np.ndarray) -> np.ndarray:
    """The Jacobian of ``f`` (a vector of the deviation from ``at``) by central differences."""
    columns = []
    for j in range(at.size):
        h = STEP * max(1.0, abs(float(at[j])))
        d = np.zeros(at.size)
        d[j] = h
        columns.append((f(d) - f(-d)) / (2 * h))
    return np.column_stack(columns) if columns else np.zeros((f(np.zeros(0)).size, 0))


def _measure_names(controller: ControllerInstance, plant: Plant) -> list[str]:
    """The names of the law's measures, as the plant's linear model names them."""
    codes = controller.cp[: controller.law.shape.n_y]
    return [plant.state_names[int(c)] if c >= 0 else plant.output_names[int(-c - 1)] for c in codes]


def law_system(controller: ControllerInstance, plant: Plant, dt: float) -> ct.StateSpace:
    """Eq. 1 as a named system from the references (``<signal>_ref``) and the measures to every
    plant input (those the law does not drive: 0)."""
    shape = controller.law.shape
    y0, r0, s0 = _operating_point(controller, plant)
    n_y, n_r = y0.size, r0.size
    at = np.concatenate([y0, r0, s0])
    period = float(controller.cp[shape.hold + 1]) or dt

    def f(d: np.ndarray) -> np.ndarray:
        x = at + d
        return _evaluate(controller.law, controller, period, x[:n_y], x[n_y : n_y + n_r], x[n_y + n_r :])

    J = _jacobian(f, at)
    n_u, n_s = shape.n_u, shape.n_s
    H, G = J[:n_u], J[n_u:]
    A = (G[:, n_y + n_r :] - np.eye(n_s)) / period
    B = np.hstack([G[:, n_y : n_y + n_r], G[:, :n_y]]) / period
    driven = [int(i) for i in controller.cp[n_y : n_y + n_u]]
    C = np.zeros((len(plant.inputs), n_s))
    D = np.zeros((len(plant.inputs), n_r + n_y))
    for j, i in enumerate(driven):
        C[i] = H[j, n_y + n_r :]
        D[i] = np.concatenate([H[j, n_y : n_y + n_r], H[j, :n_y]])
    inputs = [*(reference_name(name) for name in controller.reference_signals), *_measure_names(controller, plant)]
    states = [f"{shape.name}.{name}" for name, _ in shape.states]
    return ct.ss(A, B, C, D, inputs=inputs, outputs=plant.input_names, states=states, name="controller")


def measured_plant(linear: ct.StateSpace, controller: ControllerInstance, plant: Plant) -> ct.StateSpace:
    """The plant's linear model with an output for each state the law measures that is not an output."""
    extra = [name for name in _measure_names(controller, plant) if name not in plant.output_names]
    if not extra:
        return linear
    rows = np.array([[1.0 if s == name else 0.0 for s in plant.state_names] for name in extra])
    C = np.vstack([linear.C, rows])
    D = np.vstack([linear.D, np.zeros((len(extra), linear.ninputs))])
    return ct.ss(linear.A, linear.B, C, D, states=linear.state_labels, inputs=linear.input_labels,
                 outputs=[*linear.output_labels, *extra], name="plant")  # fmt: skip


def law_closed_loop(plant: ct.StateSpace, controller: ct.StateSpace, outputs: Sequence[str]) -> ct.StateSpace:
    """The closed loop from the law's references to the plant's ``outputs`` and inputs."""
    refs = [name for name in controller.input_labels if name.endswith("_ref")]
    outlist = [*outputs, *plant.input_labels]
    loop = ct.interconnect([plant, controller], inplist=refs, outlist=outlist, check_unused=False)
    return ct.ss(loop, inputs=refs, outputs=outlist, states=loop.state_labels, name="closed_loop")


def law_margins(
    plant: ct.StateSpace, controller: ct.StateSpace, driven: Sequence[str]
) -> tuple[pd.DataFrame, dict[str, ct.StateSpace]]:
    """The margins with the loop broken at each input the law drives (the others closed):
    L(s) from the cut input w back to the law's output for it, references at 0."""
    import pandas as pd

    from nlcx.analysis.linear import margins_row

    law = ct.ss(controller, outputs=[f"v_{name}" for name in plant.input_labels], name="law")
    rows, transfers = [], {}
    for cut in driven:
        closed = [
            ct.summing_junction(inputs=[f"v_{name}"], output=name, name=f"close_{name}")
            for name in plant.input_labels
            if name != cut
        ]
        opened = ct.summing_junction(inputs=["w"], output=cut, name="cut")
        system = ct.interconnect([plant, law, *closed, opened], inplist=["w"], outlist=[f"v_{cut}"],
                                 check_unused=False)  # fmt: skip
        transfer = ct.ss(-system, inputs=["w"], outputs=["v"], name=f"L_{cut}")
        transfers[cut] = transfer
        rows.append(margins_row(("input", cut, cut), transfer))
    return pd.DataFrame(rows), transfers


def law_gains(controller: ControllerInstance, plant: Plant) -> pd.DataFrame:
    """The law's linear gains (eq. 1): per driven input, d u / d (each measure, reference and
    state), in columns ``input``, ``of``, ``gain``. An LQR's are -K and -K_i."""
    import pandas as pd

    shape = controller.law.shape
    linear = law_system(controller, plant, 1.0)
    driven = [plant.input_names[int(i)] for i in controller.cp[shape.n_y : shape.n_y + shape.n_u]]
    names = [*linear.input_labels]
    rows = []
    for name in driven:
        i = plant.input_names.index(name)
        rows += [{"input": name, "of": of, "gain": float(linear.D[i, k])} for k, of in enumerate(names)]
        rows += [{"input": name, "of": of, "gain": float(linear.C[i, k])} for k, of in enumerate(linear.state_labels)]
    return pd.DataFrame(rows, columns=["input", "of", "gain"])

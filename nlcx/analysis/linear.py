"""The linear models of a frozen-gain analysis, as named python-control state-space systems.

- the plant linearised about its operating point (:func:`plant_system`, by the one
  linearisation of :func:`nlcx.plants.base.linearize`);
- each frozen loop as a system from (its reference, its output) to its contribution
  (:func:`loop_system`), the loops summed per plant input (:func:`controller_system`);
- the closed loop from the references to the outputs and inputs (:func:`closed_loop_system`);
- the loop transfer broken at the plant input (:func:`loop_transfer`), either where one loop's
  contribution enters its input (the other loops closed) or at an input with every loop on it;
- the tables: closed-loop poles (:func:`poles_table`) and margins (:func:`margins_table`).

Signal names follow the plant's: the outputs and inputs by name, the references ``<output>_ref``
(as timeseries.csv names them), a loop's contribution ``u_<loop>``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import control as ct
import numpy as np

from nlcx.analysis.frozen import FrozenLoop
from nlcx.plants.base import Plant, linearize

if TYPE_CHECKING:
    import pandas as pd

#: Where a loop is broken: ("loop", its name, its input) or ("input", the input, the input).
Opening = tuple[str, str, str]
#: Columns of the poles table.
POLE_COLUMNS = ("real", "imag", "zeta", "omega_n")
#: Columns of the margins table: where the loop is broken, then python-control's
#: ``stability_margins`` (gain margin as a ratio, phase margin in degrees, the frequencies in
#: rad per unit of the model's time) and the loop transfer's poles in the right half-plane.
MARGIN_COLUMNS = (
    "opening", "name", "input", "gain_margin", "gain_margin_frequency", "phase_margin", "phase_margin_frequency",
    "stability_margin", "stability_margin_frequency", "rhp_poles",
)  # fmt: skip
#: A pole whose real part exceeds this share of the spectral radius (at least 1) counts as in
#: the right half-plane: a pole the rounding moved off 0 does not.
RHP_TOLERANCE = 1e-9


def reference_name(output: str) -> str:
    """The closed loop's input that sets ``output``'s reference."""
    return f"{output}_ref"


def plant_system(plant: Plant) -> ct.StateSpace:
    """The plant linearised about its operating point and the input that holds it
    (:func:`nlcx.plants.base.linearize`, steps relative to each coordinate's size): dx/dt =
    A x + B u, y = C x in deviations from that point."""
    A, B, C = linearize(plant, relative=True)
    D = np.zeros((C.shape[0], B.shape[1]))
    return ct.ss(
        A, B, C, D, states=plant.state_names, inputs=plant.input_names, outputs=plant.output_names, name="plant"
    )


def loop_system(loop: FrozenLoop) -> ct.StateSpace:
    """Loop ``loop`` as a system from (r, y) of its output to its contribution ``u_<loop>``:
    an integral state where k_i is not 0, a derivative-filter state where k_d is not 0
    (z' = N (w - z), the derivative N (w - z) = N s/(s + N) w of w = r - y, or of -y when it
    differentiates the measurement), all in the loop's units (times its scale)."""
    gain = loop.sign * loop.scale
    d_ref = 0.0 if loop.on_measurement else 1.0
    b: list[list[float]] = []
    c: list[float] = []
    states = []
    if loop.ki != 0.0:
        b.append([1.0, -1.0])
        c.append(gain * loop.ki)
        states.append("integral")
    if loop.kd != 0.0:
        b.append([loop.N * d_ref, -loop.N])
        c.append(-gain * loop.kd * loop.N)
        states.append("derivative")
    n = len(states)
    A = np.zeros((n, n))
    if loop.kd != 0.0:
        A[n - 1, n - 1] = -loop.N
    B = np.array(b, dtype=float).reshape(n, 2)
    C = np.array(c, dtype=float).reshape(1, n)
    derivative = loop.kd * loop.N
    D = gain * np.array([[loop.kp * loop.setpoint_weight + derivative * d_ref, -(loop.kp + derivative)]])
    return ct.ss(
        A, B, C, D, states=states, inputs=[reference_name(loop.output), loop.output],
        outputs=[contribution(loop)], name=f"pid_{loop.name}",
    )  # fmt: skip


def contribution(loop: FrozenLoop) -> str:
    """The signal name of a loop's contribution to its input."""
    return f"u_{loop.name}"


def _junctions(loops: Sequence[FrozenLoop], inputs: Sequence[str], broken: str | None) -> list[ct.StateSpace]:
    """Per input driven by a loop, the summing junction of its loops' contributions; where an
    input is ``broken`` (a loop's contribution or an input's name), the open end ``w`` takes
    its place."""
    junctions = []
    for name in inputs:
        summed = [contribution(loop) for loop in loops if loop.input == name]
        if not summed:
            continue
        if broken == name:
            summed = ["w"]
        elif broken in summed:
            summed = ["w", *(s for s in summed if s != broken)]
        junctions.append(ct.summing_junction(inputs=summed, output=name, name=f"sum_{name}"))
    return junctions


def controller_system(loops: Sequence[FrozenLoop], outputs: Sequence[str], inputs: Sequence[str]) -> ct.StateSpace:
    """The frozen PID: from the references and the outputs to the plant's inputs (each the
    sum of its loops' contributions; an input no loop drives is 0)."""
    refs = [reference_name(y) for y in outputs]
    systems = [*(loop_system(loop) for loop in loops), *_junctions(loops, inputs, None)]
    driven = [name for name in inputs if any(loop.input == name for loop in loops)]
    summed = ct.interconnect(systems, inplist=[*refs, *outputs], outlist=driven, check_unused=False)
    gains = np.zeros((len(inputs), len(driven)))
    for k, name in enumerate(driven):
        gains[inputs.index(name), k] = 1.0
    selector = ct.ss(np.zeros((0, 0)), np.zeros((0, len(driven))), np.zeros((len(inputs), 0)), gains)
    return ct.ss(
        selector * summed, inputs=[*refs, *outputs], outputs=list(inputs), states=summed.state_labels,
        name="controller",
    )  # fmt: skip


def closed_loop_system(plant: ct.StateSpace, controller: ct.StateSpace) -> ct.StateSpace:
    """The closed loop from the references to the plant's outputs and inputs."""
    refs = [reference_name(y) for y in plant.output_labels]
    outputs = [*plant.output_labels, *plant.input_labels]
    loop = ct.interconnect([plant, controller], inplist=refs, outlist=outputs, check_unused=False)
    return ct.ss(loop, inputs=refs, outputs=outputs, states=loop.state_labels, name="closed_loop")


def loop_transfer(plant: ct.StateSpace, loops: Sequence[FrozenLoop], opening: Opening) -> ct.StateSpace:
    """The loop transfer L(s) broken at the plant input, references at 0, in python-control's
    negative-feedback convention (the loop is closed by w = -L w). ``opening`` (see
    :func:`openings`): a loop (its contribution is cut where it enters its input, the other
    loops closed) or an input (every loop on it cut there)."""
    kind, name, _ = opening
    opened = [loop for loop in loops if (loop.name if kind == "loop" else loop.input) == name]
    cut = contribution(opened[0]) if kind == "loop" else name
    junctions = _junctions(loops, plant.input_labels, cut)
    returned = ct.summing_junction(inputs=[contribution(loop) for loop in opened], output="v", name="returned")
    systems = [plant, *(loop_system(loop) for loop in loops), *junctions, returned]
    system = ct.interconnect(systems, inplist=["w"], outlist=["v"], check_unused=False)
    return ct.ss(-system, inputs=["w"], outputs=["v"], name=f"L_{name}")


def openings(loops: Sequence[FrozenLoop]) -> list[Opening]:
    """(opening, name, input) of each place the loop is broken: every loop, then every input
    that several loops drive."""
    found = [("loop", loop.name, loop.input) for loop in loops]
    inputs = [loop.input for loop in loops]
    shared = [name for name in dict.fromkeys(inputs) if inputs.count(name) > 1]
    return found + [("input", name, name) for name in shared]


def _tolerance(poles: np.ndarray) -> float:
    """How far from the imaginary axis a pole counts as on it: :data:`RHP_TOLERANCE` times the
    spectral radius (at least 1)."""
    return RHP_TOLERANCE * max(1.0, float(np.max(np.abs(poles)))) if poles.size else RHP_TOLERANCE


def poles_table(system: ct.StateSpace) -> pd.DataFrame:
    """The poles of ``system``, the rightmost first: real, imag, damping ratio zeta = -real/|p|
    and natural frequency omega_n = |p|. zeta is undefined (NaN) for a pole at 0, one within
    :func:`_tolerance` of it included (a mode the rounding moved off 0)."""
    import pandas as pd

    poles = np.sort_complex(np.linalg.eigvals(system.A))[::-1] if system.nstates else np.zeros(0, complex)
    omega = np.abs(poles)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where(omega > _tolerance(poles), -poles.real / omega, np.nan)
    return pd.DataFrame({"real": poles.real, "imag": poles.imag, "zeta": zeta, "omega_n": omega})


def pole_counts(poles: pd.DataFrame) -> tuple[int, int]:
    """(poles in the open right half-plane, poles on the imaginary axis) of a poles table, a
    pole within :func:`_tolerance` of the axis counting as on it."""
    values = poles.real.to_numpy() + 1j * poles.imag.to_numpy()
    tolerance = _tolerance(values)
    return int(np.sum(values.real > tolerance)), int(np.sum(np.abs(values.real) <= tolerance))


#: A direction whose plant part is below this share of it lies along the controller's states.
STRUCTURAL_TOLERANCE = 1e-6


def structural_poles(system: ct.StateSpace) -> list[tuple[str, complex]]:
    """The structural poles at 0 of a closed loop: (the state each lies along, the pole).

    A null vector v of A (A v = 0, within rounding of its largest singular value) without a
    component on the plant's states (labels ``plant_...``) is a mode of the controller's
    states that nothing moves and that moves nothing: an integrator redundant with another
    on the same input, whose difference no output sees. Each such direction is named by the
    controller state with its largest component (its label without ``controller_``); its
    pole is one of the poles nearest 0, in that order."""
    if not system.nstates:
        return []
    A = np.asarray(system.A, dtype=float)
    labels = list(system.state_labels)
    plant = [i for i, name in enumerate(labels) if name.startswith("plant_")]
    _, singular, vt = np.linalg.svd(A)
    null = vt[singular <= RHP_TOLERANCE * max(1.0, float(singular[0]))].T  # n x k, orthonormal
    if not null.shape[1]:
        return []
    # the combinations of the null space without a plant component: the null space of its plant rows
    _, s_plant, vt_plant = np.linalg.svd(null[plant, :]) if plant else (None, np.zeros(0), np.eye(null.shape[1]))
    rank = int(np.sum(s_plant > STRUCTURAL_TOLERANCE))
    directions = null @ vt_plant[rank:].T
    poles = np.linalg.eigvals(A)
    nearest = poles[np.argsort(np.abs(poles), kind="stable")]
    found = []
    for k in range(directions.shape[1]):
        state = labels[int(np.argmax(np.abs(directions[:, k])))]
        found.append((state.removeprefix("controller_"), complex(nearest[k])))
    return found


def rhp_poles(system: ct.StateSpace) -> int:
    """The number of poles of ``system`` in the open right half-plane (see :func:`pole_counts`)."""
    if not system.nstates:
        return 0
    poles = np.linalg.eigvals(system.A)
    return int(np.sum(poles.real > _tolerance(poles)))


def margins_row(opening: Opening, transfer: ct.StateSpace) -> dict[str, object]:
    """One row of the margins table: python-control's ``stability_margins`` of ``transfer``
    (gain margin inf and its frequency NaN where the phase never crosses -180 degrees; likewise
    the phase margin where the gain never crosses 1)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        gm, pm, sm, wpc, wgc, wms = ct.stability_margins(transfer)
    kind, name, input_name = opening
    values = (gm, wpc, pm, wgc, sm, wms)
    numbers = dict(zip(MARGIN_COLUMNS[3:9], (float(v) for v in values), strict=True))
    return {"opening": kind, "name": name, "input": input_name, **numbers, "rhp_poles": rhp_poles(transfer)}


def margins_table(plant: ct.StateSpace, loops: Sequence[FrozenLoop]) -> tuple[pd.DataFrame, dict[str, ct.StateSpace]]:
    """The margins of the loop broken at each opening (:func:`openings`) and the loop
    transfers by the opening's name: a loop's, or an input's (``input <name>`` where a loop
    bears the same name)."""
    import pandas as pd

    transfers = {}
    rows = []
    for opening in openings(loops):
        kind, name, _ = opening
        transfer = loop_transfer(plant, loops, opening)
        transfers[f"input {name}" if kind == "input" and name in transfers else name] = transfer
        rows.append(margins_row(opening, transfer))
    return pd.DataFrame(rows, columns=list(MARGIN_COLUMNS)), transfers

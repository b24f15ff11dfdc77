"""The metric plan: which signals of each loop are measured, how, and the order of their rows.

A run's metric rows (metrics.csv) are, for a run that finished, per measured signal in this
order: each output the loop follows (its reference's :class:`~nlcx.references.base.SignalPlan`:
step, regulation or tracking, then the error integrals), each other output after a step on an
input the loop applies (its step characteristics against its own final value, an open-loop
step test), and each input (its effort); for a run that stopped, the time it stopped and a
missing settling time per followed output. :class:`MetricPlan` says this once per experiment
and loop: the kernel each signal is measured with (:func:`nlcx.metrics.kernels.measure`), where
its samples and its reference are, where its step falls on the time grid, and the names, units
and notes of its rows. The CPU (:mod:`nlcx.engine.measure`, :mod:`nlcx.engine.ensembles`) and
the GPU (:mod:`nlcx.engine.gpu`) read the same plan.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from nlcx.metrics import names
from nlcx.metrics.kernels import EFFORT, INFO, REGULATION, STEP, TRACKING, Timing, timing
from nlcx.references.base import SignalPlan

if TYPE_CHECKING:
    from nlcx.config import MetricsSection
    from nlcx.controllers.base import ControllerInstance
    from nlcx.engine.prepared import Prepared
    from nlcx.plants.base import Plant

#: The metric names a kernel writes, by kind (:data:`nlcx.metrics.kernels.STEP`, ...).
KIND_METRICS: dict[int, tuple[str, ...]] = {
    STEP: names.STEP_METRICS + names.ERROR_METRICS,
    REGULATION: names.REGULATION_METRICS + names.ERROR_METRICS,
    TRACKING: names.ERROR_METRICS,
    INFO: names.STEP_INFO_METRICS,
    EFFORT: names.INPUT_METRICS,
}
#: The note of a metric row whose value is missing (NaN), by metric.
NAN_NOTES = {"settling_time": "did not settle within the run", "rise_time": "did not reach the upper rise level"}
_KINDS = {"step": STEP, "regulation": REGULATION, "tracking": TRACKING}

#: Where a measured signal's samples are: a state x_i (an output whose row of C selects it), an
#: output y_i = C_i x (a combination of states), an input u_i.
Source = tuple[Literal["state", "output", "input"], int]


@dataclass(frozen=True)
class MeasuredSignal:
    """One signal of a loop, measured by one kernel call: its name, the kernel (``kind``),
    where its samples are (``source``), the column of the loop's references it follows
    (``reference``; -1: none), the constant it steps or is held to (``final``), where the step
    falls on the grid (``timing``), and its rows' metric names, units and missing-value notes."""

    signal: str
    kind: int
    source: Source
    reference: int
    final: float
    timing: Timing
    metrics: tuple[str, ...]
    units: tuple[str, ...]

    @property
    def notes(self) -> tuple[str, ...]:
        """The note of each row, where its value is missing."""
        return tuple(NAN_NOTES.get(name, "undefined") for name in self.metrics)


@dataclass(frozen=True)
class LoopPlan:
    """The metric rows of one loop (a controller): its measured signals in row order, and the
    outputs it follows (what the rows of a run that stopped name)."""

    label: str
    signals: tuple[MeasuredSignal, ...]
    followed: tuple[str, ...]

    @property
    def width(self) -> int:
        """The number of metric rows of a run that finished."""
        return sum(len(s.metrics) for s in self.signals)

    def rows(self) -> list[tuple[str, str, str, str]]:
        """(signal, metric, unit, note where missing) of each row of a run that finished."""
        return [(s.signal, *row) for s in self.signals for row in zip(s.metrics, s.units, s.notes, strict=True)]

    def failed_rows(self) -> list[tuple[str, str, str]]:
        """(signal, metric, unit) of each row of a run that stopped."""
        return [("all", "t_fail", "s"), *((s, "settling_time", "s") for s in self.followed)]


@dataclass(frozen=True)
class MetricPlan:
    """The metric rows of an experiment: one :class:`LoopPlan` per loop, in the experiment's
    order of loops, on its time grid ``t``."""

    loops: tuple[LoopPlan, ...]
    t: np.ndarray

    @classmethod
    def of(cls, prepared: Prepared, controllers: list[ControllerInstance]) -> MetricPlan:
        """The plan of ``prepared``'s experiment for the loops of ``controllers``."""
        plans = signal_plans(prepared)
        cfg, t = prepared.experiment.section.metrics, prepared.grid.t
        return cls(tuple(loop_plan(prepared.plant, c, plans, cfg, t) for c in controllers), t)


def signal_plans(prepared: Prepared) -> dict[str, SignalPlan]:
    """How each signal with a reference is measured (its reference's :class:`SignalPlan`)."""
    return {s: ref.model.signal_plan(ref.config) for s, ref in prepared.references.items()}


def followed_outputs(plant: Plant, controller: ControllerInstance) -> tuple[str, ...]:
    """The outputs ``controller`` follows a reference for, in the order it names them."""
    return tuple(s for s in dict.fromkeys(controller.reference_signals) if s in plant.output_names)


def input_step(plant: Plant, controller: ControllerInstance, plans: Mapping[str, SignalPlan]) -> SignalPlan | None:
    """The earliest step on an input the controller applies (an open-loop step test), if any."""
    steps = [plans[s] for s in controller.reference_signals if s in plant.input_names and plans[s].kind == "step"]
    return min(steps, key=lambda plan: plan.t_step) if steps else None


def loop_plan(
    plant: Plant, controller: ControllerInstance, plans: Mapping[str, SignalPlan], cfg: MetricsSection, t: np.ndarray
) -> LoopPlan:
    """The :class:`LoopPlan` of ``controller`` on ``plant`` (the module docstring's order)."""
    followed = followed_outputs(plant, controller)
    signals = []
    for s in followed:
        plan = plans[s]
        column = controller.reference_signals.index(s)
        at = _timing(t, plan.t_step, cfg)
        signals.append(_measured(plant, s, _KINDS[plan.kind], _output(plant, s), column, plan.final, at))
    step = input_step(plant, controller, plans)
    if step is not None:
        at = _timing(t, step.t_step, cfg)
        signals += [_measured(plant, s, INFO, _output(plant, s), -1, 0.0, at)
                    for s in plant.output_names if s not in followed]  # fmt: skip
    at = timing(t, 0.0)
    signals += [_measured(plant, s, EFFORT, ("input", j), -1, 0.0, at) for j, s in enumerate(plant.input_names)]
    return LoopPlan(controller.label, tuple(signals), followed)


def _timing(t: np.ndarray, t_step: float, cfg: MetricsSection) -> Timing:
    """Where a step at ``t_step`` falls on ``t``, with the settings of ``metrics:`` (event times
    measured from the step or from the start of the run, ``metrics.time_origin``)."""
    origin = 0.0 if cfg.time_origin == "start" else t_step
    return timing(
        t, t_step, origin=origin, band=cfg.settling_band, rise_limits=cfg.rise_limits, window=cfg.ss_window,
        abs_tol=cfg.regulation_abs_tol,
    )  # fmt: skip


def _measured(
    plant: Plant, signal: str, kind: int, source: Source, reference: int, final: float, at: Timing
) -> MeasuredSignal:
    """The :class:`MeasuredSignal` of ``signal`` measured by kernel ``kind``."""
    metrics = KIND_METRICS[kind]
    unit = plant.unit_of(signal)
    units = tuple(metric_unit(name, unit) for name in metrics)
    return MeasuredSignal(signal, kind, source, reference, float(final), at, metrics, units)


def _output(plant: Plant, signal: str) -> Source:
    """Where output ``signal``'s samples are: the state its row of C selects, else the output."""
    j = plant.output_names.index(signal)
    state = selected_state(plant.C[j])
    return ("state", state) if state is not None else ("output", j)


def selected_state(c_row: np.ndarray) -> int | None:
    """The state a row of C selects (one entry 1, the others 0), or None (a combination)."""
    (nonzero,) = np.nonzero(c_row)
    return int(nonzero[0]) if nonzero.size == 1 and c_row[nonzero[0]] == 1.0 else None


def metric_unit(name: str, signal_unit: str) -> str:
    """The unit of metric ``name`` of a signal in ``signal_unit`` (the templates of
    :data:`nlcx.metrics.names.METRIC_UNITS`: ``signal``, ``input`` stand for the signal's unit)."""
    template = names.METRIC_UNITS.get(name) or names.STEP_INFO_UNITS.get(name, "")
    return template.replace("signal", signal_unit or "1").replace("input", signal_unit or "1")

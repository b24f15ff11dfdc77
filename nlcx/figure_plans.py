"""A run's figures as plans (:class:`nlcx.drawing.FigurePlan`): which lines, labels and axes.

:func:`output_plan` gives one panel per regulated output, every controller overlaid and the
reference dotted (the thesis's layout), then with ``outputs.figure_inputs`` one panel per
input; :func:`gains_plan` the plant inputs and every logged controller quantity against time.
Each curve is thinned to the min and max of its buckets (:func:`thinned`), so chattering and
spikes keep their envelope, and a diverging run's values are dropped (:func:`finite_for_plot`).
A plan holds numbers and strings only; :mod:`nlcx.drawing` draws it, here or in a painter
process, and :func:`nlcx.report.write_run` writes the figures of a run directory.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from nlcx.drawing import FigurePlan, Line, Panel, draw

if TYPE_CHECKING:  # matplotlib is imported by the commands that draw
    from matplotlib.figure import Figure

    from nlcx.engine import ExperimentResult, Run
    from nlcx.plants.base import Signal

#: The colour and line style of each run's curve, by its position (repeating after six).
LINE_STYLES = (("C0", "-"), ("C3", "--"), ("C2", "-."), ("C1", ":"), ("C4", "-"), ("C5", "--"))


def thinned(t: np.ndarray, y: np.ndarray, points: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """At most ~2 ``points`` samples for drawing: the min and max of each bucket, in time order,
    so chattering and spikes keep their envelope (a figure is a few hundred pixels wide)."""
    n = t.size
    if n <= 2 * points:
        return t, y
    size = -(-n // points)
    m = (n // size) * size
    tb, yb = t[:m].reshape(-1, size), y[:m].reshape(-1, size)
    with np.errstate(invalid="ignore"):
        lo = np.nanargmin(np.where(np.isnan(yb), np.inf, yb), axis=1)
        hi = np.nanargmax(np.where(np.isnan(yb), -np.inf, yb), axis=1)
    first, second = np.minimum(lo, hi), np.maximum(lo, hi)
    rows = np.arange(tb.shape[0])
    tt = np.column_stack([tb[rows, first], tb[rows, second]]).ravel()
    yy = np.column_stack([yb[rows, first], yb[rows, second]]).ravel()
    return np.concatenate([tt, t[m:]]), np.concatenate([yy, y[m:]])


def finite_for_plot(values: np.ndarray, limit: float = 1e9) -> np.ndarray:
    """Values beyond ``limit`` (a diverging run) as NaN, so an axis can still be drawn."""
    return np.where(np.abs(values) < limit, values, np.nan)


def line_style(i: int) -> tuple[str, str]:
    """(colour, line style) of the ``i``-th controller of a figure, :data:`LINE_STYLES` in turn."""
    return LINE_STYLES[i % len(LINE_STYLES)]


def _run_label(run: Run, result: ExperimentResult | None = None) -> str:
    """The legend entry: the controller, its status if not ok, and the requested metrics."""
    if run.status != "ok":
        return f"{run.label} ({run.status})"
    if result is None:
        return run.label
    names = result.prepared.experiment.section.outputs.figure_metrics
    if not names:
        return run.label
    rows = [row for row in result.metric_rows if row[0] == run.label]
    parts = []
    for name in names:
        parts += [f"{name} {row[3]:.4g}" for row in rows if row[2] == name]
    return f"{run.label} ({', '.join(parts)})" if parts else run.label


def _lines(run_values: list[tuple[Run, np.ndarray | None, str]], lw: float) -> tuple[Line, ...]:
    """The curves of a panel, one per (run, values, legend entry) with values, in the style of
    the run's position."""
    out = []
    for i, (run, values, label) in enumerate(run_values):
        if values is not None:
            color, ls = line_style(i)
            out.append(Line(*thinned(run.t, finite_for_plot(values)), color=color, ls=ls, lw=lw, label=label))
    return tuple(out)


def output_plan(result: ExperimentResult, title: str | None = None) -> FigurePlan:
    """One panel per regulated output, every controller overlaid, reference dotted (thesis
    layout); then, with ``outputs.figure_inputs``, one panel per input."""
    plant = result.prepared.plant
    outputs = plant.outputs
    inputs = plant.inputs if result.prepared.experiment.section.outputs.figure_inputs else ()
    legends = [_run_label(run, result) for run in result.runs]  # the same on every output's panel
    panels = []
    for k, sig in enumerate(outputs):
        j = plant.output_names.index(sig.name)
        runs = zip(result.runs, legends, strict=True)
        lines = _lines([(run, run.x @ plant.C[j], legend) for run, legend in runs], lw=1.3)
        first = result.runs[0]
        if sig.name in first.controller.reference_signals:
            col = first.controller.reference_signals.index(sig.name)
            lines += (Line(*thinned(first.t, first.r[:, col]), color="k", ls=":", lw=1.0, label="reference"),)
        panels.append(_time_panel(lines, k, sig))
    for j, sig in enumerate(inputs):
        lines = _lines([(run, run.u[:, j], _run_label(run)) for run in result.runs], lw=1.3)
        panels.append(_time_panel(lines, len(outputs) + j, sig))
    n_axes = len(panels)
    return FigurePlan(n_axes, 1, (7.5, 2.9 * n_axes), tuple(panels), title=title or None, layout="column")


def _time_panel(lines: tuple[Line, ...], k: int, sig: Signal) -> Panel:
    """Panel (a), (b), ... of a signal against time."""
    return Panel(
        lines, f"({chr(ord('a') + k)}) {sig.label or sig.name} vs time", xlabel="Time (s)", ylabel=sig.axis_label,
        legend_size=8,
    )  # fmt: skip


def output_figure(result: ExperimentResult, title: str | None = None) -> Figure:
    """The figure of :func:`output_plan`."""
    return draw(output_plan(result, title))


def gains_plan(result: ExperimentResult) -> FigurePlan:
    """Plant inputs and every logged controller quantity (gains, loop outputs) against time."""
    plant = result.prepared.plant
    names: list[str] = list(plant.input_names)
    for run in result.runs:
        names += [n for n in run.controller.log_names if n not in names]
    n_cols = 4 if len(names) > 4 else len(names)
    n_rows = -(-len(names) // n_cols)
    panels = []
    for k, name in enumerate(names):
        run_values: list[tuple[Run, np.ndarray | None, str]] = []
        unit = ""
        for run in result.runs:
            values = None
            if name in plant.input_names:
                values, unit = run.u[:, plant.input_names.index(name)], plant.unit_of(name)
            elif name in run.controller.log_names and run.log is not None:
                i = run.controller.log_names.index(name)
                values, unit = run.log[:, i], run.controller.log_units[i]
            run_values.append((run, values, run.label))
        lowest = k + n_cols >= len(names)  # no panel below it in its column: the time label
        panels.append(Panel(
            _lines(run_values, lw=1.0), f"{name} ({unit})" if unit else name, xlabel="Time (s)" if lowest else "",
            title_size=9, tick_size=7, legend_size=7 if k == 0 else None,
        ))  # fmt: skip
    return FigurePlan(n_rows, n_cols, (3.2 * n_cols, 2.3 * n_rows), tuple(panels), layout="tight")

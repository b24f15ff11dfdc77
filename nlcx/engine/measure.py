"""Measuring runs: the long-form metric rows of every run, computed together.

The runs of experiments with the same plant signals and metric definitions are measured in
one table (:func:`measure_experiments`), vectorised over the runs that share a metric plan
(:mod:`nlcx.metrics`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Protocol, cast

import numpy as np

from nlcx import metrics as m
from nlcx.config import MetricsSection
from nlcx.controllers.base import ControllerInstance
from nlcx.engine.prepared import Prepared
from nlcx.engine.results import MetricBlock, MetricTable, Run
from nlcx.plants.base import Plant
from nlcx.references.base import MetricPlan


def _unit(template: str, signal_unit: str) -> str:
    """A metric's unit from its template (``signal``, ``input``: the signal's unit)."""
    return template.replace("signal", signal_unit or "1").replace("input", signal_unit or "1")


def _time_origin(t_step: float, cfg: MetricsSection) -> float:
    """The time the event times of a step at ``t_step`` are measured from (``metrics.time_origin``):
    the step itself, or the start of the run."""
    return 0.0 if cfg.time_origin == "start" else t_step


def _signal_metrics(
    t: np.ndarray, y: np.ndarray, r: np.ndarray, plan: MetricPlan, cfg: MetricsSection
) -> dict[str, Any]:
    values: dict[str, Any] = {}
    if plan.kind == "step":
        step = m.step_response_metrics(
            t,
            y,
            t_step=plan.t_step,
            final=plan.final,
            band=cfg.settling_band,
            rise_limits=cfg.rise_limits,
            ss_window=cfg.ss_window,
        )
        values.update(m.measured_from(step, plan.t_step, _time_origin(plan.t_step, cfg)))
    elif plan.kind == "regulation":
        values.update(
            m.regulation_metrics(
                t,
                y,
                reference=plan.final,
                band=cfg.settling_band,
                abs_tol=cfg.regulation_abs_tol,
                ss_window=cfg.ss_window,
            )
        )
    values.update(m.error_integrals(t, r - y, t0=plan.t_step))
    return values


_NAN_NOTES = {
    "settling_time": "did not settle within the run",
    "rise_time": "did not reach the upper rise level",
}


def _selected_state(c_row: np.ndarray) -> int | None:
    """The state a row of C selects (one entry 1, the others 0), or None (a combination)."""
    (nonzero,) = np.nonzero(c_row)
    return int(nonzero[0]) if nonzero.size == 1 and c_row[nonzero[0]] == 1.0 else None


def _outputs(xs: list[np.ndarray], c_row: np.ndarray) -> np.ndarray:
    """y = x c for each state trajectory x, stacked (B, T); a row of C that selects one state
    (the usual case) is a gather, not a product."""
    state = _selected_state(c_row)
    if state is not None:
        return np.stack([x[:, state] for x in xs])
    return np.stack([x @ c_row for x in xs])


def _reference_rows(columns: list[np.ndarray]) -> np.ndarray:
    """The references of runs as rows (B, T); one row (T,), broadcast, when every run reads the
    same samples (the variants of a sweep share their reference array)."""
    first = columns[0]
    key = (first.__array_interface__["data"][0], first.shape, first.strides)
    if all((c.__array_interface__["data"][0], c.shape, c.strides) == key for c in columns[1:]):
        return first
    return np.stack(columns)


def _blocks(members: list[int], n_samples: int) -> list[list[int]]:
    """``members`` in blocks of :func:`nlcx.metrics.rows_per_block` runs: the rows gathered for
    the metric functions (outputs, errors, inputs) are formed a block at a time, in memory
    that stays in cache (forming them for a whole batch at once costs more than the metrics
    themselves). Each row's metrics are the same whatever the block it is in."""
    size = m.rows_per_block(n_samples)
    return [members[k : k + size] for k in range(0, len(members), size)]


def _per_run(
    batch: Mapping[str, np.ndarray], members: list[int], signal: str
) -> dict[tuple[int, str], dict[str, float]]:
    """A metric function's batched result (name -> value per row) split by run: (run, signal)
    -> {name: value}, row k being run ``members[k]``."""
    return {(i, signal): {name: float(v[k]) for name, v in batch.items()} for k, i in enumerate(members)}


class Controlled(Protocol):
    """What the helpers below read of a run: its controller (a :class:`Run`, or an ensemble's loop)."""

    @property
    def controller(self) -> ControllerInstance: ...


def _measured_outputs(run: Controlled, plant: Plant) -> list[str]:
    """Outputs of ``run`` that follow a reference (measured against it)."""
    return [s for s in dict.fromkeys(run.controller.reference_signals) if s in plant.output_names]


def _input_step(run: Controlled, plant: Plant, plans: dict[str, MetricPlan]) -> MetricPlan | None:
    """The earliest step on an input the controller applies (an open-loop step test), if any."""
    steps = [plans[s] for s in run.controller.reference_signals if s in plant.input_names and plans[s].kind == "step"]
    return min(steps, key=lambda plan: plan.t_step) if steps else None


def _tracking_values(
    plant: Plant, runs: list[Run], plans: list[dict[str, MetricPlan]], ok: list[int], cfg: MetricsSection
) -> dict[tuple[int, str], dict[str, float]]:
    """Metrics of each output that follows a reference, batched over runs sharing its plan."""
    groups: dict[tuple[str, MetricPlan, int], list[int]] = {}
    for i in ok:
        for s in _measured_outputs(runs[i], plant):
            groups.setdefault((s, plans[i][s], runs[i].t.size), []).append(i)
    values: dict[tuple[int, str], dict[str, float]] = {}
    for (s, plan, n_samples), group in groups.items():
        j = plant.output_names.index(s)
        for members in _blocks(group, n_samples):
            y = _outputs([runs[i].x for i in members], plant.C[j])
            r = _reference_rows([runs[i].r[:, runs[i].controller.reference_signals.index(s)] for i in members])
            batch = _signal_metrics(runs[members[0]].t, y, r, plan, cfg)
            values.update(_per_run(batch, members, s))
    return values


def _step_characteristics(t: np.ndarray, y: np.ndarray, t_step: float, cfg: MetricsSection) -> m.MetricDict:
    """:func:`nlcx.metrics.step_info` of the rows ``y`` after a step at ``t_step``, its event
    times measured from ``cfg.time_origin``: (B,) arrays."""
    info = m.step_info(t, y, t_step=t_step, settling_band=cfg.settling_band, rise_limits=cfg.rise_limits)
    return m.measured_from(cast(m.MetricDict, info), t_step, _time_origin(t_step, cfg))


def _open_loop_values(
    plant: Plant, runs: list[Run], plans: list[dict[str, MetricPlan]], ok: list[int], cfg: MetricsSection
) -> dict[tuple[int, str], dict[str, float]]:
    """Step characteristics (:func:`nlcx.metrics.step_info`, MATLAB's ``stepinfo``) of every
    output not following a reference, after a step on an input, against its own final value."""
    groups: dict[tuple[str, float, int], list[int]] = {}
    for i in ok:
        step = _input_step(runs[i], plant, plans[i])
        if step is None:
            continue
        followed = _measured_outputs(runs[i], plant)
        for s in plant.output_names:
            if s not in followed:
                groups.setdefault((s, step.t_step, runs[i].t.size), []).append(i)
    values: dict[tuple[int, str], dict[str, float]] = {}
    for (s, t_step, n_samples), group in groups.items():
        for members in _blocks(group, n_samples):
            y = _outputs([runs[i].x for i in members], plant.C[plant.output_names.index(s)])
            values.update(_per_run(_step_characteristics(runs[members[0]].t, y, t_step, cfg), members, s))
    return values


def _input_values(plant: Plant, runs: list[Run], ok: list[int]) -> dict[tuple[int, str], dict[str, float]]:
    """Effort metrics of every input, batched over runs of the same length."""
    by_length: dict[int, list[int]] = {}
    for i in ok:
        by_length.setdefault(runs[i].t.size, []).append(i)
    values: dict[tuple[int, str], dict[str, float]] = {}
    for n_samples, group in by_length.items():
        t = runs[group[0]].t
        for members in _blocks(group, n_samples):
            for j, name in enumerate(plant.input_names):
                batch = m.input_metrics(t, np.stack([runs[i].u[:, j] for i in members]))
                values.update(_per_run(batch, members, name))
    return values


def _metric_unit(name: str, signal_unit: str) -> str:
    """The unit of metric ``name`` of a signal in ``signal_unit``."""
    return _unit(m.METRIC_UNITS.get(name) or m.STEP_INFO_UNITS.get(name, ""), signal_unit)


def measure_runs(
    plant: Plant, runs: list[Run], plans: list[dict[str, MetricPlan]], cfg: MetricsSection
) -> list[list[Any]]:
    """Long-form metric rows of runs on plants with ``plant``'s outputs and inputs.

    Outputs that follow a reference get the step / regulation / tracking metrics of their
    plan; with a step on an input the controller applies (``open_loop``), every other output
    gets its step characteristics against its own final value; every input gets its effort.
    The event times of a step response are measured from its step or from t = 0
    (``cfg.time_origin``). The metrics of runs that completed are computed together,
    vectorised over the runs that share a plan (a sweep measures thousands of runs in a few
    calls). A row is the position of its run in ``runs``, then the values of
    :data:`METRIC_COLUMNS`.
    """
    ok = [i for i, r in enumerate(runs) if r.status == "ok"]
    values = {
        **_tracking_values(plant, runs, plans, ok, cfg),
        **_open_loop_values(plant, runs, plans, ok, cfg),
        **_input_values(plant, runs, ok),
    }
    rows: list[list[Any]] = []
    for i, run in enumerate(runs):
        label = run.label
        if run.status != "ok":
            rows.append([i, label, "all", "t_fail", run.t_fail, "s", run.status, run.reason])
            rows += [
                [i, label, s, "settling_time", math.nan, "s", run.status, run.reason]
                for s in _measured_outputs(run, plant)
            ]
            continue
        followed = _measured_outputs(run, plant)
        others = [s for s in plant.output_names if s not in followed]
        for s in [*followed, *others, *plant.input_names]:
            unit = plant.unit_of(s)
            for name, v in values.get((i, s), {}).items():
                note = _NAN_NOTES.get(name, "undefined") if math.isnan(v) else ""
                rows.append([i, label, s, name, v, _metric_unit(name, unit), "ok", note])
    return rows


def controller_records(run: Run) -> list[dict[str, Any]]:
    """tuning.csv rows a controller reports itself: its records and its logs' final values."""
    c = run.controller
    rows = [{"controller": c.label, "tuner": "controller", "parameter": k, "value": v} for k, v in c.records.items()]
    if run.log is not None:
        rows += [
            {"controller": c.label, "tuner": "controller", "parameter": f"{name}.final",
             "value": float(run.log[-1, c.log_names.index(name)])}
            for name in c.final_logs
        ]  # fmt: skip
    return rows


def _metric_plans(prepared: Prepared) -> dict[str, MetricPlan]:
    """The metric plan of each signal's reference."""
    return {s: ref.model.metric_plan(ref.config) for s, ref in prepared.references.items()}


def measure_experiments(prepared: list[Prepared], runs: list[list[Run]]) -> list[MetricBlock | None]:
    """Metrics of every experiment's runs as a block of a shared table; experiments
    with the same plant signals and metric definitions are measured together (vectorised
    over all their runs). A shared table has the column ``experiment``, the position in
    ``prepared``; each experiment's rows are contiguous."""
    groups: dict[tuple[Any, ...], list[int]] = {}
    for e, p in enumerate(prepared):
        plant = p.plant
        key = (
            plant.name,
            tuple(plant.output_names),
            tuple(plant.input_names),
            p.experiment.section.metrics.model_dump_json(),
        )
        groups.setdefault(key, []).append(e)
    rows: list[MetricBlock | None] = [None] * len(prepared)
    for members in groups.values():
        owner = [e for e in members for _ in runs[e]]
        flat = [r for e in members for r in runs[e]]
        plans = [_metric_plans(prepared[e]) for e in owner]
        first = prepared[members[0]]
        table = MetricTable(measure_runs(first.plant, flat, plans, first.experiment.section.metrics))
        for row in table.rows:
            row[0] = owner[row[0]]  # the run's position in ``flat`` -> its experiment's in ``prepared``
        experiment = [row[0] for row in table.rows]
        bounds = np.searchsorted(experiment, members, side="left"), np.searchsorted(experiment, members, side="right")
        for e, start, stop in zip(members, *bounds, strict=True):
            rows[e] = MetricBlock(table, int(start), int(stop))
    return rows

"""Measuring runs: the long-form metric rows of every run, computed together.

Each experiment's :class:`~nlcx.engine.plan.MetricPlan` says which signals of each loop are
measured and the order of their rows. The runs of experiments that share a loop's plan and
time grid are measured together (:func:`measure_experiments`), one kernel call per measured
signal over all their rows (:func:`signal_values`, :mod:`nlcx.metrics.kernels`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from nlcx.compiled_cache import wait_for_helpers
from nlcx.engine.plan import LoopPlan, MeasuredSignal, MetricPlan
from nlcx.engine.prepared import Prepared
from nlcx.engine.results import MetricBlock, MetricTable, Run
from nlcx.metrics.batch import measure_rows
from nlcx.plants.base import Plant

#: Samples of the rows gathered for one kernel call (outputs from states, references): rows are
#: gathered a block at a time, in memory that stays in cache.
ROWS_ELEMENTS = 1 << 18


def signal_values(
    signal: MeasuredSignal, t: np.ndarray, y: np.ndarray, r: np.ndarray, rows: np.ndarray | None = None
) -> np.ndarray:
    """The metric values (rows, len(signal.metrics)) of ``signal`` measured over the rows
    ``rows`` (default: all) of ``y`` (runs, samples) against the reference rows ``r`` (one
    shared row, or one a row of ``y``).

    The kernel gets its arrays C-contiguous and writable (:func:`compiled_form`), whatever
    they are here (a view of a column of the records, a read-only reference), so that one
    compiled :func:`~nlcx.metrics.batch.measure_rows` serves every call."""
    picked = compiled_form(np.arange(y.shape[0]) if rows is None else rows, np.int64)
    out = np.empty((picked.size, len(signal.metrics)))
    if picked.size:
        reference = compiled_form(r if r.ndim == 2 else r[np.newaxis, :])
        measure_rows(signal.kind, compiled_form(t), compiled_form(y), reference, picked, signal.timing,
                     signal.final, out)  # fmt: skip
    return out


def compiled_form(a: np.ndarray, dtype: type = np.float64) -> np.ndarray:
    """``a`` as the metric kernels are compiled for: a C-contiguous, writable array of ``dtype``
    (``a`` itself if it is one, else a copy). numba types an array by its layout and by whether
    it is writable, and compiles a kernel once for each such type it is called with."""
    if a.dtype == dtype and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, dtype=dtype, order="C")


def source_rows(xs: Sequence[np.ndarray], us: Sequence[np.ndarray], signal: MeasuredSignal, plant: Plant) -> np.ndarray:
    """The samples of ``signal`` in each run (states ``xs`` (T, n), inputs ``us``), stacked (B, T):
    a state or an input gathered, an output y = x C_j formed."""
    where, index = signal.source
    if where == "state":
        return np.stack([x[:, index] for x in xs])
    if where == "input":
        return np.stack([u[:, index] for u in us])
    c_row = plant.C[index]
    return np.stack([x @ c_row for x in xs])


def _reference_rows(columns: list[np.ndarray]) -> np.ndarray:
    """The references of runs as rows (B, T); one row (T,), broadcast, when every run reads the
    same samples (the variants of a sweep share their reference array)."""
    first = columns[0]
    key = (first.__array_interface__["data"][0], first.shape, first.strides)
    if all((c.__array_interface__["data"][0], c.shape, c.strides) == key for c in columns[1:]):
        return first
    return np.stack(columns)


def _row_ranges(n_runs: int, n_samples: int) -> list[range]:
    """The runs 0 .. n_runs-1 in ranges of :data:`ROWS_ELEMENTS` samples' worth of runs."""
    size = max(1, ROWS_ELEMENTS // max(n_samples, 1))
    return [range(k, min(k + size, n_runs)) for k in range(0, n_runs, size)]


def _loop_values(plant: Plant, plan: LoopPlan, runs: list[Run]) -> np.ndarray:
    """The metric values (runs, plan.width) of runs that finished, measured by ``plan``."""
    t = runs[0].t
    values = np.empty((len(runs), plan.width))
    o = 0
    for signal in plan.signals:
        width = len(signal.metrics)
        for rows in _row_ranges(len(runs), t.size):
            chosen = [runs[i] for i in rows]
            y = source_rows([r.x for r in chosen], [r.u for r in chosen], signal, plant)
            ref = y[:1] if signal.reference < 0 else _reference_rows([r.r[:, signal.reference] for r in chosen])
            values[rows.start : rows.stop, o : o + width] = signal_values(signal, t, y, ref)
        o += width
    return values


def _grid_key(t: np.ndarray) -> tuple[int, float, float, float]:
    """What tells nlcx's uniform time grids apart: the number of samples, the first two and the last."""
    return (t.size, float(t[0]), float(t[1]) if t.size > 1 else 0.0, float(t[-1]))


def measure_runs(plant: Plant, runs: list[Run], plans: list[LoopPlan]) -> list[list[Any]]:
    """Long-form metric rows of runs on plants with ``plant``'s outputs and inputs, run i
    measured by ``plans[i]`` (:class:`~nlcx.engine.plan.LoopPlan`, on the run's grid).

    The runs that finished and share a plan and a grid are measured together, one kernel call
    per measured signal; a run that stopped gets the time it stopped and a missing settling
    time per followed output. A row is the position of its run in ``runs``, then the values of
    :data:`~nlcx.engine.results.METRIC_COLUMNS`.
    """
    groups: dict[tuple[LoopPlan, tuple[int, float, float, float]], list[int]] = {}
    for i, run in enumerate(runs):
        if run.status == "ok":
            groups.setdefault((plans[i], _grid_key(run.t)), []).append(i)
    values: dict[int, np.ndarray] = {}
    for (plan, _), members in groups.items():
        for i, row in zip(members, _loop_values(plant, plan, [runs[i] for i in members]), strict=True):
            values[i] = row
    rows: list[list[Any]] = []
    for i, run in enumerate(runs):
        label = run.label
        if run.status != "ok":
            rows += [[i, label, s, name, run.t_fail if name == "t_fail" else math.nan, unit, run.status, run.reason]
                     for s, name, unit in plans[i].failed_rows()]  # fmt: skip
            continue
        for (s, name, unit, missing), v in zip(plans[i].rows(), values[i].tolist(), strict=True):
            rows.append([i, label, s, name, v, unit, "ok", missing if math.isnan(v) else ""])
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


def _group_key(p: Prepared) -> tuple[Any, ...]:
    """What experiments measured in one table share: the plant's signals and the metric definitions."""
    plant = p.plant
    return (plant.name, tuple(plant.output_names), tuple(plant.input_names),
            p.experiment.section.metrics.model_dump_json())  # fmt: skip


def measure_experiments(prepared: list[Prepared], runs: list[list[Run]]) -> list[MetricBlock | None]:
    """Metrics of every experiment's runs as a block of a shared table; experiments
    with the same plant signals and metric definitions are measured together (vectorised
    over all their runs). A shared table has the column ``experiment``, the position in
    ``prepared``; each experiment's rows are contiguous.

    A process whose numba cache was empty compiles the metric functions in its helper
    (:class:`nlcx.compiled_cache.CompileHelper`, ``nlcx run``): it waits for the helper first
    (:func:`nlcx.compiled_cache.wait_for_helpers`) and then loads them."""
    wait_for_helpers()
    groups: dict[tuple[Any, ...], list[int]] = {}
    for e, p in enumerate(prepared):
        groups.setdefault(_group_key(p), []).append(e)
    rows: list[MetricBlock | None] = [None] * len(prepared)
    for members in groups.values():
        owner = [e for e in members for _ in runs[e]]
        flat = [r for e in members for r in runs[e]]
        plans = [loop for e in members for loop in MetricPlan.of(prepared[e], [r.controller for r in runs[e]]).loops]
        table = MetricTable(measure_runs(prepared[members[0]].plant, flat, plans))
        for row in table.rows:
            row[0] = owner[row[0]]  # the run's position in ``flat`` -> its experiment's in ``prepared``
        experiment = [row[0] for row in table.rows]
        bounds = np.searchsorted(experiment, members, side="left"), np.searchsorted(experiment, members, side="right")
        for e, start, stop in zip(members, *bounds, strict=True):
            rows[e] = MetricBlock(table, int(start), int(stop))
    return rows

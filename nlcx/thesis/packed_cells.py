"""A GA population's table cells from columnar ensembles: each table prepared once per hypothesis.

The identification's objective (:class:`nlcx.thesis.fitting.Objective`) measures every
candidate of a generation on the train tables. Built candidate by candidate, each of those
experiments is a config to compose, validate and prepare, which costs more than simulating it.
The candidates of one hypothesis differ only in the free values (the conventional gains, a
freed parameter), so, as a columnar sweep does (:mod:`nlcx.sweeps.columnar`), each table's
experiment is prepared once (:func:`packed_table`), each free value's place in its arrays is
found by probing it at the ends of its range (``nlcx.engine.ensembles.changed_positions``), and a
population is packed straight into those arrays (:func:`packed_cells`): the same kernel calls on
the same arrays as the candidates' own experiments, so the same cells bit for bit. With
``simulation.device: cuda`` the population is simulated and measured on the GPU
(:func:`nlcx.engine.gpu.simulate_measure`).

A table whose free values do not land in its arrays as themselves (a value that changes a
structure, or enters transformed) is not packed: :func:`packed_table` says why, and the
objective builds that table's experiments candidate by candidate.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from nlcx import engine
from nlcx.engine.ensembles import Slot, Template
from nlcx.engine.gpu import Ensemble, ensemble_metrics, ensembles_metrics
from nlcx.engine.metric_rows import MetricColumns
from nlcx.errors import NlcxError
from nlcx.thesis.tables import ANGLE_METRICS, ANGLES, POSITION_METRICS

if TYPE_CHECKING:
    from nlcx.config import Experiment
    from nlcx.thesis.hypotheses import Hypothesis

#: Each free value's range, by its config key.
Box = dict[str, tuple[float, float]]


@dataclass(frozen=True)
class PackedTable:
    """A table's experiment prepared for a hypothesis, and where each free value lands in it."""

    template: Template
    slots: dict[str, tuple[Slot, ...]]


def packed_table(experiment: Callable[[dict[str, float]], Experiment], box: Box) -> PackedTable | str:
    """The table's :class:`PackedTable` (``experiment(values)``: its experiment with the free
    values ``values``; ``box``: each free value's range), or why its candidates need experiments
    of their own (a text). The template holds the middle of the box; each value is probed at
    both ends of its range, and both corners of the box must equal the template with their
    values written into those places."""
    from nlcx.engine.ensembles import corner_agrees, probed_slots

    def template(values: dict[str, float]) -> Template:
        return Template.of(engine.prepare(experiment(values)))

    middle = {k: (lo + hi) / 2.0 for k, (lo, hi) in box.items()}
    try:
        base = template(middle)
        if base.prepared.tuning:
            return "a controller is tuned"
        slots = probed_slots(base, lambda key, value: template({**middle, key: value}), middle, box)
        if isinstance(slots, str):
            return slots
        for corner in ({k: lo for k, (lo, _) in box.items()}, {k: hi for k, (_, hi) in box.items()}):
            if not corner_agrees(base, template(corner), slots, corner):
                return "the free values act on the loops together, not each as itself"
    except NlcxError as exc:
        return f"a corner of the free values is not valid ({str(exc).splitlines()[0]})"
    return PackedTable(base, slots)


def packings(
    tables: Iterable[str],
    experiment: Callable[[str, Hypothesis, dict[str, float]], Experiment],
    hyp: Hypothesis,
    box: Box,
) -> dict[str, PackedTable | str]:
    """:func:`packed_table` of each table (``experiment(table, hyp, values)``: its experiment)."""

    def of(table: str) -> Callable[[dict[str, float]], Experiment]:
        return lambda values: experiment(table, hyp, values)

    return {table: packed_table(of(table), box) for table in tables}


def population_ensembles(packing: dict[str, PackedTable | str], X: np.ndarray, keys: list[str]) -> dict[str, Ensemble]:
    """The population (rows of X: the free values ``keys``) as an ensemble of each packed table."""
    columns = {key: X[:, k] for k, key in enumerate(keys)}
    return {t: ensemble(p, columns, len(X)) for t, p in packing.items() if not isinstance(p, str)}


def ensemble(packed: PackedTable, columns: dict[str, np.ndarray], n: int) -> Ensemble:
    """``n`` candidates of a packed table (``columns``: each free value's column) as an ensemble."""
    slots = {k: s for k, s in packed.slots.items() if s}
    return Ensemble(packed.template, slots, {k: np.ascontiguousarray(columns[k], dtype=float) for k in slots}, n)


def population_cells(
    packing: dict[str, PackedTable | str], X: np.ndarray, keys: list[str], cells: pd.DataFrame,
    by_candidate: Callable[[list[dict[str, float]], pd.DataFrame], np.ndarray],
    measured_rows: dict[str, MetricColumns] | None = None,
) -> np.ndarray:  # fmt: skip
    """Our value of every cell (rows of ``cells``) for every candidate (rows of X: the free values
    ``keys``): a packed table's from the metric rows of its ensemble (``measured_rows``, by
    table; default: measured here, the GPU's ensembles together), the others' from
    ``by_candidate(candidates, their cells)`` (each candidate's own experiments)."""
    n = len(X)
    if measured_rows is None:
        ensembles = population_ensembles(packing, X, keys)
        measured_rows = dict(zip(ensembles, ensembles_metrics(list(ensembles.values())), strict=True))
    ours = np.full((len(cells), n), math.nan)
    tables = cells.table.to_numpy()
    for table, rows in measured_rows.items():
        mine = tables == table
        ours[mine] = packed_cells(rows, cells[mine], n)
    unpacked = np.isin(tables, [t for t, p in packing.items() if isinstance(p, str)])
    if unpacked.any():
        candidates = [dict(zip(keys, map(float, x), strict=True)) for x in X]
        ours[unpacked] = by_candidate(candidates, cells[unpacked])
    return ours


def measured(packed: PackedTable, columns: dict[str, np.ndarray], n: int) -> MetricColumns:
    """The metric rows of ``n`` candidates (``columns``: each free value's column) of a packed
    table, simulated and measured where its experiment says (``simulation.device``)."""
    return ensemble_metrics(*ensemble(packed, columns, n))[1]


def packed_cells(measured_rows: MetricColumns, cells: pd.DataFrame, n: int) -> np.ndarray:
    """Our value of every cell (rows of ``cells``, one table's) for each of ``n`` candidates
    (columns), from the table's metric rows: as :func:`nlcx.thesis.fitting.cell_values` reads a
    run's metrics, the first row of (controller, signal, metric) of a run that finished (M_p of
    a position is overshoot/100), NaN where there is none."""
    m = measured_rows
    out = np.full((len(cells), n), math.nan)
    codes = {k: {text: j for j, text in enumerate(v)} for k, v in m.categories.items()}
    ok = m.codes["status"] == codes["status"].get("ok", -2)
    for i, (controller, signal, metric) in enumerate(zip(cells.controller, cells.signal, cells.metric, strict=True)):
        name = (ANGLE_METRICS if signal in ANGLES else POSITION_METRICS).get(str(metric))
        if name is None:
            continue
        rows = np.flatnonzero(
            ok
            & (m.codes["controller"] == codes["controller"].get(str(controller), -2))
            & (m.codes["signal"] == codes["signal"].get(str(signal), -2))
            & (m.codes["metric"] == codes["metric"].get(name, -2))
        )
        variants, first = np.unique(m.variant[rows], return_index=True)
        values = m.value[rows[first]]
        out[i, variants] = values / 100.0 if name == "overshoot" else values
    return out

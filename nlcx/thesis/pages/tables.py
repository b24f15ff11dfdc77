"""Thesis beside nlcx, cell by cell, for every table of a reproduction (tables/*.csv).

A table CSV shows the thesis's numbers in one of two shapes: a ``thesis`` and an ``nlcx``
column (one cell per row), or column pairs ``thesis_X`` / ``nlcx_X`` (one cell per pair and
row). Tables with neither (e.g. Table 5.1: our ZN gains only) have no cells to judge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from nlcx.thesis.pages.tolerances import ReproductionTolerances

#: Columns that name a cell (the first present is its metric for the tolerance).
METRIC_COLUMNS = ("metric", "parameter")
LABEL_COLUMNS = ("method", "schedule", "loop", "signal", "controller", "parameter", "metric", "variable", "set")


@dataclass
class Cell:
    label: str
    metric: str
    controller: str
    thesis: float
    nlcx: float
    within: bool

    @property
    def delta(self) -> float:
        return self.nlcx - self.thesis

    @property
    def delta_pct(self) -> float:
        return 100.0 * self.delta / abs(self.thesis) if self.thesis != 0 else math.nan


@dataclass
class TableComparison:
    """One table: its cells, how many are within tolerance and the verdict."""

    name: str
    file: str
    cells: list[Cell] = field(default_factory=list)
    verdict: str = "n/a"

    @property
    def within(self) -> int:
        return sum(c.within for c in self.cells)


def table_number(file: str) -> str:
    """'table_2_3.csv' -> 'Table 2.3'; other files by their stem ('zn_variants')."""
    stem = Path(file).stem
    return "Table " + stem.removeprefix("table_").replace("_", ".") if stem.startswith("table_") else stem


def _label(row: pd.Series, extra: str = "") -> str:
    parts = [str(row[c]) for c in LABEL_COLUMNS if c in row.index and pd.notna(row[c]) and str(row[c]) != ""]
    return " · ".join(dict.fromkeys([*parts, extra] if extra else parts))


def _number(value: object) -> float:
    try:
        return float(value)  # type: ignore[arg-type]  # any cell: what float() refuses is NaN
    except (TypeError, ValueError):
        return math.nan


def cells_of(frame: pd.DataFrame, tolerances: ReproductionTolerances) -> list[Cell]:
    """Every (thesis, nlcx) cell of a table CSV, judged by its metric's tolerance."""
    cells = []
    pairs = [c.removeprefix("thesis_") for c in frame.columns if c.startswith("thesis_") and f"nlcx_{c[7:]}" in frame]
    for _, row in frame.iterrows():
        metric = next((str(row[c]) for c in METRIC_COLUMNS if c in row.index), "")
        controller = str(row["controller"]) if "controller" in row.index else ""
        found = [("", "thesis", "nlcx")] if {"thesis", "nlcx"} <= set(frame.columns) else []
        found += [(p, f"thesis_{p}", f"nlcx_{p}") for p in pairs]
        for extra, t_col, n_col in found:
            thesis, ours = _number(row[t_col]), _number(row[n_col])
            if math.isnan(thesis):
                continue
            tolerance = tolerances.for_metric(metric)
            cells.append(Cell(_label(row, extra), metric, controller, thesis, ours, tolerance.within(thesis, ours)))
    return cells


def compare(directory: Path, tolerances: ReproductionTolerances) -> list[TableComparison]:
    """Every table of ``directory/tables`` in thesis order, its cells judged."""
    out = []
    for path in sorted((directory / "tables").glob("*.csv"), key=_order):
        comparison = TableComparison(table_number(path.name), path.name)
        comparison.cells = cells_of(pd.read_csv(path), tolerances)
        comparison.verdict = tolerances.verdict(comparison.within, len(comparison.cells))
        out.append(comparison)
    return out


def _order(path: Path) -> tuple[int, ...]:
    numbers = [int(p) for p in path.stem.removeprefix("table_").split("_") if p.isdigit()]
    return tuple(numbers) if numbers else (99,)

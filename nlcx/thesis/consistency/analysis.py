"""The consistency study's analysis of the stored loops: which printed cells each loop hits,
the minimal sets of cells no loop hits together, and the study's tables (columns.csv,
cells.csv, subsets.csv, summary.json) and figure."""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from nlcx import report
from nlcx.thesis import catalog
from nlcx.thesis.consistency.figure import figure
from nlcx.thesis.consistency.loops import Store, families_of
from nlcx.thesis.consistency.spec import (
    NLCX_DEFINITION,
    Column,
    ConsistencySpec,
    Family,
    also_printed,
    column_cells,
    with_intervals,
)
from nlcx.thesis.fitting import FLOORS
from nlcx.thesis.pages import tolerances


def inside(cells: pd.DataFrame, ours: np.ndarray) -> np.ndarray:
    """(loops, cells) booleans of ``ours`` (loops, cells): the value inside the interval the
    printed cell covers, ``cells.lower`` <= ours <= ``cells.upper`` (:func:`with_intervals`: the
    printed value's rounding to its decimals, widened by its metric's relative tolerance)."""
    with np.errstate(invalid="ignore"):
        return (cells.lower.to_numpy() <= ours) & (ours <= cells.upper.to_numpy())


def relative_miss(cells: pd.DataFrame, ours: np.ndarray) -> np.ndarray:
    """(loops, cells) relative misses of ``ours``, |ours - printed| / max(|printed|, floor), the
    floor of the cell's metric (:data:`nlcx.thesis.fitting.FLOORS`); NaN where ours is undefined."""
    scale = np.maximum(cells.value.abs().to_numpy(), cells.metric.map(FLOORS).to_numpy())
    with np.errstate(invalid="ignore"):
        return np.abs(ours - cells.value.to_numpy()) / scale


def hits(loops: pd.DataFrame, cells: pd.DataFrame) -> np.ndarray:
    """(loops, cells) booleans: each loop's value of each cell :func:`inside` its interval."""
    return inside(cells, loops[list(cells.cell)].to_numpy(dtype=float))


#: The mirror signals of the symmetric pendulums: y mirrors x, phi mirrors theta.
MIRROR = {"y": "x", "phi": "theta"}


def twins(cells: pd.DataFrame) -> list[list[int]]:
    """Groups of cells (row positions) the thesis prints alike for mirror signals: y.Mp with
    x.Mp when both print the same value, and so on; every other cell alone."""
    groups: dict[tuple[str, str, float], list[int]] = {}
    row: Any  # a row of ``cells``: its signal, metric (str) and printed value (float)
    for i, row in enumerate(cells.itertuples(index=False)):
        groups.setdefault((MIRROR.get(row.signal, row.signal), row.metric, row.value), []).append(i)
    return list(groups.values())


def group_hits(hit: np.ndarray, miss: np.ndarray, groups: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Per group of twins: hit when every member is hit, missed by the largest member's miss."""
    merged_hit = np.stack([hit[:, g].all(axis=1) for g in groups], axis=1)
    merged_miss = np.stack([np.nan_to_num(miss[:, g], nan=np.inf).max(axis=1) for g in groups], axis=1)
    return merged_hit, merged_miss


def unreachable_sets(hit: np.ndarray, max_size: int) -> list[tuple[int, ...]]:
    """The minimal sets of cells (column indices of ``hit``, up to ``max_size``) that no loop
    hits together while every proper subset is hit by some loop."""
    n = hit.shape[1]
    masks = hit.astype(np.int64) @ (1 << np.arange(n, dtype=np.int64))
    reached = {0}
    minimal = []
    for size in range(1, max_size + 1):
        for subset in itertools.combinations(range(n), size):
            bits = sum(1 << i for i in subset)
            if np.any((masks & bits) == bits):
                reached.add(bits)
            elif all(bits & ~(1 << i) in reached for i in subset):
                minimal.append(subset)
    return minimal


@dataclass(frozen=True)
class Evidence:
    """A column's loops under one definition judged on its cells, ``cell_hit`` (loops, cells), and
    with mirror twins merged: ``hit``, ``miss`` (relative, inf where undefined), (loops, groups)."""

    loops: pd.DataFrame
    cell_hit: np.ndarray
    hit: np.ndarray
    miss: np.ndarray


def evidence(cells: pd.DataFrame, groups: list[list[int]], loops: pd.DataFrame) -> Evidence:
    miss = relative_miss(cells, loops[list(cells.cell)].to_numpy(float))
    cell_hit = hits(loops, cells)
    return Evidence(loops, cell_hit, *group_hits(cell_hit, miss, groups))


def nearest_miss(ev: Evidence, subset: tuple[int, ...]) -> tuple[float, int]:
    """(largest relative miss over ``subset`` of the loop nearest to hitting it all, that loop)."""
    worst = ev.miss[:, list(subset)].max(axis=1)
    k = int(np.argmin(worst))
    return float(worst[k]), k


def analyse(
    spec: ConsistencySpec, store: Store, families: dict[Column, Family], rules: tolerances.ReproductionTolerances
) -> pd.DataFrame:
    """columns.csv, cells.csv, subsets.csv, summary.json and consistency.png from the stored loops."""
    columns, cell_rows, subset_rows, clouds, summary = [], [], [], {}, []
    for column, family in families.items():
        names, examined = [h.name for h in family], " ".join(families_of(family))
        cells = with_intervals(column_cells(*column), rules, spec.zero_decimals)
        groups = twins(cells)
        fits = pd.DataFrame([store.fit(column, h) for h in names]).sort_values("loss", kind="stable")
        judged = {d: evidence(cells, groups, store.loops(column, d, names)) for d in spec.definitions}
        for definition, ev in judged.items():
            columns.append(column_row(column, definition, cells, ev, fits.iloc[0]) | {"families": examined})
            cell_rows += cell_table(column, definition, cells, ev)
        subset_rows += [row | {"families": examined} for row in subset_table(column, cells, groups, judged)]
        clouds[column] = judged[NLCX_DEFINITION].loops
        summary.append({"table": column[0], "controller": column[1], "families": families_of(family),
                        "hypotheses": len(family)})  # fmt: skip
    out = store.out_dir
    frame = pd.DataFrame(columns)
    report.write_csv(out / "columns.csv", frame)
    report.write_csv(out / "cells.csv", pd.DataFrame(cell_rows))
    report.write_csv(out / "subsets.csv", pd.DataFrame(subset_rows))
    scope = {"families": spec.families, "max_options": spec.max_options, "alone": spec.alone, "columns": summary}
    report.write_text(out / "summary.json", json.dumps(scope, indent=2) + "\n")
    figure(clouds, out / "consistency.png")
    return frame


def column_row(column: Column, definition: str, cells: pd.DataFrame, ev: Evidence, best: pd.Series) -> dict[str, Any]:
    """One column under one definition: the loops examined, the most cells one loop hits, the
    minimal unreachable sets, and (nlcx's definition) the best GA fit."""
    table, controller = column
    counts = ev.cell_hit.sum(axis=1)
    head = catalog.thesis_metrics().query("table == @table").iloc[0]
    values = ev.loops[list(cells.cell)].to_numpy(float)
    row = {
        "table": table, "controller": controller, "also_printed_in": " ".join(also_printed(*column)),
        "plant": head.plant, "scenario": head.scenario, "definition": definition, "cells": len(cells),
        "loops": len(ev.loops), "settled_share": float(np.mean(np.all(np.isfinite(values), axis=1))),
        "most_cells_hit": int(counts.max()), "loops_hitting_all": int(np.sum(counts == len(cells))),
        "reproduced": bool(np.any(counts == len(cells))), "unreachable_sets": len(unreachable_sets(ev.hit, 3)),
    }  # fmt: skip
    if definition == NLCX_DEFINITION:
        row |= {"best_fit": best.hypothesis, "best_fit_loss": float(best.loss),
                "best_fit_values": json.dumps(best["values"])}  # fmt: skip
    return row


def cell_table(column: Column, definition: str, cells: pd.DataFrame, ev: Evidence) -> list[dict[str, Any]]:
    """Per cell: printed (its text and the interval it covers), the value of the loop nearest
    the whole column (least loss), the range the loops reach, and how many hit it."""
    loops = ev.loops
    nearest = loops.iloc[int(loops.loss.argmin())]
    rows = []
    cell: Any  # a row of ``cells``: its cell name (a column of ``loops``), printed value and interval
    for i, cell in enumerate(cells.itertuples(index=False)):
        values = loops[cell.cell].to_numpy(dtype=float)
        finite = values[np.isfinite(values)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (np.nan, np.nan)
        rows.append({
            "table": column[0], "controller": column[1], "definition": definition, "cell": cell.cell,
            "printed": cell.value, "text": cell.text, "lower": cell.lower, "upper": cell.upper,
            "nearest_loop": float(nearest[cell.cell]), "nearest_hypothesis": nearest.hypothesis,
            "min": lo, "max": hi, "loops_hitting": int(ev.cell_hit[:, i].sum()),
        })  # fmt: skip
    return rows


def subset_table(
    column: Column, cells: pd.DataFrame, groups: list[list[int]], judged: dict[str, Evidence], max_size: int = 3
) -> list[dict[str, Any]]:
    """The minimal sets of printed cells (up to ``max_size``; mirror twins such as
    x.Mp = y.Mp count as one cell, hit when both are) that no loop examined under the first
    definition hits together, with the loop nearest to hitting each (the one whose largest
    relative miss over the set is smallest) and that nearest miss under every definition."""
    label = [" = ".join(cells.cell.iloc[m] for m in g) for g in groups]
    first, *_ = judged.values()
    rows = []
    for subset in unreachable_sets(first.hit, max_size):
        _, k = nearest_miss(first, subset)
        members = [m for i in subset for m in groups[i]]
        near = ", ".join(f"{cells.cell.iloc[m]} {first.loops[cells.cell.iloc[m]].iloc[k]:.3g}" for m in members)
        misses = {f"miss {d}": nearest_miss(ev, subset)[0] for d, ev in judged.items()}
        rows.append({
            "table": column[0], "controller": column[1], "cells": " & ".join(label[i] for i in subset),
            "printed": ", ".join(cells.text.iloc[groups[i][0]] for i in subset), "size": len(subset),
            "loops": len(first.loops), "nearest": near, **misses, "least_miss": min(misses.values()),
        })  # fmt: skip
    return rows

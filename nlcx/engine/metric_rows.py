"""An ensemble's metric rows laid out as columns: the long form of metrics.csv, written in one pass.

:func:`nlcx.engine.ensembles.measure_ensemble` measures each loop's runs as a :class:`RowBlock`:
the runs that finished (:func:`ok_block`, a row per metric) or those that stopped
(:func:`failed_block`: ``t_fail`` and a missing settling time per followed output). A block's
text columns repeat one pattern per run (its rows' controller, signal, metric, unit and
status), so a block holds the pattern once and its values as a matrix. :func:`ordered` puts
every block's rows in the order of :func:`nlcx.engine.measure_runs` (by variant, then loop,
then row) with one compiled scan that writes each row's variant, value and codes in its place.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

#: The text columns of a metric row, in the order a block's ``pattern`` holds the first five.
TEXT_COLUMNS = ("controller", "signal", "metric", "unit", "status", "note")


@dataclass
class MetricColumns:
    """The long-form metric rows of an ensemble as columns (the columns of metrics.csv): text
    columns as codes into their category lists (``-1``: missing)."""

    variant: np.ndarray
    value: np.ndarray
    codes: dict[str, np.ndarray]
    categories: dict[str, list[str]]


class Categories:
    """Text columns as codes into lists of their distinct values, in order of first use."""

    def __init__(self, names: Sequence[str] = TEXT_COLUMNS) -> None:
        self.values: dict[str, list[str]] = {n: [] for n in names}
        self._index: dict[str, dict[str, int]] = {n: {} for n in names}

    def code(self, column: str, text: str | None) -> int:
        """The code of ``text`` in ``column`` (``-1``: no text)."""
        if text is None or text == "":
            return -1
        index = self._index[column]
        if text not in index:
            index[text] = len(self.values[column])
            self.values[column].append(text)
        return index[text]


@dataclass
class RowBlock:
    """One loop's rows for some variants: the same ``w`` rows for each variant.

    ``value`` is (variants, w); ``pattern`` (w, 5) holds each row's controller, signal, metric,
    unit and status codes; a row's note is the variant's ``note`` where that is set (``>= 0``),
    else ``nan_note`` of the row where its value is NaN (``-1`` otherwise)."""

    variants: np.ndarray
    loop: int
    value: np.ndarray
    pattern: np.ndarray
    nan_note: np.ndarray
    note: np.ndarray


def _pattern(cats: Categories, label: str, status: str, rows: Sequence[tuple[str, str, str]]) -> np.ndarray:
    """The (w, 5) codes of rows given as (signal, metric, unit)."""
    return np.array(
        [[cats.code("controller", label), cats.code("signal", s), cats.code("metric", name), cats.code("unit", unit),
          cats.code("status", status)] for s, name, unit in rows],
        dtype=np.int32,
    ).reshape(len(rows), 5)  # fmt: skip


def ok_block(
    variants: np.ndarray, loop: int, value: np.ndarray, rows: Sequence[tuple[str, str, str, str]],
    cats: Categories, label: str,
) -> RowBlock:  # fmt: skip
    """The rows of the runs that finished: ``value`` (variants, w), ``rows`` each row's signal,
    metric, unit and the note of a missing value."""
    nan_note = np.array([cats.code("note", note) for *_, note in rows], dtype=np.int32)
    pattern = _pattern(cats, label, "ok", [(s, name, unit) for s, name, unit, _ in rows])
    note = np.full(variants.size, -1, dtype=np.int32)
    return RowBlock(variants, loop, np.ascontiguousarray(value, dtype=float), pattern, nan_note, note)


def failed_block(
    variants: np.ndarray, loop: int, t_fail: np.ndarray, reasons: Sequence[str],
    rows: Sequence[tuple[str, str, str]], cats: Categories, label: str,
) -> RowBlock:  # fmt: skip
    """The rows of the runs that stopped, given as (signal, metric, unit): ``t_fail`` first,
    then missing values (:meth:`nlcx.engine.plan.LoopPlan.failed_rows`); each row's note the
    run's reason."""
    note = np.array([cats.code("note", reason) for reason in reasons], dtype=np.int32)
    value = np.full((variants.size, len(rows)), np.nan)
    value[:, 0] = t_fail
    pattern = _pattern(cats, label, "unstable", rows)
    return RowBlock(variants, loop, value, pattern, np.full(len(rows), -1, dtype=np.int32), note)


@njit(cache=True, nogil=True)
def _place(
    starts: np.ndarray,
    variants: np.ndarray,
    value: np.ndarray,
    pattern: np.ndarray,
    nan_note: np.ndarray,
    note: np.ndarray,
    out_variant: np.ndarray,
    out_value: np.ndarray,
    out_codes: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Write a block's rows from ``starts`` (one per variant of the block) on."""
    n, w = value.shape
    for k in range(n):
        at, e, fixed = starts[k], variants[k], note[k]
        for r in range(w):
            v = value[k, r]
            out_variant[at + r] = e
            out_value[at + r] = v
            for c in range(5):
                out_codes[c, at + r] = pattern[r, c]
            out_codes[5, at + r] = fixed if fixed >= 0 else (nan_note[r] if np.isnan(v) else -1)


def ordered(blocks: list[RowBlock], cats: Categories, n_variants: int, n_loops: int) -> MetricColumns:
    """The blocks' rows in :func:`nlcx.engine.measure_runs`'s order (by variant, then loop, then
    row), each row put in its place."""
    counts = np.zeros((n_variants, n_loops), dtype=np.int64)
    for b in blocks:
        counts[b.variants, b.loop] = b.value.shape[1]
    starts = np.concatenate([[0], np.cumsum(counts.reshape(-1))[:-1]]).reshape(n_variants, n_loops)
    total = int(counts.sum())
    variant, value = np.empty(total, dtype=np.int64), np.empty(total)
    codes = np.empty((len(TEXT_COLUMNS), total), dtype=np.int32)
    for b in blocks:
        rows = np.asarray(b.variants, dtype=np.int64)  # no copy: the blocks' positions are int64
        _place(starts[rows, b.loop], rows, b.value, b.pattern, b.nan_note, b.note, variant, value, codes)
    return MetricColumns(variant, value, dict(zip(TEXT_COLUMNS, codes, strict=True)), cats.values)

"""The rows of two tables made ready to compare, for ``nlcx diff``: the roles of their columns
(:func:`plan_columns`) and their rows a chunk at a time (:func:`rows_of`), those of the runs
whose statuses changed left out (:mod:`nlcx.diff.statuses`).

Columns: a column is compared as numbers when BASE holds numbers in it and NEW does too, or
BASE holds some; notes and statuses are compared as text; the other columns are keys, and the
keys other than :data:`~nlcx.diff.records.ROW_KEYS` name a row's run. A CSV's kinds are first
taken from its first chunk of rows (:attr:`ColumnRoles.provisional`), its columns of numbers read
as float64 by the CSV reader; a cell further on that does not keep to its kind raises
:class:`~nlcx.diff.tables.KindChangedError`, and the tables are compared again with the kinds
of all their cells.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from nlcx.diff.cells import NUMBER, ColumnKind, as_numbers, as_texts, hash_rows, kind_holds, mix
from nlcx.diff.records import DESCRIPTIVE, ROW_KEYS, Tolerances, is_status_column
from nlcx.diff.statuses import RunFilter, RunPairs
from nlcx.diff.tables import KindChangedError, TableSource

#: The two tables, as indices of pairs.
BASE, NEW = 0, 1


@dataclass(frozen=True)
class ColumnRoles:
    """The columns of two tables with the same column names, by role.

    Attributes
    ----------
    columns : list of str
        All of them, in order.
    keys : list of str
        The text columns that identify a row; ``run_keys``: those that identify its run.
    numeric : list of str
        The columns compared as numbers.
    described : list of str
        The notes and statuses, compared as text; ``status``: the statuses.
    kinds : tuple of dict
        Each table's kind of each numeric column.
    provisional : bool
        Whether the kinds of a CSV's columns come from its first rows only: its columns of
        numbers are then read as float64, and a cell that is not a number stops the pass
        (:class:`~nlcx.diff.tables.KindChangedError`).
    """

    columns: list[str]
    keys: list[str]
    run_keys: list[str]
    numeric: list[str]
    described: list[str]
    status: list[str]
    kinds: tuple[dict[str, ColumnKind], dict[str, ColumnKind]]
    provisional: bool = False

    def read_as_numbers(self, side: int) -> list[str]:
        """The numeric columns a CSV's reader gives as float64 (where the kinds are provisional)."""
        if not self.provisional:
            return []
        return [c for c in self.numeric if self.kinds[side][c].name == NUMBER]

    def order(self, column: str) -> int:
        """Where ``column`` stands in the table; -1 for a whole row."""
        return self.columns.index(column) if column in self.columns else -1


def plan_columns(base: TableSource, new: TableSource, provisional: bool = False) -> ColumnRoles | None:
    """The roles of the columns of two tables with the same columns.

    A column is compared as numbers when BASE holds numbers in it and NEW does too, or BASE
    holds some (NEW's cells that are not numbers are then NaN); never a note, a status or a
    sweep's ``variant`` (a key). The notes and statuses are compared as text; the other
    columns are keys. ``provisional``: a CSV's kinds from its first rows (None when they
    cannot settle a column: numbers in BASE, text in NEW); else from all its cells.
    """
    columns = base.columns
    candidates = [c for c in columns if c != "variant" and c not in DESCRIPTIVE and not is_status_column(c)]
    base_kinds = base.first_kinds(candidates) if provisional else base.kinds(candidates)
    maybe = [c for c in candidates if base_kinds[c].numeric]
    new_kinds = new.first_kinds(maybe) if provisional else new.kinds(maybe)
    if provisional and not all(new_kinds[c].numeric for c in maybe):
        return None
    numeric = [c for c in maybe if new_kinds[c].numeric or _has_values(base, c, base_kinds[c])]
    described = [c for c in columns if c not in numeric and (c in DESCRIPTIVE or is_status_column(c))]
    keys = [c for c in columns if c not in numeric and c not in described]
    return ColumnRoles(
        columns=list(columns),
        keys=keys,
        run_keys=[c for c in keys if c not in ROW_KEYS],
        numeric=numeric,
        described=described,
        status=[c for c in described if is_status_column(c)],
        kinds=({c: base_kinds[c] for c in numeric}, {c: new_kinds[c] for c in numeric}),
        provisional=provisional,
    )


def _has_values(table: TableSource, column: str, kind: ColumnKind) -> bool:
    return kind.has_values if kind.has_values is not None else table.has_values(column)


@dataclass
class Rows:
    """Rows of one table, ready to compare.

    Attributes
    ----------
    pos : numpy.ndarray
        int64: each row's place in its table (0 for the first row after the header).
    values : list of numpy.ndarray
        The numeric columns (:attr:`ColumnRoles.numeric`), float64.
    texts : list of pyarrow.Array
        The notes and statuses (:attr:`ColumnRoles.described`), text.
    rtol, atol : numpy.ndarray or None
        Each row's tolerances, where a ``metric`` key column names its metric.
    keys : list of pyarrow.Array or None
        The key columns, text: rows fresh from the table; None for rows that wait.
    hashes, occurrence : numpy.ndarray or None
        uint64 key hashes and int64 occurrence numbers, once the rows are matched on them.
    """

    pos: np.ndarray
    values: list[np.ndarray]
    texts: list[pa.Array]
    rtol: np.ndarray | None = None
    atol: np.ndarray | None = None
    keys: list[pa.Array] | None = None
    hashes: np.ndarray | None = None
    occurrence: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.pos)

    def slice(self, start: int, stop: int) -> Rows:
        def part(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[start:stop]

        return Rows(
            self.pos[start:stop],
            [v[start:stop] for v in self.values],
            [t.slice(start, stop - start) for t in self.texts],
            part(self.rtol),
            part(self.atol),
            None if self.keys is None else [k.slice(start, stop - start) for k in self.keys],
            part(self.hashes),
            part(self.occurrence),
        )

    def take(self, index: np.ndarray) -> Rows:
        def part(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[index]

        arrow = pa.array(index, pa.int64())
        return Rows(
            self.pos[index],
            [v[index] for v in self.values],
            [t.take(arrow) for t in self.texts],
            part(self.rtol),
            part(self.atol),
            None if self.keys is None else [k.take(arrow) for k in self.keys],
            part(self.hashes),
            part(self.occurrence),
        )

    def key_hashes(self, index: np.ndarray | None = None) -> np.ndarray:
        """The key hashes of the rows (``index``: of those rows only); a row's place where the
        table has no key column."""
        if self.hashes is not None:
            return self.hashes if index is None else self.hashes[index]
        if self.keys is None:  # pragma: no cover - waiting rows have their hashes
            raise ValueError("rows without keys or hashes")
        pos = self.pos if index is None else self.pos[index]
        if not self.keys:
            return mix(pos.astype(np.uint64))
        keys = self.keys if index is None else [k.take(pa.array(index, pa.int64())) for k in self.keys]
        return hash_rows(keys, len(pos))


def no_rows(layout: ColumnRoles, per_row_tolerance: bool) -> Rows:
    """No rows, with the columns of ``layout`` (and per-row tolerances where there are)."""
    empty = np.zeros(0)
    tolerance = empty if per_row_tolerance else None
    return Rows(
        np.zeros(0, np.int64),
        [empty for _ in layout.numeric],
        [pa.array([], pa.string()) for _ in layout.described],
        tolerance,
        tolerance,
        None,
        np.zeros(0, np.uint64),
        np.zeros(0, np.int64),
    )


def concat_rows(parts: list[Rows]) -> Rows:
    """Rows that wait and rows that come, one after the other (without their key columns)."""

    def joined(arrays: list[np.ndarray | None]) -> np.ndarray | None:
        present = [a for a in arrays if a is not None]
        return np.concatenate(present) if len(present) == len(arrays) else None

    first = parts[0]
    return Rows(
        np.concatenate([rows.pos for rows in parts]),
        [np.concatenate([rows.values[j] for rows in parts]) for j in range(len(first.values))],
        [pa.concat_arrays([rows.texts[j] for rows in parts]) for j in range(len(first.texts))],
        joined([rows.rtol for rows in parts]),
        joined([rows.atol for rows in parts]),
        None,
        joined([rows.hashes for rows in parts]),
        joined([rows.occurrence for rows in parts]),
    )


def rows_of(
    table: TableSource,
    layout: ColumnRoles,
    side: int,
    tol: Tolerances,
    runs: RunFilter | None = None,
    pairs: RunPairs | None = None,
) -> Iterator[Rows]:
    """The rows of ``table`` a chunk at a time, ready to compare: those of the runs whose
    statuses changed (``runs``) left out; ``pairs``: gathers each run's statuses.

    Raises
    ------
    nlcx.diff.tables.KindChangedError
        The kinds are provisional and a CSV column's cells do not keep to its kind.
    """
    kinds = layout.kinds[side]
    checked = [c for c in layout.numeric if layout.provisional and table.is_csv]
    start = 0
    for batch in table.batches(layout.columns, layout.read_as_numbers(side) if table.is_csv else ()):
        n = batch.num_rows
        if not all(kind_holds(batch.column(c), kinds[c]) for c in checked):
            raise KindChangedError(str(table.path))
        pos = np.arange(start, start + n, dtype=np.int64)
        start += n
        keys = [as_texts(batch.column(c)) for c in layout.keys]
        texts = [as_texts(batch.column(c)) for c in layout.described]
        run_keys = [keys[layout.keys.index(c)] for c in layout.run_keys]
        statuses = [texts[layout.described.index(c)] for c in layout.status]
        if pairs is not None:
            pairs.add(hash_rows(run_keys, n), hash_rows(statuses, n), pos)
        if runs is not None:
            kept = runs.rows_kept(run_keys, statuses, n)
            if not kept.all():
                mask = pa.array(kept)
                batch, pos = batch.filter(mask), pos[kept]
                keys, texts = [k.filter(mask) for k in keys], [t.filter(mask) for t in texts]
        if not len(pos):
            continue
        values = [as_numbers(batch.column(c), kinds[c]) for c in layout.numeric]
        metric = keys[layout.keys.index("metric")] if "metric" in layout.keys else None
        rtol, atol = row_tolerances(metric, tol) if metric is not None else (None, None)
        yield Rows(pos, values, texts, rtol, atol, keys)


def row_tolerances(metric: pa.Array, tol: Tolerances) -> tuple[np.ndarray, np.ndarray]:
    """Each row's rtol and atol, from the metric it names."""
    codes = pc.dictionary_encode(metric)
    index = codes.indices.to_numpy(zero_copy_only=False)
    per_metric = np.array([tol.of(name) for name in codes.dictionary.to_pylist()], dtype=np.float64).reshape(-1, 2)
    per_row = per_metric[index]
    return per_row[:, 0], per_row[:, 1]

"""Two tables compared a chunk of rows at a time (:func:`compare_tables`), for ``nlcx diff``.

:mod:`nlcx.diff` says what is compared. Both tables are read in step (:func:`~nlcx.diff.rows.rows_of`),
and their rows matched and compared by :class:`~nlcx.diff.matching.Matcher`.

Counts are exact; only the first ``keep`` drifts of a table in row order are kept, and named
at the end in one pass over the key columns of the table that holds their rows (:func:`_labels`):
their key text and, for a key the table holds more than once, the row's occurrence number.
"""

from __future__ import annotations

import numpy as np

from nlcx.diff.cells import as_texts, hash_rows
from nlcx.diff.matching import Found, Matcher, pending_cap
from nlcx.diff.records import KEEP_STATUS, STATUS_RUNS, Drift, FileDrift, Tolerances
from nlcx.diff.rows import BASE, NEW, ColumnRoles, plan_columns, rows_of
from nlcx.diff.statuses import RunFilter, RunPairs, status_changes
from nlcx.diff.tables import KindChangedError, TableSource


def _labels(table: TableSource, layout: ColumnRoles, found: list[Found]) -> dict[int, str]:
    """The names of the rows of ``table`` at the places of ``found``: ``KEY`` (the text of its
    key columns, ``a | b``, or its place where there are none), or ``KEY #k`` for the k-th row
    (from 0) of a key that the table holds more than once."""
    places = sorted({f.pos for f in found})
    if not places:
        return {}
    if not layout.keys:
        return {p: str(p) for p in places}
    key_of = {f.pos: f.key_hash for f in found}
    wanted = sorted(set(key_of.values()))
    texts: dict[int, str] = {}
    before = dict.fromkeys(places, 0)
    total = dict.fromkeys(wanted, 0)
    start = 0
    for batch in table.batches(layout.keys):
        n = batch.num_rows
        keys = [as_texts(batch.column(c)) for c in layout.keys]
        hashes = hash_rows(keys, n)
        for value in wanted:
            rows = np.flatnonzero(hashes == np.uint64(value)) + start
            total[value] += len(rows)
            for p in places:
                if key_of[p] == value:
                    before[p] += int(np.searchsorted(rows, p))
        for p in places:
            if start <= p < start + n:
                texts[p] = " | ".join(k[p - start].as_py() for k in keys)
        start += n
    return {p: texts.get(p, "?") + (f" #{before[p]}" if total[key_of[p]] > 1 else "") for p in places}


def compare_tables(name: str, base: TableSource, new: TableSource, tol: Tolerances, keep: int) -> FileDrift:
    """The drift between two tables (their files checked already).

    The kinds of a CSV's columns are first taken from its first rows, and its columns of
    numbers read as numbers; if a cell further on is not one, the tables are compared again
    with the kinds found in all their cells.

    Parameters
    ----------
    name : str
        The table's relative path, naming it in the drifts.
    base, new : TableSource
        The tables.
    tol : Tolerances
        The tolerances.
    keep : int
        Drifts other than status changes kept to be shown (all are counted).

    Returns
    -------
    FileDrift
        Counts of every kind of drift, the first ``keep`` drifts in row order, the first
        :data:`~nlcx.diff.records.KEEP_STATUS` status changes, and a line for each limit reached.
    """
    if base.columns != new.columns:
        columns = Drift(name, "(columns)", "", ", ".join(base.columns), ", ".join(new.columns))
        return FileDrift(name, tables=1, first=[columns])
    if not base.columns:
        return FileDrift(name)
    layout = plan_columns(base, new, provisional=True)
    if layout is not None:
        try:
            return _compared(name, base, new, layout, tol, keep)
        except KindChangedError:
            pass
    checked = plan_columns(base, new)
    assert checked is not None
    return _compared(name, base, new, checked, tol, keep)


def _compared(
    name: str, base: TableSource, new: TableSource, layout: ColumnRoles, tol: Tolerances, keep: int
) -> FileDrift:
    """The drift between two tables of this layout: a pass over both that compares their rows
    and gathers their runs' statuses; a second pass without the runs whose statuses changed,
    if any did; the names of the drifts kept."""
    out = FileDrift(name)
    pairs = (RunPairs(STATUS_RUNS), RunPairs(STATUS_RUNS)) if layout.status else (None, None)
    matcher = _matched(name, base, new, layout, tol, keep, None, pairs)
    runs = _runs_changed(name, pairs, out)
    if runs is not None:
        matcher = _matched(name, base, new, layout, tol, keep, runs, (None, None))
        out.statuses = runs.drifts(name, layout.status)
    tally = matcher.tally
    out.cells, out.missing_rows, out.extra_rows = tally.cells, tally.missing, tally.extra
    out.largest = tally.largest
    out.columns = sorted(tally.columns, key=layout.order)
    names = [_labels(table, layout, [f for f in tally.kept if f.side == side]) for side, table in ((0, base), (1, new))]
    out.first = [Drift(name, names[f.side][f.pos], f.column, f.base, f.new) for f in tally.kept]
    if (note := matcher.note()) is not None:
        out.notes.append(note)
    return out


def _matched(
    name: str,
    base: TableSource,
    new: TableSource,
    layout: ColumnRoles,
    tol: Tolerances,
    keep: int,
    runs: RunFilter | None,
    pairs: tuple[RunPairs | None, RunPairs | None],
) -> Matcher:
    """One pass over both tables: their rows matched and compared."""
    matcher = Matcher(name, layout, tol, keep, pending_cap(layout))
    matcher.run(
        rows_of(base, layout, BASE, tol, runs, pairs[BASE]),
        rows_of(new, layout, NEW, tol, runs, pairs[NEW]),
    )
    return matcher


def _runs_changed(name: str, pairs: tuple[RunPairs | None, RunPairs | None], out: FileDrift) -> RunFilter | None:
    """The runs whose statuses changed (counted in ``out``); None when none did, or when the
    tables hold too many runs to tell (a note in ``out`` then says that their statuses are
    compared row by row)."""
    gathered_base, gathered_new = pairs
    if gathered_base is None or gathered_new is None:
        return None
    before, after = gathered_base.runs(), gathered_new.runs()
    if before is None or after is None:
        out.notes.append(
            f"{name}: more than {STATUS_RUNS:,} distinct runs and statuses: statuses compared row by row, not per run"
        )
        return None
    runs = status_changes(before, after, KEEP_STATUS)
    out.status_changes = len(runs.changed)
    return runs if len(runs.changed) else None

"""The rows of two tables matched and their drifts tallied (:class:`Matcher`), for ``nlcx diff``.

Rows come a chunk at a time from each table (:func:`~nlcx.diff.rows.rows_of`). While the tables
list the same keys in the same order (no row waits), the rows of a chunk are compared with the
rows at the same places in the other table's chunk, column by column. From the first row whose
key differs, rows are matched on (key hash, occurrence number) with each other and with the rows
that wait from the other table, and the rows without a match wait, across chunks, at most
:func:`pending_cap` of them at once. The occurrence numbers count from the last point where both
tables had seen a key equally often (past the last row of the key that waits, or at the first of
the other table's): that pairs the k-th row of a key in BASE with the k-th in NEW, as numbering
every row of a key from the top of the table does, without a count of every key.

Counts are exact (:class:`DriftTally`); only the first ``keep`` drifts of a table in row order
are kept, each as the table, row and key hash that name it (:class:`Found`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from nlcx.diff.cells import mix
from nlcx.diff.records import PENDING_BYTES, PENDING_ROWS, Tolerances
from nlcx.diff.rows import BASE, NEW, ColumnRoles, Rows, concat_rows, no_rows


@dataclass(order=True)
class Found:
    """A drift kept to be shown, before its row has its name (in :mod:`nlcx.diff.stream`):
    ``order`` is (row, column, table), the row of BASE for a cell or a missing row, of NEW for
    an extra row; ``side``, ``pos`` and ``key_hash``: the table, the row and the key hash that
    name it."""

    order: tuple[int, int, int]
    side: int = field(compare=False)
    pos: int = field(compare=False)
    key_hash: int = field(compare=False)
    column: str = field(compare=False)
    base: float | str = field(compare=False)
    new: float | str = field(compare=False)


@dataclass
class DriftTally:
    """The counts of one table's drifts and the first ``keep`` of them, in row order."""

    keep: int
    cells: int = 0
    missing: int = 0
    extra: int = 0
    kept: list[Found] = field(default_factory=list)
    #: The largest |new - base| of a drifting numeric cell (NaN: none yet).
    largest: float = math.nan
    #: The columns with a drifting cell.
    columns: set[str] = field(default_factory=set)

    def wants(self, pos: int) -> bool:
        """Whether a drift at row ``pos`` may be among the first ``keep``."""
        return len(self.kept) < self.keep or pos <= self.kept[-1].order[0]

    def offer(self, found: list[Found]) -> None:
        if found:
            self.kept = sorted(self.kept + found)[: self.keep]


def _drifting(base: np.ndarray, new: np.ndarray, rtol: np.ndarray | float, atol: np.ndarray | float) -> np.ndarray:
    """Which cells moved beyond atol + rtol |base|: NaN against NaN and an infinity against
    itself have not."""
    with np.errstate(invalid="ignore"):
        same = (base == new) | (np.isnan(base) & np.isnan(new))
        close = np.abs(new - base) <= atol + rtol * np.abs(base)
    return ~(same | close)


def _first_difference(base: list[pa.Array], new: list[pa.Array], n: int) -> int:
    """The first of ``n`` rows whose key differs between two tables (``n`` when none does)."""
    agree = np.ones(n, dtype=bool)
    for a, b in zip(base, new, strict=True):
        agree &= pc.equal(a, b).to_numpy(zero_copy_only=False)
    return n if agree.all() else int(np.argmin(agree))


def _occurrences(hashes: np.ndarray, own: Rows, other: Rows) -> np.ndarray:
    """The occurrence number of each of a table's coming rows of key ``hashes``, counted from
    the last point where both tables had seen that key equally often: past this table's rows
    that wait (``own``), or at the first row of the other table's that wait (``other``)."""
    keys = pd.Series(hashes)
    within = keys.groupby(keys, sort=False).cumcount().to_numpy(dtype=np.int64)
    return within + _starts(hashes, own, other)


def _starts(hashes: np.ndarray, own: Rows, other: Rows) -> np.ndarray:
    """Each coming row's first occurrence number: one past the last of its key among this
    table's rows that wait, or the first of its key among the other table's; else 0."""
    out = np.zeros(len(hashes), dtype=np.int64)
    for rows, last in ((own, True), (other, False)):
        if not len(rows):
            continue
        assert rows.hashes is not None and rows.occurrence is not None
        frame = pd.DataFrame({"key": rows.hashes, "occurrence": rows.occurrence})
        bound = frame.groupby("key", sort=True)["occurrence"].agg("max" if last else "min")
        keys, values = bound.index.to_numpy(dtype=np.uint64), bound.to_numpy(dtype=np.int64) + int(last)
        where = np.minimum(np.searchsorted(keys, hashes), len(keys) - 1)
        found = keys[where] == hashes
        out[found] = values[where[found]]
    return out


def _pairs(base: Rows, new: Rows) -> tuple[np.ndarray, np.ndarray]:
    """The rows of two tables with the same key and occurrence: their indices, in pairs."""
    assert base.hashes is not None and base.occurrence is not None
    assert new.hashes is not None and new.occurrence is not None
    ours = mix(base.hashes ^ mix(base.occurrence.astype(np.uint64)))
    theirs = mix(new.hashes ^ mix(new.occurrence.astype(np.uint64)))
    index = pd.Index(theirs)
    if not index.is_unique:  # two rows of a table share a 64-bit hash: practically never
        _, in_base, in_new = np.intersect1d(ours, theirs, return_indices=True)
        order = np.argsort(in_base)
        return in_base[order], in_new[order]
    where = index.get_indexer(ours)
    in_base = np.flatnonzero(where >= 0)
    return in_base, where[in_base]  # in BASE's order of rows: those that wait come first


def pending_cap(layout: ColumnRoles) -> int:
    """The rows that may wait at once: :data:`~nlcx.diff.records.PENDING_ROWS`, fewer where
    they would hold more than :data:`~nlcx.diff.records.PENDING_BYTES` (a row holds its place,
    key hash and occurrence, its numbers and tolerances, 8 bytes each, and its texts, 16)."""
    numbers = 3 + len(layout.numeric) + (2 if "metric" in layout.keys else 0)
    return max(1, min(PENDING_ROWS, PENDING_BYTES // (8 * numbers + 16 * len(layout.described))))


class Matcher:
    """Matches the rows of two tables and tallies their drifts (see the module's docstring).

    Parameters
    ----------
    name : str
        The table's relative path.
    layout : ColumnRoles
        The roles of its columns.
    tol : Tolerances
        The tolerances.
    keep : int
        Drifts kept to be shown.
    cap : int
        Rows that may wait for their match at once before matching stops.
    """

    def __init__(self, name: str, layout: ColumnRoles, tol: Tolerances, keep: int, cap: int) -> None:
        self.name, self.layout, self.tol, self.cap = name, layout, tol, cap
        self.tally = DriftTally(keep)
        per_row = "metric" in layout.keys
        self.waiting = [no_rows(layout, per_row), no_rows(layout, per_row)]
        self.done = [False, False]
        self.seen = [0, 0]
        self.stopped: tuple[int, int] | None = None

    @property
    def in_step(self) -> bool:
        """Whether both tables have seen the same keys equally often (no row waits)."""
        return not len(self.waiting[BASE]) and not len(self.waiting[NEW])

    def run(self, base: Iterator[Rows], new: Iterator[Rows]) -> None:
        """Compare every row of the two tables."""
        b, n = next(base, None), next(new, None)
        while b is not None and n is not None:
            m = min(len(b), len(n))
            self._in_pairs(b.slice(0, m), n.slice(0, m))
            b = b.slice(m, len(b)) if m < len(b) else next(base, None)
            n = n.slice(m, len(n)) if m < len(n) else next(new, None)
        side, rows, rest = (NEW, n, new) if b is None else (BASE, b, base)
        self.done[1 - side] = True
        while rows is not None:
            self._alone(side, rows)
            rows = next(rest, None)
        self.done[side] = True
        for s in (BASE, NEW):
            self._unmatched(s, self.waiting[s])
            self.waiting[s] = self.waiting[s].slice(0, 0)

    def _in_pairs(self, base: Rows, new: Rows) -> None:
        """The next ``len(base)`` rows of each table."""
        self._note_seen(BASE, base)
        self._note_seen(NEW, new)
        if self.stopped is not None:
            self._unmatched(BASE, base)
            self._unmatched(NEW, new)
            return
        if self.in_step:
            assert base.keys is not None and new.keys is not None
            agree = _first_difference(base.keys, new.keys, len(base)) if self.layout.keys else len(base)
            if agree:
                self._compare(base.slice(0, agree), new.slice(0, agree))
            if agree == len(base):
                return
            base, new = base.slice(agree, len(base)), new.slice(agree, len(new))
        self._match(base, new)

    def _alone(self, side: int, rows: Rows) -> None:
        """Rows of one table after the other's last row."""
        self._note_seen(side, rows)
        if self.stopped is not None or self.in_step:
            self._unmatched(side, rows)
            return
        coming = [rows, rows.slice(0, 0)] if side == BASE else [rows.slice(0, 0), rows]
        self._match(coming[BASE], coming[NEW])

    def _note_seen(self, side: int, rows: Rows) -> None:
        if len(rows):
            self.seen[side] = int(rows.pos[-1]) + 1

    def _match(self, base: Rows, new: Rows) -> None:
        """Match coming rows on (key, occurrence) with each other and with the rows that wait."""
        coming = [base, new]
        for side in (BASE, NEW):
            rows = coming[side]
            rows.hashes = rows.key_hashes()
            rows.occurrence = _occurrences(rows.hashes, self.waiting[side], self.waiting[1 - side])
        every = [concat_rows([self.waiting[s], coming[s]]) for s in (BASE, NEW)]
        self.waiting = [every[s].slice(0, 0) for s in (BASE, NEW)]  # held once, in ``every``
        in_base, in_new = _pairs(every[BASE], every[NEW])
        if len(in_base):
            self._compare(every[BASE].take(in_base), every[NEW].take(in_new))
        for side, matched in ((BASE, in_base), (NEW, in_new)):
            alone = np.ones(len(every[side]), dtype=bool)
            alone[matched] = False
            rest = every[side].take(np.flatnonzero(alone))
            if self.done[1 - side]:
                self._unmatched(side, rest)
                rest = rest.slice(0, 0)
            self.waiting[side] = rest
        if len(self.waiting[BASE]) + len(self.waiting[NEW]) > self.cap:
            self._stop()

    def _stop(self) -> None:
        """Too many rows wait: matching stops, and they and the rows after them are unmatched."""
        self.stopped = (self.seen[BASE], self.seen[NEW])
        for side in (BASE, NEW):
            self._unmatched(side, self.waiting[side])
            self.waiting[side] = self.waiting[side].slice(0, 0)

    def note(self) -> str | None:
        """The line that says matching stopped, if it did."""
        if self.stopped is None:
            return None
        base, new = self.stopped
        return (
            f"{self.name}: rows not matched after row {base:,} of BASE and row {new:,} of NEW: more than "
            f"{self.cap:,} rows waited for their match at once (the tables list their rows in different "
            "orders); those rows and the rest are counted as missing and extra rows"
        )

    def _unmatched(self, side: int, rows: Rows) -> None:
        """Rows of one table without a match in the other: missing (BASE's) or extra (NEW's)."""
        if not len(rows):
            return
        if side == BASE:
            self.tally.missing += len(rows)
        else:
            self.tally.extra += len(rows)
        if not self.tally.wants(int(rows.pos.min())):
            return
        first = np.argsort(rows.pos, kind="stable")[: self.tally.keep]
        hashes = rows.key_hashes(first)
        base, new = ("present", "missing in NEW") if side == BASE else ("", "extra in NEW")
        self.tally.offer(
            [
                Found((int(rows.pos[i]), -1, side), side, int(rows.pos[i]), int(h), "(row)", base, new)
                for i, h in zip(first, hashes, strict=True)
            ]
        )

    def _compare(self, base: Rows, new: Rows) -> None:
        """Compare matched rows (the k-th of ``base`` with the k-th of ``new``), cell by cell."""
        picked: list[tuple[int, str, float | str, float | str]] = []
        for j, column in enumerate(self.layout.numeric):
            rtol: np.ndarray | float
            atol: np.ndarray | float
            if base.rtol is not None and base.atol is not None:
                rtol, atol = base.rtol, base.atol
            else:
                rtol, atol = self.tol.of(column)
            bad = _drifting(base.values[j], new.values[j], rtol, atol)
            self._note_largest(base.values[j][bad], new.values[j][bad])
            for k in self._count(bad, base, column):
                picked.append((k, column, float(base.values[j][k]), float(new.values[j][k])))
        for j, column in enumerate(self.layout.described):
            bad = pc.not_equal(base.texts[j], new.texts[j]).to_numpy(zero_copy_only=False)
            for k in self._count(bad, base, column):
                picked.append((k, column, base.texts[j][k].as_py(), new.texts[j][k].as_py()))
        if not picked:
            return
        rows = np.array(sorted({k for k, *_ in picked}), dtype=np.int64)
        hashes = dict(zip(rows.tolist(), base.key_hashes(rows).tolist(), strict=True))
        self.tally.offer(
            [
                Found((int(base.pos[k]), self.layout.order(c), BASE), BASE, int(base.pos[k]), hashes[k], c, b, n)
                for k, c, b, n in picked
            ]
        )

    def _note_largest(self, base: np.ndarray, new: np.ndarray) -> None:
        """Keep the largest finite |new - base| of drifting cells."""
        if not base.size:
            return
        with np.errstate(invalid="ignore"):
            diff = np.abs(new - base)
        diff = diff[np.isfinite(diff)]
        if diff.size:
            largest = float(diff.max())
            self.tally.largest = largest if math.isnan(self.tally.largest) else max(self.tally.largest, largest)

    def _count(self, bad: np.ndarray, rows: Rows, column: str) -> list[int]:
        """Count the drifting cells ``bad`` of a column; those that may be kept (row indices)."""
        count = int(np.count_nonzero(bad))
        self.tally.cells += count
        if count:
            self.tally.columns.add(column)
        if not count or not self.tally.wants(int(rows.pos[0])):
            return []
        return [int(k) for k in np.flatnonzero(bad)[: self.tally.keep] if self.tally.wants(int(rows.pos[k]))]

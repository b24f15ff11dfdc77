"""The runs whose statuses changed between two tables, for ``nlcx diff``: each table's runs
and statuses (:class:`RunPairs`, :class:`RunStatuses`), the runs that changed
(:func:`status_changes`), and their rows left out (:class:`RunFilter`).

While the rows are read (:func:`~nlcx.diff.rows.rows_of`), each table's distinct (run, status)
pairs are gathered as 64-bit hashes (:class:`RunPairs`, at most
:data:`~nlcx.diff.records.STATUS_RUNS`), with the row where each first appears; a run's
statuses, in that order, make its signature (:class:`RunStatuses`). A run of both tables whose
signatures differ changed its status: its rows are left out when the rows are read again
(:class:`RunFilter`), which picks up the texts of the runs shown from their rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pyarrow as pa

from nlcx.diff.cells import hash_rows, mix
from nlcx.diff.records import Drift

#: Distinct (run, status) pairs held before they are merged again (and more, as they grow).
_MERGE_PAIRS = 1 << 16


@dataclass
class RunStatuses:
    """Each run of one table and its distinct statuses, in the order they first appear.

    Attributes
    ----------
    runs : numpy.ndarray
        uint64 run hashes, sorted.
    first : numpy.ndarray
        int64: the row where each run first appears.
    signature : numpy.ndarray
        uint64: a hash of each run's statuses, in order.
    starts : numpy.ndarray
        Where each run's statuses start in ``statuses`` (one more entry: the end).
    statuses : numpy.ndarray
        uint64 status hashes, run by run.
    """

    runs: np.ndarray
    first: np.ndarray
    signature: np.ndarray
    starts: np.ndarray
    statuses: np.ndarray

    @classmethod
    def of(cls, run: np.ndarray, status: np.ndarray, first: np.ndarray) -> RunStatuses:
        """From the distinct (run, status) pairs and the row where each first appears."""
        order = np.lexsort((first, run))
        run, status, first = run[order], status[order], first[order]
        heads = np.flatnonzero(np.r_[True, run[1:] != run[:-1]]) if len(run) else np.zeros(0, np.int64)
        starts = np.r_[heads, len(run)].astype(np.int64)
        rank = np.arange(len(run)) - np.repeat(heads, np.diff(starts))
        terms = mix(status ^ mix(rank.astype(np.uint64) + np.uint64(1)))
        signature = np.add.reduceat(terms, heads) if len(run) else np.zeros(0, np.uint64)
        return cls(run[heads], first[heads], signature.astype(np.uint64), starts, status)

    def of_run(self, index: int) -> list[int]:
        """The status hashes of the ``index``-th run, in order."""
        return [int(s) for s in self.statuses[self.starts[index] : self.starts[index + 1]]]


class RunPairs:
    """The distinct (run, status) pairs of one table and the row where each first appears,
    gathered a chunk at a time (at most ``cap`` of them: beyond, :meth:`runs` is None).

    Each chunk's pairs are told apart on a hash of the pair; the pairs gathered are merged
    again (their repeats dropped) whenever they have grown by half since the last merge."""

    def __init__(self, cap: int) -> None:
        self.cap = cap
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.held = self.merged = 0
        self.over = False

    def add(self, run: np.ndarray, status: np.ndarray, pos: np.ndarray) -> None:
        """The run and status hashes of rows at places ``pos``."""
        if self.over:
            return
        first = ~pd.Series(_pair_hashes(run, status)).duplicated().to_numpy()
        self.parts.append((run[first], status[first], pos[first]))
        self.held += int(np.count_nonzero(first))
        if self.held > self.merged + max(self.merged // 2, _MERGE_PAIRS):
            self._merge()

    def _merge(self) -> None:
        if len(self.parts) > 1:
            run, status, first = (np.concatenate([part[i] for part in self.parts]) for i in range(3))
            _, index = np.unique(_pair_hashes(run, status), return_index=True)
            index.sort()
            self.parts = [(run[index], status[index], first[index])]
        self.held = self.merged = len(self.parts[0][0]) if self.parts else 0
        if self.merged > self.cap:
            self.over, self.parts = True, []

    def runs(self) -> RunStatuses | None:
        """The runs and their statuses; None beyond ``cap`` pairs."""
        self._merge()
        if self.over:
            return None
        if not self.parts:
            return RunStatuses.of(np.zeros(0, np.uint64), np.zeros(0, np.uint64), np.zeros(0, np.int64))
        return RunStatuses.of(*self.parts[0])


def _pair_hashes(run: np.ndarray, status: np.ndarray) -> np.ndarray:
    """A uint64 hash of each (run, status) pair."""
    return mix(run ^ mix(status))


@dataclass
class StatusChange:
    """A run whose statuses changed: its hash, its statuses' hashes in BASE and NEW, its text."""

    run: int
    base: list[int]
    new: list[int]
    text: str | None = None


@dataclass
class RunFilter:
    """The runs whose statuses changed: their rows are left out, and the texts of the first
    :data:`~nlcx.diff.records.KEEP_STATUS` of them are picked up from their rows.

    Attributes
    ----------
    changed : numpy.ndarray
        uint64 hashes of the runs that changed, sorted.
    shown : dict
        The runs kept to be shown, by hash, in BASE's order.
    status_texts : dict
        The text of each status hash of the runs shown, once seen.
    """

    changed: np.ndarray
    shown: dict[int, StatusChange]
    status_texts: dict[int, str] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """Whether every text of the runs shown is known."""
        needed = {s for change in self.shown.values() for s in (*change.base, *change.new)}
        return all(c.text is not None for c in self.shown.values()) and needed <= self.status_texts.keys()

    def rows_kept(self, run_keys: list[pa.Array], statuses: list[pa.Array], n: int) -> np.ndarray:
        """Which of ``n`` rows do not belong to a run whose statuses changed (picking up the
        texts of the runs shown from their rows)."""
        run = hash_rows(run_keys, n)
        where = np.minimum(np.searchsorted(self.changed, run), len(self.changed) - 1)
        changed = self.changed[where] == run
        if changed.any() and not self.complete:
            self._pick_texts(run, run_keys, statuses)
        return ~changed

    def _pick_texts(self, run: np.ndarray, run_keys: list[pa.Array], statuses: list[pa.Array]) -> None:
        shown = np.fromiter(self.shown, dtype=np.uint64, count=len(self.shown))
        rows = np.flatnonzero(np.isin(run, shown))
        if not len(rows):
            return
        distinct, first = np.unique(run[rows], return_index=True)
        for value, row in zip(distinct, rows[first], strict=True):
            change = self.shown[int(value)]
            if change.text is None:
                change.text = " | ".join(k[int(row)].as_py() for k in run_keys) if run_keys else "(all rows)"
        index = pa.array(rows, pa.int64())
        hashes = hash_rows([s.take(index) for s in statuses], len(rows))
        distinct, first = np.unique(hashes, return_index=True)
        for value, row in zip(distinct, rows[first], strict=True):
            self.status_texts.setdefault(int(value), " | ".join(s[int(row)].as_py() for s in statuses))

    def drifts(self, name: str, status: list[str]) -> list[Drift]:
        """The status changes kept to be shown: ``RUN  status: ok -> unstable`` (``status``:
        the status columns, :attr:`~nlcx.diff.rows.ColumnRoles.status`)."""
        column = " | ".join(status)

        def text(hashes: list[int]) -> str:
            return " / ".join(self.status_texts.get(h, "?") for h in hashes)

        return [
            Drift(name, c.text or "?", column, text(c.base), text(c.new), status_change=True)
            for c in self.shown.values()
        ]


def status_changes(base: RunStatuses, new: RunStatuses, keep: int) -> RunFilter:
    """The runs of both tables whose statuses differ; the first ``keep`` of them in BASE's
    order kept to be shown."""
    common, in_base, in_new = np.intersect1d(base.runs, new.runs, assume_unique=True, return_indices=True)
    differ = base.signature[in_base] != new.signature[in_new]
    in_base, in_new = in_base[differ], in_new[differ]
    order = np.argsort(base.first[in_base], kind="stable")[:keep]
    shown = {
        int(base.runs[in_base[k]]): StatusChange(
            int(base.runs[in_base[k]]), base.of_run(int(in_base[k])), new.of_run(int(in_new[k]))
        )
        for k in order
    }
    return RunFilter(np.sort(common[differ]), shown)

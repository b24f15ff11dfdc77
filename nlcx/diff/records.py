"""What ``nlcx diff`` finds and the rules it keeps: tolerances, drifts, each table's count of
them, the roles of the text columns and the limits on what is held in memory.

:mod:`nlcx.diff` describes the comparison and re-exports these names.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

#: Text columns that describe a row rather than identify it: compared as cells.
DESCRIPTIVE = ("note", "message", "reason")
#: Text columns that tell the rows of one run apart; the other key columns identify the run.
ROW_KEYS = ("signal", "metric", "unit")
#: Drifts kept to be shown per file (cells and rows); the others are counted.
KEEP = 10
#: Status changes kept to be shown per file; the others are counted.
KEEP_STATUS = 50
#: Rows that may wait for their match at once (both tables together) before matching stops.
PENDING_ROWS = 1_000_000
#: Bytes those rows may hold at once (fewer rows of a wide table wait): 8 a number, 16 a text.
PENDING_BYTES = 128 << 20
#: Distinct (run, status) pairs of one table beyond which statuses are compared row by row.
STATUS_RUNS = 1_000_000


@dataclass
class Tolerances:
    """Relative and absolute tolerances by metric name; ``default`` for the others."""

    rtol: dict[str, float] = field(default_factory=lambda: {"default": 1e-6})
    atol: dict[str, float] = field(default_factory=lambda: {"default": 1e-9})

    def of(self, metric: str) -> tuple[float, float]:
        """The (rtol, atol) of ``metric``."""
        return self.rtol.get(metric, self.rtol["default"]), self.atol.get(metric, self.atol["default"])


@dataclass
class Drift:
    """One drift: a cell that moved, a row missing or extra, a run's changed status.

    Attributes
    ----------
    file : str
        The table's relative path.
    key : str
        The row (``KEY`` or ``KEY #k``, the k-th row of a repeated key), or the run of a
        status change, or ``(file)`` / ``(columns)``.
    column : str
        The column; ``(row)`` for a missing or extra row.
    base, new : float or str
        The cell in BASE and in NEW.
    status_change : bool
        Whether this is a run's changed status (see :mod:`nlcx.diff`).
    """

    file: str
    key: str
    column: str
    base: float | str
    new: float | str
    status_change: bool = False

    @property
    def abs_diff(self) -> float:
        """|new - base|; NaN for text."""
        try:
            return abs(float(self.new) - float(self.base))
        except (TypeError, ValueError):
            return math.nan


@dataclass
class FileDrift:
    """What changed in one table: exact counts, and the first drifts kept to be shown.

    Attributes
    ----------
    file : str
        The table's relative path.
    cells : int
        Cells beyond their tolerance (numbers) or changed (notes, statuses of unchanged runs).
    status_changes, missing_rows, extra_rows : int
        Runs whose statuses changed; rows of BASE without a match in NEW; rows of NEW without one.
    tables : int
        1 when the table itself differs: missing in NEW, or other columns.
    first : list of Drift
        The first drifts other than status changes, in row order (at most :data:`KEEP`).
    statuses : list of Drift
        The first status changes, in BASE's order of runs (at most :data:`KEEP_STATUS`).
    notes : list of str
        One line for each limit reached (matching stopped, statuses compared row by row).
    largest : float
        The largest |new - base| of the numeric cells that drifted (NaN where none did, or
        where each of them is NaN on one side).
    identical : bool
        The two tables are the same bytes: they were not parsed.
    columns : list of str
        The columns with a drifted cell, in the table's order.
    """

    file: str
    cells: int = 0
    status_changes: int = 0
    missing_rows: int = 0
    extra_rows: int = 0
    tables: int = 0
    first: list[Drift] = field(default_factory=list)
    statuses: list[Drift] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    largest: float = math.nan
    identical: bool = False
    columns: list[str] = field(default_factory=list)

    @property
    def total(self) -> int:
        """Every drift of the table, status changes included."""
        return self.cells + self.status_changes + self.missing_rows + self.extra_rows + self.tables


def is_status_column(column: str) -> bool:
    """``status`` and ``<something>_status`` (e.g. the thesis tables' ``nlcx_status``)."""
    return column == "status" or column.endswith("_status")


def status_columns(columns: Sequence[str]) -> list[str]:
    """The status columns of ``columns`` (:func:`is_status_column`), in order."""
    return [c for c in columns if is_status_column(c)]

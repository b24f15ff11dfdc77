"""What the engine returns: runs, their metric rows, an experiment's result."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from nlcx.controllers.base import ControllerInstance

if TYPE_CHECKING:
    import pandas as pd

    from nlcx.engine.prepared import Prepared

#: The columns of a metric row (after the column ``experiment`` of a shared table).
METRIC_COLUMNS = ["controller", "signal", "metric", "value", "unit", "status", "note"]


@dataclass
class Run:
    """One controller's closed-loop run, truncated where it diverged."""

    controller: ControllerInstance
    status: str
    reason: str
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    r: np.ndarray
    #: Controller logs and friction forces (None when the simulation did not record them).
    log: np.ndarray | None
    friction: np.ndarray | None
    t_fail: float = math.nan

    @property
    def label(self) -> str:
        return self.controller.label


@dataclass(frozen=True)
class MetricTable:
    """The long-form metric rows of experiments measured together: the column ``experiment``
    (an experiment's position in the measured list), then :data:`METRIC_COLUMNS`; each
    experiment's rows contiguous. The rows are computed when the runs are measured; the
    DataFrame (and the pandas import it needs) only when :attr:`frame` is first read. ``nlcx
    run`` never reads it: it writes metrics.csv from the rows (:attr:`ExperimentResult.metric_rows`)."""

    rows: list[list[Any]]

    @functools.cached_property
    def frame(self) -> pd.DataFrame:
        import pandas as pd

        return pd.DataFrame(self.rows, columns=["experiment", *METRIC_COLUMNS])


class MetricBlock(NamedTuple):
    """An experiment's metric rows: rows ``start`` to ``stop`` (excluded) of a shared ``table``."""

    table: MetricTable
    start: int
    stop: int


@dataclass
class ExperimentResult:
    """One experiment's runs and metrics. The metrics are a block of rows of a table shared
    by the experiments measured together (``rows``: the table and its row range), sliced
    out only when :attr:`metrics` is read (a sweep reads the shared tables instead)."""

    prepared: Prepared
    runs: list[Run]
    rows: MetricBlock | None = None
    timings: dict[str, float] = field(default_factory=dict)

    @functools.cached_property
    def metrics(self) -> pd.DataFrame:
        """Long-form metrics of the runs (columns :data:`METRIC_COLUMNS`)."""
        if self.rows is None:
            import pandas as pd

            return pd.DataFrame(columns=METRIC_COLUMNS)
        block = self.rows
        return block.table.frame.iloc[block.start : block.stop][METRIC_COLUMNS].reset_index(drop=True)

    @property
    def metric_rows(self) -> list[list[Any]]:
        """The rows of :attr:`metrics` as lists of their :data:`METRIC_COLUMNS` values, without
        building a DataFrame."""
        if self.rows is None:
            return []
        block = self.rows
        return [row[1:] for row in block.table.rows[block.start : block.stop]]


def shared_metrics(results: list[ExperimentResult]) -> pd.DataFrame:
    """The metrics of ``results`` (from one :func:`~nlcx.engine.evaluate` call) in one table, with the
    column ``experiment``: the position of the row's result in ``results``, ascending."""
    import pandas as pd

    tables = {id(r.rows.table): r.rows.table.frame for r in results if r.rows is not None}
    if not tables:
        return pd.DataFrame(columns=["experiment", *METRIC_COLUMNS])
    table = pd.concat(list(tables.values()), ignore_index=True)
    return table.sort_values("experiment", kind="stable", ignore_index=True)

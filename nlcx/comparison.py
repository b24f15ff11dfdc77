"""Controllers side by side: each controller's metrics per signal and the improvement % of each
later controller over the first, by the thesis's formula.

The thesis compares a conventional controller with a proposed one by
``(conventional - proposed) / proposed x 100``: a positive % means the proposed controller has
the smaller value (e.g. a shorter rise time, a smaller ISE). :func:`compare` applies it to a
long-form metrics frame (``metrics.csv``) with the first controller in the role of the
conventional one; :func:`comparison` is the same table without pandas (the report of a run
uses it, so that ``nlcx run`` never imports pandas).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

from nlcx.errors import NlcxError, did_you_mean

if TYPE_CHECKING:
    import pandas as pd

#: The metrics the thesis's tables compare: step characteristics (a signal regulated to 0 has
#: its peak deviation instead of overshoot and peak) and the error integrals.
THESIS_METRICS: tuple[str, ...] = (
    "rise_time",
    "settling_time",
    "overshoot",
    "peak",
    "peak_deviation",
    "ise",
    "iae",
    "itae",
)
#: The columns a metrics frame must have (``unit``, ``status`` and ``note`` are optional).
REQUIRED = ("controller", "signal", "metric", "value")


def improvement(first: float, other: float) -> float:
    """The thesis's improvement % of ``other`` over ``first``: ``(first - other) / other x 100``.

    Parameters
    ----------
    first
        The value of the reference controller (the thesis's conventional one).
    other
        The value of the controller compared with it (the thesis's proposed one).

    Returns
    -------
    float
        Positive when ``other`` is the smaller value; NaN where the formula is undefined
        (``other`` is 0 or NaN, or ``first`` is NaN).

    Examples
    --------
    An overshoot of 40 % against one of 25 %: the second is 60 % better by the thesis's measure.

    >>> from nlcx import improvement
    >>> improvement(40.0, 25.0)
    60.0
    >>> improvement(1.0, 0.0)
    nan
    """
    if math.isnan(other) or other == 0 or math.isnan(first):
        return math.nan
    return float((first - other) / other * 100.0)


@dataclass(frozen=True)
class Row:
    """One (signal, metric) of a comparison: each controller's value and the improvements."""

    signal: str
    metric: str
    unit: str
    #: One value per controller, in the comparison's controller order (NaN: not measured).
    values: tuple[float, ...]

    @property
    def improvements(self) -> tuple[float, ...]:
        """The improvement % of each controller after the first over the first."""
        return tuple(improvement(self.values[0], v) for v in self.values[1:])


@dataclass(frozen=True)
class Comparison:
    """Controllers side by side: their order, each one's run status and the compared rows."""

    controllers: tuple[str, ...]
    #: Controller -> the status of its run (``ok`` unless a row of it says otherwise).
    status: dict[str, str]
    #: Controller -> why its run is not ok (the note of its first row that is not ok; '' if ok).
    reasons: dict[str, str]
    rows: tuple[Row, ...]

    def signals(self) -> list[str]:
        """The compared signals, in the order of the rows."""
        return list(dict.fromkeys(r.signal for r in self.rows))


def _text(value: Any) -> str:
    """A text field as written ('' for a missing one: None or pandas' NaN)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return str(value)


def _float(value: Any) -> float:
    """A value as a float (NaN for a missing or empty one)."""
    if value is None or value == "":
        return math.nan
    return float(value)


def _selected(records: list[Mapping[str, Any]], names: Sequence[str] | str | None) -> tuple[str, ...]:
    """The metric names to compare: ``names`` checked against the metrics present, or the
    thesis's metrics that are present."""
    present = list(dict.fromkeys(_text(r["metric"]) for r in records))
    if names is None:
        return tuple(m for m in THESIS_METRICS if m in present)
    wanted = (names,) if isinstance(names, str) else tuple(names)
    unknown = [n for n in wanted if n not in present]
    if unknown:
        raise NlcxError(
            f"compare: names = {unknown!r} are not metrics of this frame{did_you_mean(unknown[0], present)}; "
            f"allowed: {', '.join(present) or '(none)'}"
        )
    return wanted


def _check_columns(columns: Iterable[str]) -> None:
    missing = [c for c in REQUIRED if c not in set(columns)]
    if missing:
        raise NlcxError(
            f"compare: metrics lacks the columns {missing!r}; a metrics.csv frame has {', '.join(REQUIRED)}"
        )


def comparison(records: Iterable[Mapping[str, Any]], names: Sequence[str] | str | None = None) -> Comparison:
    """The comparison of long-form metric records (the rows of ``metrics.csv`` as mappings).

    Parameters
    ----------
    records
        Rows with ``controller``, ``signal``, ``metric`` and ``value`` (``unit``, ``status``
        and ``note`` when present), as :func:`compare` takes them.
    names
        The metrics to compare; None: those of :data:`THESIS_METRICS` that are present.

    Returns
    -------
    Comparison
        Controllers in order of first appearance; rows grouped by signal (signals in order of
        first appearance), each signal's metrics in order of first appearance. A value is NaN
        where the controller has no row for it or its row's status is not ``ok`` (a run that
        stopped has no comparable response).

    Raises
    ------
    NlcxError
        A required column is missing, ``names`` holds a metric the records lack, or a
        (controller, signal, metric) appears twice (e.g. the variants of a sweep).
    """
    rows = list(records)
    if rows:
        _check_columns(rows[0].keys())
    selected = set(_selected(rows, names))
    controllers = tuple(dict.fromkeys(_text(r["controller"]) for r in rows))
    status = dict.fromkeys(controllers, "ok")
    reasons = dict.fromkeys(controllers, "")
    values: dict[tuple[str, str, str], float] = {}
    units: dict[tuple[str, str], str] = {}
    for r in rows:
        controller, signal, metric = _text(r["controller"]), _text(r["signal"]), _text(r["metric"])
        state = _text(r.get("status", "ok")) or "ok"
        if state != "ok" and status[controller] == "ok":
            status[controller], reasons[controller] = state, _text(r.get("note"))
        if metric not in selected:
            continue
        key = (controller, signal, metric)
        if key in values:
            raise NlcxError(
                f"compare: (controller, signal, metric) = {key!r} appears twice; allowed: one run's metrics "
                "(select one variant of a sweep first)"
            )
        values[key] = _float(r["value"]) if state == "ok" else math.nan
        units.setdefault((signal, metric), "")
        units[(signal, metric)] = units[(signal, metric)] or _text(r.get("unit"))
    signals = list(dict.fromkeys(s for s, _ in units))
    order = [(s, m) for s in signals for (s2, m) in units if s2 == s]
    return Comparison(
        controllers,
        status,
        reasons,
        tuple(Row(s, m, units[(s, m)], tuple(values.get((c, s, m), math.nan) for c in controllers)) for s, m in order),
    )


def compare(metrics: pd.DataFrame, names: Sequence[str] | None = None) -> pd.DataFrame:
    """Controllers side by side, per signal and metric, with the thesis's improvement %.

    Parameters
    ----------
    metrics
        A long-form metrics frame as ``metrics.csv`` holds it: columns ``controller``,
        ``signal``, ``metric``, ``value``, ``unit``, ``status``, ``note`` (the last three
        optional), one run's rows.
    names
        The metrics to compare, exactly these; None: those of :data:`THESIS_METRICS` present.

    Returns
    -------
    pandas.DataFrame
        Indexed by (signal, metric): signals in order of first appearance, each signal's
        metrics in order of first appearance. Columns: ``unit``; one float column per
        controller (in order of first appearance; NaN where it has no value or its run's
        status is not ``ok``); ``improvement_<controller>_pct`` for each controller after the
        first: ``(first - controller) / controller x 100``, positive where that controller has
        the smaller value.

    Raises
    ------
    NlcxError
        A required column is missing, ``names`` holds a metric the frame lacks, or a
        (controller, signal, metric) appears twice.

    Examples
    --------
    >>> import pandas as pd
    >>> from nlcx.comparison import compare
    >>> metrics = pd.DataFrame({
    ...     "controller": ["conventional", "conventional", "proposed", "proposed"],
    ...     "signal": ["x", "x", "x", "x"],
    ...     "metric": ["rise_time", "ise", "rise_time", "ise"],
    ...     "value": [2.0, 0.5, 1.6, 0.4],
    ...     "unit": ["s", "m^2*s", "s", "m^2*s"],
    ...     "status": ["ok"] * 4,
    ...     "note": [""] * 4,
    ... })
    >>> table = compare(metrics)
    >>> table[["unit", "conventional", "proposed"]]  # doctest: +NORMALIZE_WHITESPACE
                       unit  conventional  proposed
    signal metric
    x      rise_time      s           2.0       1.6
           ise        m^2*s           0.5       0.4

    The proposed controller rises in 1.6 s instead of 2.0 s: (2.0 - 1.6) / 1.6 x 100 = 25 %.

    >>> table["improvement_proposed_pct"].round(6).tolist()
    [25.0, 25.0]
    """
    import pandas as pd

    _check_columns(metrics.columns)
    records = cast("list[dict[str, Any]]", metrics.to_dict("records"))  # its columns are named by strings
    table = comparison(records, names)
    index = pd.MultiIndex.from_tuples([(r.signal, r.metric) for r in table.rows], names=["signal", "metric"])
    columns: dict[str, list[Any]] = {"unit": [r.unit for r in table.rows]}
    for k, controller in enumerate(table.controllers):
        columns[controller] = [r.values[k] for r in table.rows]
    for k, controller in enumerate(table.controllers[1:]):
        columns[f"improvement_{controller}_pct"] = [r.improvements[k] for r in table.rows]
    frame = pd.DataFrame(columns, index=index)
    return frame.astype({c: float for c in columns if c != "unit"})

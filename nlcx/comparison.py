"""Controllers side by side: each controller's metrics per signal, the change % of each later
controller against the first (the baseline), and which controller is better on each metric.

The change % of a controller is ``100 (other - baseline) / |baseline|`` (:func:`change`):
negative where the other controller has the smaller value. Which value is better follows the
metric's direction (:data:`DIRECTIONS`: smaller is better for the times, the overshoot, the
errors and the control effort). :func:`compare` gives the table as a
:class:`~nlcx.comparison_frame.Comparison` (a pandas DataFrame); :func:`comparison` is the
same table without pandas (the report of a run uses it, so that ``nlcx run`` never imports
pandas).

The thesis's tables compare by another formula, ``(conventional - proposed) / proposed x 100``
(:func:`thesis_improvement`); only the reproduction of those tables uses it.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from nlcx.errors import NlcxError, did_you_mean

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

#: A direction: the smaller value is the better one.
SMALLER = "smaller"
#: A direction: the value nearer 0 (the smaller magnitude) is the better one.
NEARER_ZERO = "nearer 0"

#: Which value of a metric is the better one, from its definition (docs/metrics.md): smaller
#: for the times to rise and to settle, the overshoot and undershoot, the peak deviation of a
#: regulated signal, every error metric (:data:`nlcx.metrics.names.ERROR_METRICS`) and every
#: metric of the control input (:data:`nlcx.metrics.names.INPUT_METRICS`: effort, peak, total
#: variation); nearer 0 for the signed steady-state error. A metric not named here has no
#: better value (:data:`UNDIRECTED`) and gets no ``better`` marker. (The names are written out
#: so that comparing imports none of :mod:`nlcx.metrics`' compiled code; tests/test_compare_frame.py
#: holds them to :data:`nlcx.metrics.names.METRIC_UNITS`.)
DIRECTIONS: dict[str, str] = {
    # step_response_metrics, regulation_metrics
    "rise_time": SMALLER,
    "settling_time": SMALLER,
    "overshoot": SMALLER,
    "undershoot": SMALLER,
    "peak_deviation": SMALLER,
    "steady_state_error": NEARER_ZERO,
    # error_integrals
    "ise": SMALLER,
    "iae": SMALLER,
    "itae": SMALLER,
    "max_abs_error": SMALLER,
    "rms_error": SMALLER,
    # input_metrics
    "control_effort": SMALLER,
    "peak_input": SMALLER,
    "total_variation": SMALLER,
}
#: The metrics that have no better value: ``peak`` (a value of the signal, which a step up and
#: a step down reach from opposite sides), ``peak_time`` (a response without overshoot peaks
#: at the end of its record, which is no worse than an early peak), the final value and the
#: extremes after the rise of :func:`nlcx.metrics.step_info`, and ``t_fail`` (the time a run
#: stopped: a run that stopped is not compared at all).
UNDIRECTED: tuple[str, ...] = ("peak", "peak_time", "steady_state_value", "settling_min", "settling_max", "t_fail")

#: The ``better`` marker where several controllers share the best value.
TIE = "tie"


def change(baseline: float, other: float) -> float:
    """The change % of ``other`` against ``baseline``: ``100 (other - baseline) / |baseline|``.

    Parameters
    ----------
    baseline
        The value of the first controller of a comparison.
    other
        The value of the controller compared with it.

    Returns
    -------
    float
        Negative where ``other`` is the smaller value, positive where it is the larger; NaN
        where the formula is undefined (``baseline`` is 0, or either value is NaN).

    Examples
    --------
    An overshoot of 25 % against a baseline of 40 %: 37.5 % less.

    >>> from nlcx.comparison import change
    >>> change(40.0, 25.0)
    -37.5
    >>> change(-2.0, -1.0)  # a steady-state error of -1 against -2: 50 % larger (nearer 0)
    50.0
    >>> change(0.0, 1.0)
    nan
    """
    if math.isnan(baseline) or math.isnan(other) or baseline == 0:
        return math.nan
    return float(100.0 * (other - baseline) / abs(baseline))


def thesis_improvement(first: float, other: float) -> float:
    """The thesis's improvement % of ``other`` over ``first``: ``(first - other) / other x 100``,
    as the thesis's tables print it (docs/metrics.md: its denominator is ``other``).

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

    >>> from nlcx import thesis_improvement
    >>> thesis_improvement(40.0, 25.0)
    60.0
    >>> thesis_improvement(1.0, 0.0)
    nan
    """
    if math.isnan(other) or other == 0 or math.isnan(first):
        return math.nan
    return float((first - other) / other * 100.0)


#: The metrics that are the time of an event (docs/metrics.md): undefined (NaN) on a run that
#: went on to its end, the event did not happen within the record, which is worse than any
#: time it did happen at.
EVENT_TIMES: tuple[str, ...] = ("rise_time", "settling_time")


def better(metric: str, values: Mapping[str, float], stopped: Collection[str] = ()) -> str:
    """Which controller has the better value of ``metric`` (:data:`DIRECTIONS`).

    Parameters
    ----------
    metric
        The metric's name.
    values
        Controller -> its value (NaN: undefined, or its run stopped).
    stopped
        The controllers whose run stopped (status not ``ok``): not compared.

    Returns
    -------
    str
        The controller with the better value; :data:`TIE` where several share it; ``""`` where
        the metric has no direction or fewer than two controllers are compared. A controller
        is compared where it has a value, and for a time of an event (:data:`EVENT_TIMES`)
        also where its run went on but the event never happened: such a NaN ranks last.

    Examples
    --------
    >>> import math
    >>> from nlcx.comparison import better
    >>> better("overshoot", {"conventional": 28.3, "proposed": 12.1})
    'proposed'
    >>> better("steady_state_error", {"a": -0.02, "b": 0.01})
    'b'
    >>> better("settling_time", {"a": math.nan, "b": 9.9})  # a never settled
    'b'
    >>> better("settling_time", {"a": math.nan, "b": 9.9}, stopped={"a"})  # a's run stopped
    ''
    >>> better("peak", {"a": 1.2, "b": 1.1})
    ''
    """
    direction = DIRECTIONS.get(metric)
    ran = {c: v for c, v in values.items() if c not in stopped}
    measured = {c: v for c, v in ran.items() if not math.isnan(v)}
    compared = ran if metric in EVENT_TIMES and measured else measured
    if direction is None or len(compared) < 2:
        return ""
    score = {c: math.inf if math.isnan(v) else abs(v) if direction == NEARER_ZERO else v for c, v in compared.items()}
    best = min(score.values())
    winners = [c for c, v in score.items() if v == best]
    return winners[0] if len(winners) == 1 else TIE


@dataclass(frozen=True)
class Row:
    """One (signal, metric) of a comparison: each controller's value, the change % of each
    later one against the first and the better controller."""

    signal: str
    metric: str
    unit: str
    #: One value per controller, in the comparison's controller order (NaN: not measured).
    values: tuple[float, ...]
    #: The controller with the better value, :data:`TIE`, or "" (:func:`better`).
    better: str = ""

    @property
    def changes(self) -> tuple[float, ...]:
        """The change % of each controller after the first against the first (:func:`change`)."""
        return tuple(change(self.values[0], v) for v in self.values[1:])


@dataclass(frozen=True)
class SideBySide:
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

    def verdicts(self) -> list[str]:
        """One line per signal: which controller is better on how many of its metrics
        (:func:`verdict`); none for fewer than two controllers."""
        if len(self.controllers) < 2:
            return []
        stopped = {c: s for c, s in self.status.items() if s != "ok"}
        return [
            verdict(s, self.controllers, [r.better for r in self.rows if r.signal == s], stopped)
            for s in self.signals()
        ]


def verdict(
    signal: str, controllers: Sequence[str], markers: Sequence[str], stopped: Mapping[str, str] | None = None
) -> str:
    """One signal's line: how many of its metrics each controller is better on.

    Parameters
    ----------
    signal
        The signal's name.
    controllers
        Every controller compared, in order.
    markers
        The ``better`` marker of each of the signal's metrics (a controller, :data:`TIE` or "").
    stopped
        Controller -> its run's status, for the controllers whose run stopped (not compared).

    Returns
    -------
    str
        The controllers that ran from the most metrics to the fewest (ties in their order),
        counted over the metrics that have a marker; the ties, if any; the controllers whose
        run stopped, with their status, last.

    Examples
    --------
    >>> from nlcx.comparison import verdict
    >>> verdict("x", ["conventional", "proposed"], ["proposed"] * 5 + ["conventional"] * 2 + [""])
    'x: proposed better on 5 of 7 metrics, conventional on 2'
    >>> verdict("x", ["a", "b", "c"], ["b", "b", "a"], {"c": "unstable"})
    'x: b better on 2 of 3 metrics, a on 1, c unstable'
    >>> verdict("theta", ["a", "b"], ["", ""], {"a": "unstable"})
    'theta: no metric compared, a unstable'
    """
    stopped = dict(stopped or {})
    last = "".join(f", {c} {s}" for c, s in stopped.items())
    marked = [m for m in markers if m]
    if not marked:
        why = last or " (none has a direction and a value of two controllers)"
        return f"{signal}: no metric compared{why}"
    counts = {c: marked.count(c) for c in controllers if c not in stopped}
    ordered = sorted(counts, key=lambda c: -counts[c])
    first, rest = ordered[0], ordered[1:]
    noun = "metric" if len(marked) == 1 else "metrics"
    parts = [f"{first} better on {counts[first]} of {len(marked)} {noun}", *(f"{c} on {counts[c]}" for c in rest)]
    ties = marked.count(TIE)
    if ties:
        parts.append(f"tied on {ties}")
    return f"{signal}: " + ", ".join(parts) + last


def _text(value: object) -> str:
    """A text field as written ('' for a missing one: None or pandas' NaN)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return str(value)


def _float(value: Any) -> float:
    """A value as a float (NaN for a missing or empty one): a number, or its text as a CSV file holds it."""
    if value is None or value == "":
        return math.nan
    return float(value)


def _selected(records: list[Mapping[str, object]], names: Sequence[str] | str | None) -> tuple[str, ...]:
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


def check_columns(columns: Iterable[str]) -> None:
    missing = [c for c in REQUIRED if c not in set(columns)]
    if missing:
        raise NlcxError(
            f"compare: metrics lacks the columns {missing!r}; a metrics.csv frame has {', '.join(REQUIRED)}"
        )


def comparison(records: Iterable[Mapping[str, object]], names: Sequence[str] | str | None = None) -> SideBySide:
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
    SideBySide
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
        check_columns(rows[0].keys())
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
    compared = []
    for s, m in order:
        row_values = {c: values.get((c, s, m), math.nan) for c in controllers}
        marker = better(m, row_values, stopped=[c for c in controllers if status[c] != "ok"])
        compared.append(Row(s, m, units[(s, m)], tuple(row_values.values()), marker))
    return SideBySide(controllers, status, reasons, tuple(compared))

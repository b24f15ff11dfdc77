"""The kinds of check a claim is made of: one evaluator each, registered by name in :data:`KINDS`.

A check reads cells of the runs behind thesis figures and tables (a :class:`ClaimRun` each): the
``metric`` of each of its ``signals`` under each of its ``controllers``. Its evaluator says
whether it holds and gives the numbers it looked at (the evidence). The limits it compares
against are named thresholds of the claims table, handed over by the role the kind gives
each (``tolerance``, ``limit``, ...).

The pendulums' kinds (chapters 2-4) read the conventional and the proposed controller of a
stabilisation or tracking run. The CSTR's (chapter 5) read our Table 5.8, whose
"controllers" are its five tuning methods (ZN, Fuzzy, ANN, ANFIS, GA) and whose metrics are
its columns (``tr_s``, ``Mp_percent``, ...), or the H2 and H∞ preview controllers of
Fig. 5.19.

Every evidence text below is what ``claims.csv`` shows; numbers are written to three
significant digits (Fig. 5.19's to four; ``nan`` where a cell is missing).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from nlcx.thesis.catalog import CSTR_METHODS
from nlcx.thesis.tables import thesis_value

if TYPE_CHECKING:
    from nlcx.thesis.records import Record

#: The two controllers of every pendulum experiment: the literature's PID and the AGS PID.
CONTROLLERS = ("conventional", "proposed")
#: Table 5.8's tuning methods, in its order: the "controllers" a CSTR check of the table names.
METHODS = tuple(CSTR_METHODS)
#: Table 5.8's columns (:data:`nlcx.thesis.cstr.CSTR_METRICS`) as the evidence writes them.
TABLE_5_8_LABELS = {
    "tr_s": "t_r",
    "ts_s": "t_s",
    "Mp_percent": "M_p %",
    "ess": "e_ss",
    "inverse_response_percent": "inverse response %",
}
#: Fig. 5.19's preview controllers and the metrics its checks read, as the evidence writes them.
PREVIEW_LABELS = {"h2": "H2", "hinf": "H∞", "ise": "ISE", "control_effort": "∫u² dt"}
#: The metrics the thesis's tables print (:func:`nlcx.thesis.tables.thesis_value` maps them onto ours).
TABLE_METRICS = ("Mp", "tr", "ts", "ess")
#: Greek signals as the evidence writes them.
SYMBOL = {"theta": "θ", "phi": "φ"}


@dataclass(frozen=True)
class Check:
    """One condition of a claim.

    ``runs`` are the thesis tables and figures whose runs it reads ("Table 2.3", "Fig. 2.9"),
    ``controllers``, ``signals`` and ``metric`` the cells it reads of them, ``thresholds`` the
    names of the limits it compares against, in the order of its kind's roles. ``than``: the
    controllers (Table 5.8's methods) the ``controllers`` are compared with, for the kinds that
    compare them. ``shown``: whether the claim's evidence gives this check's numbers (it decides
    the verdict either way).
    """

    kind: str
    runs: tuple[str, ...]
    controllers: tuple[str, ...]
    signals: tuple[str, ...]
    metric: str
    thresholds: tuple[str, ...]
    than: tuple[str, ...] = ()
    shown: bool = True


@dataclass(frozen=True)
class ClaimRun:
    """The run behind one thesis table or figure, as a check reads it.

    ``record`` is what the reproduction keeps of the run (:class:`nlcx.thesis.records.Record`:
    ``metrics``, ``extras``, ``status``, ``resolved``, ``lyapunov``) or, for Table 5.8, whose
    five runs are one per tuning method, our values of the table (method -> column -> value,
    :func:`nlcx.thesis.cstr.method_values`); ``uncertainty`` is the figure's, as the figure
    list names it.
    """

    reference: str
    uncertainty: str
    record: Any


Outcome = tuple[bool, str]
Evaluator = Callable[[Check, Sequence[ClaimRun], Mapping[str, float]], Outcome]


@dataclass(frozen=True)
class Kind:
    """What a kind of check reads, and its evaluator.

    ``reads``: the one thesis table or figure it reads ("Table 5.8"), or "" for the run behind
    any stabilisation or tracking figure or metrics table of a pendulum. ``schedules``: one
    entry per run it reads, the AGS schedule that run must use ("" for any). ``mode``: the
    experiments it reads ("stabilization", "tracking", "" for either). ``controllers`` and
    ``metric``: fixed by the kind, or None where each check names its own, ``choices`` and
    ``metrics`` (if not empty) saying which it may name. ``signals``: whether a check names
    signals. ``rivals``: whether a check names the controllers it compares with (``than``).
    ``thresholds``: the roles of the named thresholds a check hands over, in order.
    """

    name: str
    evaluate: Evaluator
    reads: str = ""
    schedules: tuple[str, ...] = ("",)
    mode: str = "stabilization"
    controllers: tuple[str, ...] | None = CONTROLLERS
    choices: tuple[str, ...] = CONTROLLERS
    metric: str | None = None
    metrics: tuple[str, ...] = ()
    signals: bool = True
    rivals: bool = False
    thresholds: tuple[str, ...] = ()


#: Every kind of check, by name.
KINDS: dict[str, Kind] = {}


def kind(name: str, **reads: Any) -> Callable[[Evaluator], Evaluator]:
    """Register the decorated function as the evaluator of checks of kind ``name``
    (``reads``: the other fields of :class:`Kind`)."""

    def register(evaluate: Evaluator) -> Evaluator:
        KINDS[name] = Kind(name, evaluate, **reads)
        return evaluate

    return register


def metric_value(record: Record, controller: str, signal: str, metric: str) -> float:
    """A table metric (M_p, t_r, t_s, e_ss as the thesis defines them) or any other metric of a
    run (its metrics, then its extras); NaN where the run has none."""
    if metric in TABLE_METRICS:
        return thesis_value(record.metrics, controller, signal, metric)
    for table in (record.metrics, record.extras):
        rows = table[(table.controller == controller) & (table.signal == signal) & (table.metric == metric)]
        if not rows.empty:
            return float(rows.value.iloc[0])
    return math.nan


def fmt(value: float) -> str:
    """A number of the evidence: three significant digits."""
    return "nan" if math.isnan(value) else f"{value:.3g}"


def _joined(outcomes: Sequence[Outcome]) -> Outcome:
    """Every part holds; the parts' evidence joined by "; "."""
    return all(ok for ok, _ in outcomes), "; ".join(text for _, text in outcomes)


def _pairs(check: Check, run: ClaimRun) -> list[tuple[str, float, float]]:
    """(signal, conventional's value, proposed's value) of the check's metric on each signal."""
    return [
        (
            s,
            metric_value(run.record, "conventional", s, check.metric),
            metric_value(run.record, "proposed", s, check.metric),
        )
        for s in check.signals
    ]


def _versus(check: Check, run: ClaimRun, holds: Callable[[float, float], bool]) -> Outcome:
    """``holds(conventional, proposed)`` on every signal; evidence "Mp x: conv 0.5 vs prop 0.33"."""
    return _joined(
        [
            (bool(holds(c, p)), f"{check.metric} {SYMBOL.get(s, s)}: conv {fmt(c)} vs prop {fmt(p)}")
            for s, c, p in _pairs(check, run)
        ]
    )


@kind("proposed_lower")
def proposed_lower(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The tables' "improvement": the proposed controller's ``metric`` is below the conventional
    one's on every signal (a lower M_p, t_r, t_s, undershoot)."""
    return _versus(check, runs[0], lambda c, p: p < c)


@kind("proposed_higher")
def proposed_higher(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The tables' "deterioration": the proposed controller's ``metric`` is above the
    conventional one's on every signal (a longer rise time)."""
    return _versus(check, runs[0], lambda c, p: p > c)


@kind("proposed_zero", thresholds=("limit",))
def proposed_zero(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "overshoot reduced to zero": the proposed controller's ``metric`` is at most
    ``limit`` on every signal (the conventional value shown beside it)."""
    return _versus(check, runs[0], lambda c, p: p <= limits["limit"])


@kind("less_chattering", mode="", metric="total_variation")
def less_chattering(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "less chattering" with noise in the controllers: every input force of the
    proposed controller has a lower total variation sum |F_k - F_(k-1)| than the conventional
    one's (the two runs see the same noise)."""
    return _joined([(p < c, f"TV({f}): conv {fmt(c)} N vs prop {fmt(p)} N") for f, c, p in _pairs(check, runs[0])])


def _bounded(run: ClaimRun, controller: str, signals: Sequence[str], limit: float) -> Outcome:
    """Whether the controller's run neither diverged nor took a position beyond +-``limit``."""
    record = run.record
    if record.status[controller] != "ok":
        t_end = metric_value(record, controller, "all", "t_end_reached")
        return False, f"{controller} diverged (t = {fmt(t_end)} s)"
    worst = max(metric_value(record, controller, s, "max_abs") for s in signals)
    return worst <= limit, f"{controller} max|position| {fmt(worst)} m"


@kind("bounded", controllers=None, metric="max_abs", thresholds=("limit",))
def bounded(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "stable", "satisfactory" response: each controller's run neither diverged (the
    run's status) nor took a position beyond +-``limit``."""
    return _joined([_bounded(runs[0], c, check.signals, limits["limit"]) for c in check.controllers])


@kind("unbounded", controllers=None, metric="max_abs", thresholds=("limit",))
def unbounded(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "unbounded", "unstable" response: each controller's run diverged or took a
    position beyond +-``limit``."""
    outcomes = [_bounded(runs[0], c, check.signals, limits["limit"]) for c in check.controllers]
    return _joined([(not ok, text) for ok, text in outcomes])


def _oscillation(run: ClaimRun, controller: str, signals: Sequence[str], limit: float) -> tuple[bool | None, str]:
    """Whether a position of the controller's run still moves more than ``limit`` peak to peak
    over the last 5 s (None if the run failed)."""
    status = run.record.status[controller]
    if status != "ok":
        return None, f"{controller} {status}"
    ptp = max(metric_value(run.record, controller, s, "tail_ptp") for s in signals)
    return ptp > limit, f"{controller} position peak-to-peak over the last 5 s {fmt(ptp)} m"


@kind("oscillatory", controllers=None, metric="tail_ptp", thresholds=("limit",))
def oscillatory(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "oscillatory response": each controller's run completed and a position still
    moves more than ``limit`` peak to peak over its last 5 s."""
    outcomes = [_oscillation(runs[0], c, check.signals, limits["limit"]) for c in check.controllers]
    return _joined([(moves is not None and bool(moves), text) for moves, text in outcomes])


@kind("not_oscillatory", controllers=None, metric="tail_ptp", thresholds=("limit",))
def not_oscillatory(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "almost perfect control": each controller's run completed and no position moves
    more than ``limit`` peak to peak over its last 5 s."""
    outcomes = [_oscillation(runs[0], c, check.signals, limits["limit"]) for c in check.controllers]
    return _joined([(moves is not None and not moves, text) for moves, text in outcomes])


@kind("zero_ess", controllers=None, metric="ess", thresholds=("tolerance",))
def zero_ess(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "zero steady-state error": each controller's run completed with |e_ss| at most
    ``tolerance`` on every signal (positions, per unit step)."""
    record = runs[0].record
    outcomes = []
    for c in check.controllers:
        if record.status[c] != "ok":
            outcomes.append((False, f"{c} {record.status[c]}"))
            continue
        worst = max(abs(metric_value(record, c, s, check.metric)) for s in check.signals)
        outcomes.append((worst <= limits["tolerance"], f"{c} max|e_ss| {fmt(worst)}"))
    return _joined(outcomes)


def _tracking(run: ClaimRun, controller: str, signals: Sequence[str], fraction: float) -> tuple[bool | None, str]:
    """Whether the controller's RMS tracking error over the last 5 s is at most ``fraction`` of
    the sine's amplitude on every signal (None if the run failed)."""
    status = run.record.status[controller]
    if status != "ok":
        return None, f"{controller} {status}"
    reference = run.record.resolved["reference"]
    ratio = max(metric_value(run.record, controller, s, "tail_rms_error") / reference[s]["amplitude"] for s in signals)
    return ratio <= fraction, f"{controller} RMS tracking error {fmt(100 * ratio)} % of amplitude"


@kind("tracks", mode="tracking", controllers=None, metric="tail_rms_error", thresholds=("fraction",))
def tracks(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "good reference tracking": each controller's run completed with an RMS tracking
    error over the last 5 s of at most ``fraction`` of the sine's amplitude on every signal."""
    outcomes = [_tracking(runs[0], c, check.signals, limits["fraction"]) for c in check.controllers]
    return _joined([(good is not None and bool(good), text) for good, text in outcomes])


@kind("fails_to_track", mode="tracking", controllers=None, metric="tail_rms_error", thresholds=("fraction",))
def fails_to_track(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "fails to respond": each controller's run failed, or its RMS tracking error
    over the last 5 s exceeds ``fraction`` of the sine's amplitude on some signal."""
    outcomes = [_tracking(runs[0], c, check.signals, limits["fraction"]) for c in check.controllers]
    return _joined([(good is None or not good, text) for good, text in outcomes])


@kind("better_tracking", mode="tracking", metric="tail_rms_error")
def better_tracking(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The thesis's "better reference tracking": the proposed controller's largest RMS tracking
    error over the last 5 s is below the conventional one's (a failed run's counts as infinite)."""
    run = runs[0]
    worst = {
        c: max(metric_value(run.record, c, s, check.metric) for s in check.signals)
        if run.record.status[c] == "ok"
        else math.inf
        for c in CONTROLLERS
    }
    return worst["proposed"] < worst["conventional"], (
        f"{run.uncertainty}: RMS error conv {fmt(worst['conventional'])} vs prop {fmt(worst['proposed'])} m"
    )


def _lyapunov(run: ClaimRun, controller: str, limits: Mapping[str, float]) -> Outcome:
    """V̇ of one controller's run against sum F v, and its decay over the final window."""
    if controller not in run.record.lyapunov:
        return False, f"{controller} run unavailable"
    t, dV, power = run.record.lyapunov[controller]
    scale = np.max(np.abs(dV))
    agree = float(np.max(np.abs(dV - power)) / scale)
    tail = float(np.max(np.abs(dV[t >= t[-1] - limits["window"]])) / scale)
    return agree < limits["agreement"] and tail < limits["decay"], (
        f"max|V̇ - F·v|/max|V̇| {agree:.1e}; max|V̇| over the last {limits['window']:g} s / peak {tail:.2g}"
    )


@kind("lyapunov", controllers=None, metric="", signals=False, thresholds=("agreement", "decay", "window"))
def lyapunov(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """Theorems 2.1-4.1: along each controller's nominal run, V̇ from the trajectory equals the
    input power sum F v (max deviation below ``agreement`` of max |V̇|), and V̇ tends to zero
    (max |V̇| over the final ``window`` s below ``decay`` of its peak)."""
    return _joined([_lyapunov(runs[0], c, limits) for c in check.controllers])


def _schedules(check: Check, runs: Sequence[ClaimRun], error_lower: bool) -> Outcome:
    """The proposed controller's ``metric`` under error-AGS (runs[1]) against time-AGS (runs[0])."""
    outcomes = []
    for s in check.signals:
        vt, ve = (metric_value(r.record, "proposed", s, check.metric) for r in runs)
        ok = ve < vt if error_lower else vt < ve
        outcomes.append((ok, f"{check.metric} {SYMBOL.get(s, s)}: time {fmt(vt)} vs error {fmt(ve)}"))
    return _joined(outcomes)


@kind("error_ags_lower", schedules=("time", "error"), controllers=("proposed",))
def error_ags_lower(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The chapters' comparative study: the proposed controller's ``metric`` is lower under
    error-AGS (the second run) than under time-AGS (the first) on every signal."""
    return _schedules(check, runs, error_lower=True)


@kind("time_ags_lower", schedules=("time", "error"), controllers=("proposed",))
def time_ags_lower(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The chapters' comparative study: the proposed controller's ``metric`` is lower under
    time-AGS (the first run) than under error-AGS (the second) on every signal."""
    return _schedules(check, runs, error_lower=False)


def _listing(values: Mapping[str, Mapping[str, float]], column: str) -> str:
    """Every method's value in one column of our Table 5.8: "t_r: ZN 0.338; Fuzzy 0.227; ..."."""
    return f"{TABLE_5_8_LABELS[column]}: " + "; ".join(f"{m} {fmt(row[column])}" for m, row in values.items())


#: What every kind of check of Table 5.8 reads: the table, the methods a check names, no signals.
READS_TABLE_5_8 = {"reads": "Table 5.8", "mode": "", "controllers": None, "choices": METHODS, "signals": False}


@kind("method_lower", metrics=tuple(TABLE_5_8_LABELS), rivals=True, **READS_TABLE_5_8)
def method_lower(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """Table 5.8's comparisons ("the rise time which is less in case of ZN", "the best
    performance in terms of settling time ... given by ANFIS"): each of the check's methods has
    a lower value in the ``metric`` column than each method it is compared with (``than``); a
    missing value compares as not lower. The evidence lists the column."""
    values = runs[0].record
    lower = all(values[m][check.metric] < values[r][check.metric] for m in check.controllers for r in check.than)
    return lower, _listing(values, check.metric)


@kind("method_zero_ess", metric="ess", thresholds=("tolerance",), **READS_TABLE_5_8)
def method_zero_ess(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """Table 5.8's zero steady-state errors: each of the check's methods has |e_ss| at most
    ``tolerance`` (the CSTR's step is a unit step). The evidence lists the column."""
    values = runs[0].record
    zero = all(abs(values[m][check.metric]) <= limits["tolerance"] for m in check.controllers)
    return zero, _listing(values, check.metric)


@kind("method_no_overshoot", metric="Mp_percent", thresholds=("limit",), **READS_TABLE_5_8)
def method_no_overshoot(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """Section 5.4.4's "zero maximum overshoot": each of the check's methods has an M_p (in %, as
    Table 5.8 prints it) of at most ``limit``, an overshoot fraction."""
    values = runs[0].record
    return _joined(
        [
            (values[m][check.metric] <= 100 * limits["limit"], f"M_p {m} {fmt(values[m][check.metric])} %")
            for m in check.controllers
        ]
    )


@kind("method_inverse_response", metric="inverse_response_percent", thresholds=("limit",), **READS_TABLE_5_8)
def method_inverse_response(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """The "inverse response behavior ... due to RHP zero": each of the check's methods' step
    response first moves the wrong way by more than ``limit`` % of the step (our undershoot)."""
    values = runs[0].record
    return _joined(
        [
            (values[m][check.metric] > limits["limit"], f"{m} inverse response {fmt(values[m][check.metric])} %")
            for m in check.controllers
        ]
    )


@kind("hinf_lower", reads="Fig. 5.19", mode="", controllers=("h2", "hinf"), metrics=("ise", "control_effort"))
def hinf_lower(check: Check, runs: Sequence[ClaimRun], limits: Mapping[str, float]) -> Outcome:
    """Section 5.5's "improvement in the steady state tracking performance ... with minimum
    control effort": the H∞ preview controller's ``metric`` (ISE, or the control effort, the
    integral of u²) is below the H2 one's on every signal."""
    label = PREVIEW_LABELS
    outcomes = []
    for s in check.signals:
        h2, hinf = (metric_value(runs[0].record, c, s, check.metric) for c in check.controllers)
        outcomes.append((hinf < h2, f"{label[check.metric]}: {label['h2']} {h2:.4g}, {label['hinf']} {hinf:.4g}"))
    return _joined(outcomes)

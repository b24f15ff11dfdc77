"""The qualitative claims of chapters 2-4, checked against our runs.

Each claim paraphrases one statement of the thesis's text (its section or figure is
given), and is a conjunction of checks on the runs of the figure it is about. A claim is
``yes`` when every check holds, ``partly`` when some do, ``no`` when none does; the evidence
column gives the numbers. Definitions used by the checks:

- M_p, t_r, t_s, e_ss as in the tables (docs/metrics.md; M_p of a position = overshoot
  fraction, of an angle = peak deviation in rad);
- chattering = total variation sum |F_k - F_{k-1}| of every input force;
- unbounded = the run diverged (``unstable``: |angle| > pi/2 or non-finite) or a position
  left +-10 m; bounded = neither;
- oscillatory = a position still moves more than 2 % of its step (peak-to-peak) over the
  last 5 s; zero e_ss = |e_ss| <= 0.01 (positions, per unit step) and bounded;
- tracks well = RMS tracking error over the last 5 s <= 10 % of the sine amplitude;
- chattering compared only between runs with the same noise realisation (common seeds).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from nlcx.drawing import new_figure
from nlcx.thesis import catalog, cstr
from nlcx.thesis.catalog import FigureSpec
from nlcx.thesis.tables import thesis_value

POSITIONS = {"x": ("x",), "xy": ("x", "y"), "xz": ("x", "z"), "xyz": ("x", "y", "z")}
ANGLES = {"x": ("theta",), "xy": ("theta", "phi"), "xz": ("theta",), "xyz": ("theta", "phi")}
INPUTS = {"x": ("F_x",), "xy": ("F_x", "F_y"), "xz": ("F_x", "F_z"), "xyz": ("F_x", "F_y", "F_z")}
AMPLITUDE = {"x": 0.3, "y": 0.3, "z": 0.15}
AMPLITUDE_XYZ = {"x": 0.25, "y": 0.25, "z": 0.15}
SYMBOL = {"theta": "θ", "phi": "φ"}

Check = Callable[["Context"], tuple[bool, str]]


@dataclass
class Context:
    """The runs the checks of one pendulum look at."""

    records: dict[Path, Any]
    root: Path
    plant: str

    def record(self, ags: str, mode: str, uncertainty: str) -> Any:
        """The run of this pendulum's figure with this schedule, mode and uncertainty."""
        number = catalog.figure_number(self.plant, ags, mode, uncertainty)
        return self.records[catalog.figure_config(self.root, number)]


def _metric(record: Any, controller: str, signal: str, metric: str) -> float:
    """A table metric (M_p, t_r, t_s, e_ss as the thesis defines them) or any other metric of a run."""
    if metric in ("Mp", "tr", "ts", "ess"):
        return thesis_value(record.metrics, controller, signal, metric)
    for table in (record.metrics, record.extras):
        rows = table[(table.controller == controller) & (table.signal == signal) & (table.metric == metric)]
        if not rows.empty:
            return float(rows.value.iloc[0])
    return math.nan


def _fmt(v: float) -> str:
    return "nan" if math.isnan(v) else f"{v:.3g}"


def _signals(plant: str, which: str) -> tuple[str, ...]:
    """ "positions", "horizontal" (positions without z) or "angles" of a pendulum."""
    if which == "angles":
        return ANGLES[plant]
    if which == "horizontal":
        return tuple(s for s in POSITIONS[plant] if s != "z")
    return POSITIONS[plant]


def compare(ags: str, unc: str, metric: str, signals: str, better: bool = True, mode: str = "stabilization") -> Check:
    """Proposed lower (better=True) or higher than conventional in ``metric`` on each signal."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, mode, unc)
        sigs = _signals(ctx.plant, signals)
        oks, parts = [], []
        for s in sigs:
            c, p = _metric(rec, "conventional", s, metric), _metric(rec, "proposed", s, metric)
            ok = (p < c) if better else (p > c)
            oks.append(bool(ok))
            parts.append(f"{metric} {SYMBOL.get(s, s)}: conv {_fmt(c)} vs prop {_fmt(p)}")
        return all(oks), "; ".join(parts)

    return check


def zero_ess(ags: str, unc: str, controllers: tuple[str, ...] = ("conventional", "proposed")) -> Check:
    """Each controller's stabilisation run reaches |e_ss| <= 0.01 on every position."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, "stabilization", unc)
        oks, parts = [], []
        for c in controllers:
            if rec.status[c] != "ok":
                oks.append(False)
                parts.append(f"{c} {rec.status[c]}")
                continue
            worst = max(abs(_metric(rec, c, s, "ess")) for s in POSITIONS[ctx.plant])
            oks.append(worst <= 0.01)
            parts.append(f"{c} max|e_ss| {_fmt(worst)}")
        return all(oks), "; ".join(parts)

    return check


def less_chattering(ags: str, mode: str) -> Check:
    """With noise, proposed forces vary less (total variation) than conventional ones."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, mode, "noise")
        oks, parts = [], []
        for f in INPUTS[ctx.plant]:
            c = _metric(rec, "conventional", f, "total_variation")
            p = _metric(rec, "proposed", f, "total_variation")
            oks.append(p < c)
            parts.append(f"TV({f}): conv {_fmt(c)} N vs prop {_fmt(p)} N")
        return all(oks), "; ".join(parts)

    return check


def _bounded(rec: Any, controller: str, plant: str) -> tuple[bool, str]:
    """Neither diverged nor a position beyond +-10 m."""
    if rec.status[controller] != "ok":
        t_end = _metric(rec, controller, "all", "t_fail")
        return False, f"{controller} diverged (t = {_fmt(t_end)} s)"
    worst = max(_metric(rec, controller, s, "max_abs") for s in POSITIONS[plant])
    return worst <= 10.0, f"{controller} max|position| {_fmt(worst)} m"


def unbounded(ags: str, mode: str, unc: str, controller: str) -> Check:
    """The controller's run diverged or a position left +-10 m."""

    def check(ctx: Context) -> tuple[bool, str]:
        ok, text = _bounded(ctx.record(ags, mode, unc), controller, ctx.plant)
        return not ok, text

    return check


def bounded(ags: str, mode: str, unc: str, controller: str) -> Check:
    """The controller's run neither diverged nor left +-10 m."""

    def check(ctx: Context) -> tuple[bool, str]:
        return _bounded(ctx.record(ags, mode, unc), controller, ctx.plant)

    return check


def oscillatory(ags: str, unc: str, controller: str, expected: bool = True) -> Check:
    """A position still moves more than 0.02 m peak to peak over the last 5 s (or, not expected, none does)."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, "stabilization", unc)
        if rec.status[controller] != "ok":
            return False, f"{controller} {rec.status[controller]}"
        ptp = max(_metric(rec, controller, s, "tail_ptp") for s in POSITIONS[ctx.plant])
        osc = ptp > 0.02
        return osc == expected, f"{controller} position peak-to-peak over the last 5 s {_fmt(ptp)} m"

    return check


def tracks(ags: str, unc: str, controller: str, expected: bool = True) -> Check:
    """RMS tracking error over the last 5 s <= 10 % of the sine amplitude (or, not expected, above)."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, "tracking", unc)
        if rec.status[controller] != "ok":
            return not expected, f"{controller} {rec.status[controller]}"
        amp = AMPLITUDE_XYZ if ctx.plant == "xyz" else AMPLITUDE
        ratios = [_metric(rec, controller, s, "tail_rms_error") / amp[s] for s in POSITIONS[ctx.plant]]
        good = max(ratios) <= 0.10
        return good == expected, f"{controller} RMS tracking error {_fmt(100 * max(ratios))} % of amplitude"

    return check


def better_tracking(ags: str, unc: str) -> Check:
    """Proposed tracks with a lower RMS error over the last 5 s than conventional."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, "tracking", unc)
        vals = {}
        for c in ("conventional", "proposed"):
            if rec.status[c] != "ok":
                vals[c] = math.inf
                continue
            vals[c] = max(_metric(rec, c, s, "tail_rms_error") for s in POSITIONS[ctx.plant])
        return vals["proposed"] < vals["conventional"], (
            f"{unc}: RMS error conv {_fmt(vals['conventional'])} vs prop {_fmt(vals['proposed'])} m"
        )

    return check


def lyapunov(ags: str) -> Check:
    """Theorems 2.1-4.1: V-dot = sum F v along the proposed run, and V-dot tends to zero."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, "stabilization", "none")
        if "proposed" not in rec.lyapunov:
            return False, "proposed run unavailable"
        t, dV, power = rec.lyapunov["proposed"]
        scale = np.max(np.abs(dV))
        agree = float(np.max(np.abs(dV - power)) / scale)
        tail = float(np.max(np.abs(dV[t >= t[-1] - 5.0])) / scale)
        return agree < 1e-3 and tail < 0.05, (
            f"max|V̇ - F·v|/max|V̇| {agree:.1e}; max|V̇| over the last 5 s / peak {tail:.2g}"
        )

    return check


def ags_vs_ags(metric: str, signals: str, lower: str) -> Check:
    """Between the two proposed schedules: ``lower`` ("error"/"time") has the lower metric."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec_t = ctx.record("time", "stabilization", "none")
        rec_e = ctx.record("error", "stabilization", "none")
        sigs = _signals(ctx.plant, signals)
        oks, parts = [], []
        for s in sigs:
            vt, ve = _metric(rec_t, "proposed", s, metric), _metric(rec_e, "proposed", s, metric)
            oks.append(ve < vt if lower == "error" else vt < ve)
            parts.append(f"{metric} {SYMBOL.get(s, s)}: time {_fmt(vt)} vs error {_fmt(ve)}")
        return all(oks), "; ".join(parts)

    return check


def z_check(ags: str, unc: str, metric: str, zero: bool = False, lower: bool = True) -> Check:
    """z-loop checks: proposed M_p (about) zero, or proposed lower/higher than conventional."""

    def check(ctx: Context) -> tuple[bool, str]:
        rec = ctx.record(ags, "stabilization", unc)
        c, p = _metric(rec, "conventional", "z", metric), _metric(rec, "proposed", "z", metric)
        ok = (p <= 0.005) if zero else ((p < c) if lower else (p > c))
        return ok, f"{metric} z: conv {_fmt(c)} vs prop {_fmt(p)}"

    return check


@dataclass(frozen=True)
class Claim:
    """One statement of the thesis about one pendulum, and the checks that decide it."""

    key: str
    source: str
    text: str
    checks: tuple[Check, ...]


@dataclass(frozen=True)
class TableClaim:
    """A claim read off a quantitative table of the ``plants`` named.

    ``tables`` are the (schedule, uncertainty) of the pendulum's metrics tables cited; their
    numbers fill ``source`` ({0}, {1}, ...).
    """

    key: str
    plants: tuple[str, ...]
    tables: tuple[tuple[str, str], ...]
    source: str
    text: str
    checks: tuple[Check, ...]


@dataclass(frozen=True)
class ScheduleClaim:
    """A claim the thesis makes in the same words for both AGS schedules and every pendulum.

    ``figures`` are the (mode, uncertainty) of the figures cited; their numbers fill
    ``source`` ({0}, {1}; {plant} is the pendulum). ``{name}`` in ``text`` is "Time" or
    "Error"; ``checks`` makes the checks for a schedule, "time" or "error".
    """

    key: str
    figures: tuple[tuple[str, str], ...]
    source: str
    text: str
    checks: Callable[[str], tuple[Check, ...]]


@dataclass(frozen=True)
class ConclusionClaim:
    """A claim of a chapter's conclusion, for every pendulum; the numbers of the ``figures``
    cited, each (schedule, mode, uncertainty), fill ``source``."""

    key: str
    figures: tuple[tuple[str, str, str], ...]
    source: str
    text: str
    checks: tuple[Check, ...]


PLANAR = ("x", "xy")
WITH_Z = ("xz", "xyz")
#: Tables 2.3-2.6 and 3.2-3.5 (x, x-y), 3.7-3.10 and 4.2-4.5 (x-z, x-y-z), as the text reads them.
TABLE_CLAIMS = (
    TableClaim(
        "time-nominal-Mp",
        PLANAR,
        (("time", "none"),),
        "Table {0}",
        "Time-AGS PID lowers M_p of positions and angles",
        (compare("time", "none", "Mp", "positions"), compare("time", "none", "Mp", "angles")),
    ),
    TableClaim(
        "time-nominal-tr",
        PLANAR,
        (("time", "none"),),
        "Table {0}",
        "Time-AGS PID raises the rise time slightly",
        (compare("time", "none", "tr", "positions", better=False),),
    ),
    TableClaim(
        "time-disturbance",
        PLANAR,
        (("time", "disturbance"),),
        "Table {0}",
        "With disturbance, time-AGS PID lowers M_p a lot, at a small cost in t_r",
        (
            compare("time", "disturbance", "Mp", "positions"),
            compare("time", "disturbance", "Mp", "angles"),
            compare("time", "disturbance", "tr", "positions", better=False),
        ),
    ),
    TableClaim(
        "error-nominal",
        PLANAR,
        (("error", "none"),),
        "Table {0}",
        "Error-AGS PID lowers M_p of positions and angles and shortens t_s",
        (
            compare("error", "none", "Mp", "positions"),
            compare("error", "none", "Mp", "angles"),
            compare("error", "none", "ts", "positions"),
            compare("error", "none", "ts", "angles"),
        ),
    ),
    TableClaim(
        "error-disturbance",
        PLANAR,
        (("error", "disturbance"),),
        "Table {0}",
        "With disturbance, error-AGS PID improves M_p and t_s a lot",
        (
            compare("error", "disturbance", "Mp", "positions"),
            compare("error", "disturbance", "ts", "positions"),
            compare("error", "disturbance", "ts", "angles"),
        ),
    ),
    TableClaim(
        "time-nominal-ts",
        ("x",),
        (("time", "none"),),
        "Table {0}",
        "Time-AGS PID improves t_s slightly",
        (compare("time", "none", "ts", "positions"), compare("time", "none", "ts", "angles")),
    ),
    TableClaim(
        "time-nominal-x",
        WITH_Z,
        (("time", "none"),),
        "Table {0}",
        "Time-AGS PID improves M_p, t_r and t_s of the horizontal positions",
        tuple(compare("time", "none", m, "horizontal") for m in ("Mp", "tr", "ts")),
    ),
    TableClaim(
        "time-nominal-z",
        WITH_Z,
        (("time", "none"),),
        "Table {0}",
        "Time-AGS PID brings the z overshoot to zero with a longer z rise time",
        (z_check("time", "none", "Mp", zero=True), z_check("time", "none", "tr", lower=False)),
    ),
    TableClaim(
        "time-nominal-angle",
        WITH_Z,
        (("time", "none"),),
        "Table {0}",
        "Time-AGS PID lowers the angle M_p a lot",
        (compare("time", "none", "Mp", "angles"),),
    ),
    TableClaim(
        "time-disturbance",
        WITH_Z,
        (("time", "disturbance"),),
        "Table {0}",
        "With disturbance, time-AGS PID lowers M_p of x and θ and brings z overshoot to zero",
        (
            compare("time", "disturbance", "Mp", "horizontal"),
            compare("time", "disturbance", "Mp", "angles"),
            z_check("time", "disturbance", "Mp", zero=True),
        ),
    ),
    TableClaim(
        "error-nominal",
        WITH_Z,
        (("error", "none"),),
        "Table {0}",
        "Error-AGS PID lowers x M_p a lot and improves x t_r and t_s",
        tuple(compare("error", "none", m, "horizontal") for m in ("Mp", "tr", "ts")),
    ),
    TableClaim(
        "error-disturbance",
        WITH_Z,
        (("error", "disturbance"),),
        "Table {0}",
        "With disturbance, error-AGS PID lowers x M_p, brings z overshoot to zero and shortens θ t_s",
        (
            compare("error", "disturbance", "Mp", "horizontal"),
            z_check("error", "disturbance", "Mp", zero=True),
            compare("error", "disturbance", "ts", "angles"),
        ),
    ),
    TableClaim(
        "time-inverse-response",
        ("xyz",),
        (("time", "none"),),
        "Table {0} and section 4.5.1.1",
        "AGS PID reduces the inverse response (undershoot) of the horizontal positions",
        (
            compare("time", "none", "undershoot", "horizontal"),
            compare("error", "none", "undershoot", "horizontal"),
        ),
    ),
)
#: The schedules, as the claims name them.
SCHEDULES = (("time", "Time"), ("error", "Error"))
#: Claims made for each schedule: the uncertainty and tracking figures, the tables' e_ss, the theorems.
SCHEDULE_CLAIMS = (
    ScheduleClaim(
        "noise-stab",
        (("stabilization", "noise"),),
        "Fig. {0}",
        "With noise in the controllers, {name}-AGS PID shows less chattering than conventional PID",
        lambda ags: (less_chattering(ags, "stabilization"),),
    ),
    ScheduleClaim(
        "simple-friction-stab",
        (("stabilization", "simple_friction"),),
        "Fig. {0}",
        "With simple friction, conventional PID is unbounded while {name}-AGS PID stays bounded",
        lambda ags: (
            unbounded(ags, "stabilization", "simple_friction", "conventional"),
            bounded(ags, "stabilization", "simple_friction", "proposed"),
        ),
    ),
    ScheduleClaim(
        "exp-friction-stab",
        (("stabilization", "exponential_friction"),),
        "Fig. {0}",
        "With exponential friction, conventional PID oscillates while {name}-AGS PID reaches zero e_ss",
        lambda ags: (
            oscillatory(ags, "exponential_friction", "conventional"),
            oscillatory(ags, "exponential_friction", "proposed", expected=False),
            zero_ess(ags, "exponential_friction", ("proposed",)),
        ),
    ),
    ScheduleClaim(
        "tracking-nominal",
        (("tracking", "none"), ("tracking", "disturbance")),
        "Figs. {0}, {1}",
        "Without uncertainties and with disturbance, conventional and {name}-AGS PID both track well",
        lambda ags: (
            tracks(ags, "none", "conventional"),
            tracks(ags, "none", "proposed"),
            tracks(ags, "disturbance", "conventional"),
            tracks(ags, "disturbance", "proposed"),
        ),
    ),
    ScheduleClaim(
        "tracking-noise",
        (("tracking", "noise"),),
        "Fig. {0}",
        "Tracking with noise: {name}-AGS PID chatters less than conventional PID",
        lambda ags: (less_chattering(ags, "tracking"),),
    ),
    ScheduleClaim(
        "tracking-simple-friction",
        (("tracking", "simple_friction"),),
        "Fig. {0}",
        "Tracking with simple friction: conventional PID fails, {name}-AGS PID performs satisfactorily",
        lambda ags: (
            tracks(ags, "simple_friction", "conventional", expected=False),
            tracks(ags, "simple_friction", "proposed"),
        ),
    ),
    ScheduleClaim(
        "tracking-exp-friction",
        (("tracking", "exponential_friction"),),
        "Fig. {0}",
        "Tracking with exponential friction: {name}-AGS PID tracks (almost perfectly), conventional does not",
        lambda ags: (tracks(ags, "exponential_friction", "proposed"), better_tracking(ags, "exponential_friction")),
    ),
    ScheduleClaim(
        "nominal-ess",
        (("stabilization", "none"),),
        "Table of Fig. {0}",
        "Both controllers reach zero steady-state error without uncertainties",
        lambda ags: (zero_ess(ags, "none"),),
    ),
    ScheduleClaim(
        "lyapunov",
        (),
        "Theorem and V̇ figure of the {plant} pendulum",
        "V̇ = sum F v along the closed loop, and V̇ tends to zero with {name}-AGS PID",
        lambda ags: (lyapunov(ags),),
    ),
)
#: The chapters' conclusions on error- against time-AGS PID.
CONCLUSION_CLAIMS = (
    ConclusionClaim(
        "error-tracking-uncertain",
        (("error", "tracking", "disturbance"), ("error", "tracking", "exponential_friction")),
        "Figs. {0}-{1}",
        "Error-AGS PID tracks better than conventional PID, especially with uncertainties",
        tuple(better_tracking("error", u) for u in ("disturbance", "noise", "simple_friction", "exponential_friction")),
    ),
    ConclusionClaim(
        "error-vs-time-position",
        (),
        "Conclusion of the chapter",
        "Position M_p and t_s are lower with error-AGS than with time-AGS; t_r is lower with time-AGS",
        (
            ags_vs_ags("Mp", "positions", "error"),
            ags_vs_ags("ts", "positions", "error"),
            ags_vs_ags("tr", "positions", "time"),
        ),
    ),
    ConclusionClaim(
        "error-vs-time-angle",
        (),
        "Conclusion of the chapter",
        "Angle M_p is lower with time-AGS; angle t_s is lower with error-AGS",
        (ags_vs_ags("Mp", "angles", "time"), ags_vs_ags("ts", "angles", "error")),
    ),
)
CHAPTER_PLANTS = {2: ("x",), 3: ("xy", "xz"), 4: ("xyz",)}


def _tables_of(plant: str) -> dict[tuple[str, str], str]:
    """The metrics tables of a pendulum: (schedule, uncertainty) -> table number."""
    meta = catalog.thesis_metrics()[["table", "plant", "ags", "scenario"]].drop_duplicates()
    meta = meta[meta.plant == plant]
    return {
        (r.ags, "none" if r.scenario == "nominal" else r.scenario): str(r.table) for r in meta.itertuples(index=False)
    }


def _table_claims(plant: str) -> list[Claim]:
    """The claims of TABLE_CLAIMS about this pendulum, citing its table numbers."""
    numbers = _tables_of(plant)
    return [
        Claim(c.key, c.source.format(*(numbers[t] for t in c.tables)), c.text, c.checks)
        for c in TABLE_CLAIMS
        if plant in c.plants
    ]


def _schedule_claims(plant: str) -> list[Claim]:
    """SCHEDULE_CLAIMS for time-AGS, then for error-AGS, citing this pendulum's figures."""
    out = []
    for ags, name in SCHEDULES:
        for c in SCHEDULE_CLAIMS:
            figures = (catalog.figure_number(plant, ags, mode, unc) for mode, unc in c.figures)
            source = c.source.format(*figures, plant=plant)
            out.append(Claim(f"{ags}-{c.key}", source, c.text.format(name=name), c.checks(ags)))
    return out


def _conclusion_claims(plant: str) -> list[Claim]:
    """CONCLUSION_CLAIMS, citing this pendulum's figures."""
    return [
        Claim(c.key, c.source.format(*(catalog.figure_number(plant, *f) for f in c.figures)), c.text, c.checks)
        for c in CONCLUSION_CLAIMS
    ]


def claims_for(plant: str) -> list[Claim]:
    """Every claim about one pendulum: its tables', then each schedule's, then the conclusion's."""
    return _table_claims(plant) + _schedule_claims(plant) + _conclusion_claims(plant)


def configs_for(root: Path, chapters: set[int]) -> list[Path]:
    """Every experiment the claims of these chapters look at."""
    plants = {p for c in chapters for p in CHAPTER_PLANTS.get(c, ())}
    if 5 in chapters:
        plants.add("cstr")
    return [f.configs[0] for f in catalog.figures(root) if f.kind == "response" and f.plant in plants]


def evaluate(root: Path, records: dict[Path, Any], chapters: set[int]) -> pd.DataFrame:
    """claims.csv: chapter, pendulum, id, source, claim, reproduced, evidence."""
    rows = []
    for chapter in sorted(chapters):
        if chapter == 5:
            rows += cstr.claims(records, root)
        for plant in CHAPTER_PLANTS.get(chapter, ()):
            ctx = Context(records=records, root=root, plant=plant)
            for claim in claims_for(plant):
                results = [check(ctx) for check in claim.checks]
                n_ok = sum(ok for ok, _ in results)
                verdict = "yes" if n_ok == len(results) else ("no" if n_ok == 0 else "partly")
                rows.append(
                    {
                        "chapter": chapter,
                        "pendulum": plant,
                        "id": f"{plant}-{claim.key}",
                        "source": claim.source,
                        "claim": claim.text,
                        "reproduced": verdict,
                        "evidence": " | ".join(text for _, text in results),
                    }
                )
    return pd.DataFrame(rows)


def lyapunov_figure(spec: FigureSpec, records: list[Any]) -> Figure:
    """V̇ from the stored trajectory beside sum F v, for time-AGS (a) and error-AGS (b)."""
    fig, axes = new_figure(len(records), 1, (7.5, 2.9 * len(records)))
    for k, (ax, rec, name) in enumerate(zip(axes[:, 0], records, ("Time", "Error"), strict=False)):
        for label, color in (("proposed", "C3"), ("conventional", "C0")):
            if label not in rec.lyapunov:
                continue
            t, dV, power = rec.lyapunov[label]
            ax.plot(t, dV, color=color, lw=1.3, label=f"V̇ from trajectory, {label}")
            ax.plot(t, power, color="k", ls=":", lw=1.0, label=f"ΣF·v, {label}" if label == "proposed" else None)
        ax.set_title(f"({chr(ord('a') + k)}) V̇ vs time with {name} AGS PID")
        ax.set_xlabel("Time (s)")
        ax.set_ylabel("V̇ (W)")
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        else:  # both runs diverged (possible under a loop profile): nothing to draw
            ax.text(0.5, 0.5, "no run completed", transform=ax.transAxes, ha="center", va="center")
    fig.suptitle(spec.title, fontsize=9)
    fig.tight_layout()
    return fig

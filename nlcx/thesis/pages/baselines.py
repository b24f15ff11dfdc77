"""What the report of a baselines directory (``nlcx baselines``) shows: the thesis's controllers
against the baselines, per pendulum and scenario side by side, then each pendulum's robustness
sweep (the share of stable variants per controller, and the spread of each metric).

Reads ``tables/comparison.csv`` and ``tables/robustness.csv`` (:mod:`nlcx.thesis.baselines`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pandas as pd

from nlcx.pages.kinds import ReportPage

#: The metrics the side-by-side tables show, in this order (step-referenced and regulated signals).
SHOWN = ("overshoot", "rise_time", "settling_time", "peak_deviation", "ise", "control_effort")
#: The metrics the robustness tables show.
SPREAD = ("overshoot", "settling_time", "peak_deviation")


def _value(value: object, status: str) -> str:
    """A cell: the number, a dash where undefined, or the run's status where it did not run to the end."""
    if status != "ok":
        return status
    return "—" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.4g}"


def _scenario_table(rows: pd.DataFrame) -> dict[str, object]:
    """One pendulum's scenario: the controllers as columns, a row per (signal, metric) shown."""
    controllers = list(dict.fromkeys(rows.controller))
    shown = rows[rows.metric.isin(SHOWN)]
    body = []
    for (signal, metric), group in shown.groupby(["signal", "metric"], sort=False):
        cells = dict(zip(group.controller, zip(group.value, group.status, strict=True), strict=True))
        unit = str(group.unit.iloc[0]) if "unit" in group else ""
        body.append({"signal": signal, "metric": metric, "unit": unit,
                     "cells": [_value(*cells.get(c, (math.nan, "—"))) for c in controllers]})  # fmt: skip
    stopped = sorted({c for c, s in zip(rows.controller, rows.status, strict=True) if s != "ok"})
    return {"controllers": controllers, "rows": body, "stopped": stopped}


def _robustness_table(rows: pd.DataFrame) -> dict[str, object]:
    """One pendulum's sweep: per controller, the share of stable variants and each metric's
    median and interquartile range."""
    controllers = list(dict.fromkeys(rows.controller))
    share = {c: float(rows[rows.controller == c].stable_share.iloc[0]) for c in controllers}
    body = []
    for (signal, metric), group in rows[rows.metric.isin(SPREAD)].groupby(["signal", "metric"], sort=False):
        by = {r.controller: r for r in group.itertuples()}
        body.append({"signal": signal, "metric": metric,
                     "cells": [_spread(by.get(c)) for c in controllers]})  # fmt: skip
    variants = int(rows.variants.max()) if len(rows) else 0
    return {"controllers": controllers, "share": share, "rows": body, "variants": variants}


def _spread(row: Any) -> str:  # a row of itertuples (its fields: the columns), or None
    if row is None or not isinstance(row.median, float) or math.isnan(row.median):
        return "—"
    return f"{row.median:.4g} ({row.q25:.4g} to {row.q75:.4g})"


def context(directory: Path) -> dict[str, object]:
    """Everything the baselines page shows."""
    comparison = pd.read_csv(directory / "tables" / "comparison.csv", keep_default_na=False, na_values={"value": [""]})
    numbers = {c: [""] for c in ("median", "q25", "q75", "min", "max", "stable_share")}
    robustness = pd.read_csv(directory / "tables" / "robustness.csv", keep_default_na=False, na_values=numbers)
    pendulums = []
    for pendulum in dict.fromkeys(comparison.pendulum):
        mine = comparison[comparison.pendulum == pendulum]
        scenarios = [{"scenario": s, **_scenario_table(mine[mine.scenario == s])} for s in dict.fromkeys(mine.scenario)]
        sweep = robustness[robustness.pendulum == pendulum]
        pendulums.append({"pendulum": pendulum, "scenarios": scenarios,
                          "robustness": _robustness_table(sweep) if len(sweep) else None})  # fmt: skip
    return {
        "kind": "baselines",
        "title": "nlcx baselines: AGS PID against LQR and sliding mode",
        "pendulums": pendulums,
        "shown": SHOWN,
        "spread": SPREAD,
    }


def page_context(directory: Path, configs: Path | None, repo: Path | None) -> dict[str, object]:
    """The page's :func:`context` (it reads only the directory's tables)."""
    return context(directory)


#: The report page of a baselines directory (the entry point ``baselines`` of nlcx.pages).
PAGE = ReportPage(Path(__file__).parent / "templates", page_context)

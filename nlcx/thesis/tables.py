"""The pendulum tables of chapters 2-4, ours beside the thesis's.

The metrics tables (2.3-2.6, 3.2-3.5, 3.7-3.10, 4.2-4.5) set our metrics of a run beside the
printed numbers, with the improvement % by the thesis's formula; the parameter tables (2.1,
and the AGS Tables 2.2, 3.1, 3.6, 4.1 with the rates of section 2.3) set the resolved configs
actually run beside the printed values. :func:`thesis_value` maps a thesis (signal, metric)
onto nlcx's metrics for the claims and the calibration too.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import pandas as pd

from nlcx.comparison import thesis_improvement  # the thesis's formula, importable from here too
from nlcx.thesis import ags, catalog

ANGLES = ("theta", "phi")
#: Thesis metric -> nlcx metric for position signals (unit step) and angles (regulated to 0).
POSITION_METRICS = {"Mp": "overshoot", "tr": "rise_time", "ts": "settling_time", "ess": "steady_state_error"}
ANGLE_METRICS = {"Mp": "peak_deviation", "ts": "settling_time", "ess": "steady_state_error"}


def metric_lookup(metrics: pd.DataFrame) -> dict[tuple[str, str, str], float]:
    """(controller, signal, nlcx metric) -> value of a run's metrics, the first row of each:
    one pass over the frame, so a table of cells is read without one filter per cell."""
    return rows_lookup(zip(metrics.controller, metrics.signal, metrics.metric, metrics.value, strict=True))


def rows_lookup(rows: Iterable[Sequence[Any]]) -> dict[tuple[str, str, str], float]:
    """:func:`metric_lookup` of metric rows that start (controller, signal, metric, value), as
    :attr:`nlcx.engine.results.ExperimentResult.metric_rows` gives them without building a DataFrame (a missing
    value is NaN, as in the frame)."""
    out: dict[tuple[str, str, str], float] = {}
    for controller, signal, metric, value, *_ in rows:
        out.setdefault((controller, signal, metric), math.nan if value is None else float(value))
    return out


def lookup_value(values: dict[tuple[str, str, str], float], controller: str, signal: str, metric: str) -> float:
    """Our number for a thesis (signal, metric) from :func:`metric_lookup`: M_p of a position
    is overshoot/100."""
    mapping = ANGLE_METRICS if signal in ANGLES else POSITION_METRICS
    name = mapping.get(metric)
    value = math.nan if name is None else values.get((controller, signal, name), math.nan)
    return value / 100.0 if name == "overshoot" else value


def thesis_value(metrics: pd.DataFrame, controller: str, signal: str, metric: str) -> float:
    """Our number for a thesis (signal, metric) of one run's metrics (:func:`lookup_value`)."""
    return lookup_value(metric_lookup(metrics), controller, signal, metric)


def _metric_row(printed: Any, metrics: pd.DataFrame, status: dict[str, str]) -> dict[str, object]:
    """One printed cell (signal, metric, controller; a row of the thesis's metrics by itertuples) with
    our number beside it."""
    ours = thesis_value(metrics, printed.controller, printed.signal, printed.metric)
    angle_peak = printed.signal in ANGLES and printed.metric == "Mp"
    unit = "rad" if angle_peak else ("s" if printed.metric in ("tr", "ts") else "")
    return {
        "signal": printed.signal,
        "metric": printed.metric,
        "controller": printed.controller,
        "thesis": float(printed.value),
        "nlcx": ours,
        "delta": ours - float(printed.value),
        "unit": unit,
        "nlcx_status": status.get(printed.controller, "missing"),
    }


def _improvements(table: pd.DataFrame, column: str) -> list[float]:
    """The improvement % of the proposed controller's row of every (signal, metric), from ``column``;
    NaN on the other rows and for e_ss (the thesis gives none)."""
    out = []
    for row in table.itertuples(index=False):
        pair = table[(table.signal == row.signal) & (table.metric == row.metric)].set_index("controller")
        if row.controller != "proposed" or "conventional" not in pair.index or row.metric == "ess":
            out.append(math.nan)
            continue
        out.append(thesis_improvement(pair.loc["conventional", column], pair.loc["proposed", column]))
    return out


def metrics_table(table: str, metrics: pd.DataFrame, status: dict[str, str]) -> pd.DataFrame:
    """A metrics table (e.g. Table 2.3) from one run's metrics and its controllers' status."""
    thesis = catalog.thesis_metrics()
    printed = thesis[thesis.table == table]
    out = pd.DataFrame([_metric_row(r, metrics, status) for r in printed.itertuples(index=False)])
    out["improvement_thesis_pct"] = _improvements(out, "thesis")
    out["improvement_nlcx_pct"] = _improvements(out, "nlcx")
    return out


def plant_table(params: dict[str, float]) -> pd.DataFrame:
    """Table 2.1 (M, m, l, g) beside the plant parameters run."""
    printed = {"M": 1.0, "m": 0.1, "l": 0.3, "g": 9.8}
    units = {"M": "kg", "m": "kg", "l": "m", "g": "m/s^2"}
    return pd.DataFrame([{"parameter": k, "nlcx": params[k], "thesis": printed[k], "unit": units[k]} for k in printed])


def _ags_rows(table: pd.DataFrame, signal: str, schedule: dict[str, Any]) -> list[list[object]]:
    """One loop's min, max and rate k of each gain as run, beside the printed ones (NaN: not printed)."""
    printed = signal in table.index
    loop = table.loc[signal, "loop"] if printed else ""
    rows = []
    for gain in ags.GAINS:
        for end in ("min", "max"):
            thesis = table.loc[signal, f"{gain}_{end}"] if printed else math.nan
            rows.append([schedule["kind"], loop, signal, f"{gain}_{end}", schedule[gain][end], thesis])
        rate = ags.printed_rate(signal, gain)
        rows.append([schedule["kind"], loop, signal, f"rate_{gain}", schedule["rate"][gain], rate])
    return rows


def ags_table(table: str, configs: list[dict[str, Any]]) -> pd.DataFrame:
    """The AGS ranges and rates of the proposed controller of each resolved config, beside
    Table ``table`` (2.2, 3.1, 3.6 or 4.1) and the rates of section 2.3."""
    printed = ags.printed_ranges(table)
    rows = []
    for config in configs:
        for signal, loop in config["controllers"]["proposed"]["loops"].items():
            rows += _ags_rows(printed, signal, loop["schedule"])
    return pd.DataFrame(rows, columns=["schedule", "loop", "signal", "parameter", "nlcx", "thesis"])

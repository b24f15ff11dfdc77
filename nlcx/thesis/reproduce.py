"""``nlcx reproduce``: every pendulum figure and table of the thesis, ours beside theirs.

Writes into the output directory (default ``results/thesis``):

- ``figures/fig_<chapter>_<number>.png``, laid out like the thesis figure;
- ``tables/table_<chapter>_<number>.csv``: metrics tables with the thesis's number, ours,
  the difference and the improvement % by the thesis's formula; parameter tables written
  from the configs actually run, beside the printed values;
- ``claims.csv``: every qualitative claim with ``reproduced`` yes/no/partly and evidence;
- ``runs/<name>/``: metrics.csv, config.yaml and manifest.json of every experiment run.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from nlcx.config import load as load_config
from nlcx.errors import ConfigError, NlcxError
from nlcx.thesis import catalog, cstr
from nlcx.thesis.catalog import FigureSpec, TableSpec

ANGLES = ("theta", "phi")
#: The rates k of section 2.3 (data/ags_rates.csv): angle loops, position loops; z: not printed.
PRINTED_RATES = {
    "theta": {"kp": 0.1, "ki": 0.1, "kd": 0.05},
    "phi": {"kp": 0.1, "ki": 0.1, "kd": 0.05},
    "x": {"kp": 0.1, "ki": 0.1, "kd": 0.25},
    "y": {"kp": 0.1, "ki": 0.1, "kd": 0.25},
}
#: Thesis metric -> nlcx metric for position signals (unit step) and angles (regulated to 0).
POSITION_METRICS = {"Mp": "overshoot", "tr": "rise_time", "ts": "settling_time", "ess": "steady_state_error"}
ANGLE_METRICS = {"Mp": "peak_deviation", "ts": "settling_time", "ess": "steady_state_error"}


@dataclass
class Record:
    """What one experiment run hands back to the parent process."""

    config: Path
    name: str
    resolved: dict[str, Any]
    metrics: pd.DataFrame
    status: dict[str, str]
    extras: pd.DataFrame
    lyapunov: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)
    tuning: list[dict[str, Any]] = field(default_factory=list)
    #: Each controller's configuration as built (after its tuners).
    built: dict[str, dict[str, Any]] = field(default_factory=dict)
    wall: float = 0.0


def thesis_value(metrics: pd.DataFrame, controller: str, signal: str, metric: str) -> float:
    """Our number for a thesis (signal, metric): M_p of a position is overshoot/100."""
    mapping = ANGLE_METRICS if signal in ANGLES else POSITION_METRICS
    name = mapping.get(metric)
    if name is None:
        return math.nan
    rows = metrics[(metrics.controller == controller) & (metrics.signal == signal) & (metrics.metric == name)]
    if rows.empty:
        return math.nan
    value = float(rows.value.iloc[0])
    return value / 100.0 if name == "overshoot" else value


def improvement(conventional: float, proposed: float) -> float:
    """The thesis's % improvement: (conventional - proposed) / proposed x 100."""
    if proposed == 0 or math.isnan(proposed) or math.isnan(conventional):
        return math.nan
    return (conventional - proposed) / proposed * 100.0


def _extras(result: Any) -> pd.DataFrame:
    """Claim evidence not in metrics.csv: tail peak-to-peak, max |y| over the run."""
    plant = result.prepared.plant
    window = result.prepared.experiment.section.metrics.ss_window * 5
    rows = []
    for run in result.runs:
        y = run.x @ plant.C.T
        tail = run.t >= run.t[-1] - window
        for j, name in enumerate(plant.output_names):
            rows.append([run.label, name, "max_abs", float(np.max(np.abs(y[:, j])))])
            rows.append([run.label, name, "tail_ptp", float(np.ptp(y[tail, j]))])
            if name in run.controller.reference_signals:
                col = run.controller.reference_signals.index(name)
                err = run.r[tail, col] - y[tail, j]
                rows.append([run.label, name, "tail_rms_error", float(np.sqrt(np.mean(err**2)))])
        rows.append([run.label, "all", "t_end_reached", float(run.t[-1])])
    return pd.DataFrame(rows, columns=["controller", "signal", "metric", "value"])


def run_config(config: Path, out_dir: Path, figure: tuple[str, str] | None, overrides: tuple[str, ...] = ()) -> Record:
    """Run one experiment, write its run directory and (optionally) its figure."""
    import time

    from nlcx import config as cfg
    from nlcx import engine, report
    from nlcx.thesis.lyapunov import lyapunov_rate

    start = time.perf_counter()
    exp = cfg.load(config, [*overrides, "outputs.timeseries=false", "outputs.figure=false"])
    result = engine.run_experiment(exp)
    report.write_run(result, out_dir / "runs" / exp.name, result.timings, started=start)
    if figure is not None:
        filename, title = figure
        report.write_figure(out_dir / "figures" / filename, report.output_figure(result, title))
    lyap = {}
    plant = result.prepared.plant
    if plant.energy is not None and not exp.uncertainties:
        for run in result.runs:
            if run.status == "ok":
                dV, power = lyapunov_rate(plant, run)
                lyap[run.label] = (run.t[::10], dV[::10], power[::10])
    return Record(
        config=config,
        name=exp.name,
        resolved=exp.resolved(),
        metrics=result.metrics,
        status={run.label: run.status for run in result.runs},
        extras=_extras(result),
        lyapunov=lyap,
        tuning=result.prepared.tuning,
        built={c.label: c.config for c in result.prepared.controllers},
        wall=time.perf_counter() - start,
    )


def _metrics_table(spec: TableSpec, record: Record) -> pd.DataFrame:
    thesis = catalog.thesis_metrics()
    rows = thesis[thesis.table == spec.table]
    out = []
    for r in rows.itertuples(index=False):
        ours = thesis_value(record.metrics, r.controller, r.signal, r.metric)
        unit = "rad" if r.signal in ANGLES and r.metric == "Mp" else ("s" if r.metric in ("tr", "ts") else "")
        out.append(
            {
                "signal": r.signal,
                "metric": r.metric,
                "controller": r.controller,
                "thesis": float(r.value),
                "nlcx": ours,
                "delta": ours - float(r.value),
                "unit": unit,
                "nlcx_status": record.status.get(r.controller, "missing"),
            }
        )
    table = pd.DataFrame(out)
    imp_thesis, imp_ours = [], []
    for row in table.itertuples(index=False):
        other = table[(table.signal == row.signal) & (table.metric == row.metric)].set_index("controller")
        if row.controller != "proposed" or "conventional" not in other.index or row.metric == "ess":
            imp_thesis.append(math.nan)
            imp_ours.append(math.nan)
            continue
        imp_thesis.append(improvement(other.loc["conventional", "thesis"], other.loc["proposed", "thesis"]))
        imp_ours.append(improvement(other.loc["conventional", "nlcx"], other.loc["proposed", "nlcx"]))
    table["improvement_thesis_pct"] = imp_thesis
    table["improvement_nlcx_pct"] = imp_ours
    return table


def _plant_table(records: list[Record]) -> pd.DataFrame:
    params = records[0].resolved["plant"]["params"]
    printed = {"M": 1.0, "m": 0.1, "l": 0.3, "g": 9.8}
    units = {"M": "kg", "m": "kg", "l": "m", "g": "m/s^2"}
    return pd.DataFrame([{"parameter": k, "nlcx": params[k], "thesis": printed[k], "unit": units[k]} for k in printed])


def _ags_table(spec: TableSpec, records: list[Record]) -> pd.DataFrame:
    """The AGS ranges and rates of the proposed controllers actually run, beside Table X."""
    printed = catalog.gain_ranges()
    printed = printed[printed.table == spec.table].set_index("signal")
    rows = []
    for record in records:
        proposed = record.resolved["controllers"]["proposed"]
        for signal, loop in proposed["loops"].items():
            sched = loop["schedule"]
            pid = printed.loc[signal, "loop"] if signal in printed.index else ""
            for gain in ("kp", "ki", "kd"):
                for end in ("min", "max"):
                    thesis = printed.loc[signal, f"{gain}_{end}"] if signal in printed.index else math.nan
                    rows.append([sched["kind"], pid, signal, f"{gain}_{end}", sched[gain][end], thesis])
                rows.append(
                    [
                        sched["kind"],
                        pid,
                        signal,
                        f"rate_{gain}",
                        sched["rate"][gain],
                        PRINTED_RATES.get(signal, {}).get(gain, math.nan),
                    ]
                )
    return pd.DataFrame(rows, columns=["schedule", "loop", "signal", "parameter", "nlcx", "thesis"])


def select(
    figs: list[FigureSpec], tabs: list[TableSpec], chapters: Iterable[int] | None, only: Iterable[str] | None
) -> tuple[list[FigureSpec], list[TableSpec]]:
    """Filter by chapter and by keys such as ``fig-2.4`` or ``table-2.3``."""
    chapters = set(chapters or [])
    only = {k.strip() for k in (only or []) if k.strip()}
    known = {f.key for f in figs} | {t.key for t in tabs}
    unknown = only - known
    if unknown:
        raise NlcxError(f"--only: unknown {', '.join(sorted(unknown))}; use keys like fig-2.4, table-2.3")
    if chapters:
        figs = [f for f in figs if f.chapter in chapters]
        tabs = [t for t in tabs if t.chapter in chapters]
    if only:
        figs = [f for f in figs if f.key in only]
        tabs = [t for t in tabs if t.key in only]
    return figs, tabs


def reproduce(
    root: Path,
    out_dir: Path,
    chapters: Iterable[int] | None = None,
    only: Iterable[str] | None = None,
    jobs: int | None = None,
    progress: Any = None,
    overrides: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Run what the selected figures and tables need, then write them and the claims."""
    from nlcx import report
    from nlcx.thesis import claims

    figs, tabs = select(catalog.figures(root), catalog.tables(root), chapters, only)
    response_titles = {f.configs[0]: (f.filename, f.title) for f in figs if f.kind == "response"}
    needed = dict.fromkeys([c for f in figs for c in f.configs] + [c for t in tabs for c in t.configs])
    if claims_needed := not only:
        needed.update(dict.fromkeys(claims.configs_for(root, {f.chapter for f in figs} | {t.chapter for t in tabs})))
    missing = [str(c) for c in needed if not c.is_file()]
    if missing:
        raise NlcxError(f"missing experiment config(s): {', '.join(missing[:3])}")
    for config in needed:  # fail fast, in this process, on a bad config
        try:
            load_config(config, list(overrides))
        except ConfigError as exc:
            raise NlcxError(f"{config}: {exc}") from None
    jobs = jobs or os.cpu_count() or 1
    records: dict[Path, Record] = {}
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {c: pool.submit(run_config, c, out_dir, response_titles.get(c), overrides) for c in needed}
        for config, future in futures.items():
            records[config] = future.result()
            if progress is not None:
                progress(records[config])
    for spec in figs:
        if spec.kind == "lyapunov":
            report.write_figure(
                out_dir / "figures" / spec.filename,
                claims.lyapunov_figure(spec, [records[c] for c in spec.configs]),
            )
        elif spec.kind == "membership":
            from nlcx.controllers.fuzzy import membership_figure

            schedule = cstr._fuzzy_schedule(records[spec.configs[0]])
            fig = membership_figure(schedule, spec.variable)
            fig.axes[0].set_title(spec.title, fontsize=10)
            report.write_figure(out_dir / "figures" / spec.filename, fig)
    written_tables = {}
    for spec in tabs:
        recs = [records[c] for c in spec.configs]
        if spec.kind == "metrics":
            table = _metrics_table(spec, recs[0])
        elif spec.kind == "plant":
            table = _plant_table(recs)
        elif spec.kind == "ags":
            table = _ags_table(spec, recs)
        elif spec.kind == "cstr_metrics":
            table = cstr.table_5_8(records, root)
        elif spec.kind == "zn_rules":
            table = cstr.table_5_1(recs[0])
        elif spec.kind == "fuzzy_universes":
            table = cstr.table_5_2(recs[0])
        else:
            table = cstr.table_sets(recs[0], spec.variable)
        report.write_csv(out_dir / "tables" / spec.filename, table)
        written_tables[spec.table] = table
    summary: dict[str, Any] = {"figures": [f.figure for f in figs], "tables": sorted(written_tables)}
    if not only and 5 in {f.chapter for f in figs}:
        summary["zn_variants"] = cstr.zn_variants(root, out_dir)
    if claims_needed:
        claim_table = claims.evaluate(root, records, {f.chapter for f in figs} | {t.chapter for t in tabs})
        report.write_csv(out_dir / "claims.csv", claim_table)
        summary["claims"] = claim_table
    summary["tables_data"] = written_tables
    summary["records"] = records
    return summary

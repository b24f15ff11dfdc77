"""``nlcx reproduce``: every pendulum figure and table of the thesis, ours beside theirs.

Writes into the output directory (default ``results/thesis``):

- ``figures/fig_<chapter>_<number>.png``, laid out like the thesis figure;
- ``tables/table_<chapter>_<number>.csv``: metrics tables with the thesis's number, ours,
  the difference and the improvement % by the thesis's formula; parameter tables written
  from the configs actually run, beside the printed values;
- ``claims.csv``: every qualitative claim with ``reproduced`` yes/no/partly and evidence;
- ``runs/<name>/``: metrics.csv, config.yaml and manifest.json of every experiment run.

:func:`reproduce` writes into the directory it is given as it stands; ``nlcx reproduce``
hands it a staged directory that is renamed into place when complete (:func:`nlcx.rundir.staged`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np
import pandas as pd

from nlcx import runtime
from nlcx.errors import ConfigError, NlcxError, did_you_mean
from nlcx.thesis import catalog, cstr, profiles, tables
from nlcx.thesis.catalog import FigureSpec, TableSpec
from nlcx.thesis.records import Record

if TYPE_CHECKING:
    from nlcx.engine import ExperimentResult


def _extras(result: ExperimentResult) -> pd.DataFrame:
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


def run_config(
    config: Path,
    out_dir: Path,
    figure: tuple[str, str] | None,
    overrides: tuple[str, ...] = (),
    profile: profiles.Profile | None = None,
) -> Record:
    """Run one experiment (under ``profile``), write its run directory and (optionally) its figure."""
    import time

    from nlcx import drawing, engine, figure_plans, report
    from nlcx.thesis.lyapunov import lyapunov_rate

    start = time.perf_counter()
    applied = [*overrides, "outputs.timeseries=false", "outputs.figure=false"]
    exp = profiles.experiment(config, applied, profile)
    result = engine.run_experiment(exp)
    report.write_run(result, out_dir / "runs" / exp.name, result.timings, started=start, overrides=applied)
    if figure is not None:
        filename, title = figure
        drawing.write_figure(out_dir / "figures" / filename, figure_plans.output_figure(result, title))
    lyap = {}
    plant = result.prepared.plant
    if plant.features.energy is not None and not exp.uncertainties:
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


def select(
    figs: list[FigureSpec], tabs: list[TableSpec], chapters: Iterable[int] | None, only: Iterable[str] | None
) -> tuple[list[FigureSpec], list[TableSpec]]:
    """Filter by chapter and by keys such as ``fig-2.4`` or ``table-2.3``."""
    chapters = set(chapters or [])
    only = {k.strip() for k in (only or []) if k.strip()}
    known = {f.key for f in figs} | {t.key for t in tabs}
    unknown = only - known
    if unknown:
        first = sorted(unknown)[0]
        raise NlcxError(
            f"--only: unknown {', '.join(sorted(unknown))}{did_you_mean(first, sorted(known))}; "
            "use keys like fig-2.4, table-2.3"
        )
    if chapters:
        figs = [f for f in figs if f.chapter in chapters]
        tabs = [t for t in tabs if t.chapter in chapters]
    if only:
        figs = [f for f in figs if f.key in only]
        tabs = [t for t in tabs if t.key in only]
    return figs, tabs


def _chapters(figs: list[FigureSpec], tabs: list[TableSpec]) -> set[int]:
    """The chapters the selected figures and tables belong to."""
    return {f.chapter for f in figs} | {t.chapter for t in tabs}


def _needed_configs(root: Path, figs: list[FigureSpec], tabs: list[TableSpec], with_claims: bool) -> list[Path]:
    """Every config the figures and tables (and, ``with_claims``, their chapters' claims) need."""
    from nlcx.thesis import claims

    needed = dict.fromkeys([c for f in figs for c in f.configs] + [c for t in tabs for c in t.configs])
    if with_claims:
        needed.update(dict.fromkeys(claims.configs_for(root, _chapters(figs, tabs))))
    return list(needed)


def _check_configs(configs: list[Path], overrides: tuple[str, ...], profile: profiles.Profile | None) -> None:
    """Fail fast, in this process, on a missing or bad config."""
    missing = [str(c) for c in configs if not c.is_file()]
    if missing:
        raise NlcxError(f"missing experiment config(s): {', '.join(missing[:3])}")
    from nlcx.tuning.ga import require_tuning_extra

    for config in configs:
        try:
            experiment = profiles.experiment(config, list(overrides), profile)
        except ConfigError as exc:
            raise NlcxError(f"{config}: {exc}") from None
        require_tuning_extra(experiment.controllers, f"{config}: ")  # GA-tuned: needs pymoo


def _run_all(
    configs: list[Path],
    out_dir: Path,
    titles: dict[Path, tuple[str, str]],
    overrides: tuple[str, ...],
    jobs: int,
    progress: Callable[[Record], object] | None,
    profile: profiles.Profile | None = None,
) -> dict[Path, Record]:
    """Run every config in a process pool, in order, drawing the response figures named in ``titles``."""
    records: dict[Path, Record] = {}
    with ProcessPoolExecutor(max_workers=jobs, initializer=runtime.worker) as pool:
        futures = {c: pool.submit(run_config, c, out_dir, titles.get(c), overrides, profile) for c in configs}
        for config, future in futures.items():
            records[config] = future.result()
            if progress is not None:
                progress(records[config])
    return records


def _write_figure(spec: FigureSpec, records: dict[Path, Record], out_dir: Path) -> None:
    """A figure drawn from finished runs: V-dot of Theorems 2.1-4.1, or Figs. 5.4-5.8's membership functions."""
    from nlcx import drawing
    from nlcx.thesis import claims

    if spec.kind == "lyapunov":
        fig = claims.lyapunov_figure(spec, [records[c] for c in spec.configs])
    else:
        from nlcx.thesis.membership import membership_figure

        fig = membership_figure(cstr.fuzzy_schedule(records[spec.configs[0]]), spec.variable)
        fig.axes[0].set_title(spec.title, fontsize=10)
    drawing.write_figure(out_dir / "figures" / spec.filename, fig)


def _table(spec: TableSpec, records: dict[Path, Record], root: Path) -> pd.DataFrame:
    """One thesis table, ours beside theirs, from the runs it needs."""
    recs = [records[c] for c in spec.configs]
    if spec.kind == "metrics":
        return tables.metrics_table(spec.table, recs[0].metrics, recs[0].status)
    if spec.kind == "plant":
        return tables.plant_table(recs[0].resolved["plant"]["params"])
    if spec.kind == "ags":
        return tables.ags_table(spec.table, [r.resolved for r in recs])
    if spec.kind == "cstr_metrics":
        return cstr.table_5_8(records, root)
    if spec.kind == "zn_rules":
        return cstr.table_5_1(recs[0])
    if spec.kind == "fuzzy_universes":
        return cstr.table_5_2(recs[0])
    return cstr.table_sets(recs[0], spec.variable)


class _Written(TypedDict):
    #: The figures and the tables written.
    figures: list[str]
    tables: list[str]


class Reproduction(_Written, total=False):
    """What :func:`reproduce` wrote and the runs it wrote them from (``tables_data`` and
    ``records`` always, added last)."""

    #: The ZN variants of chapter 5 (when its figures were selected and nothing was left out).
    zn_variants: pd.DataFrame
    #: The claims table (when nothing was left out).
    claims: pd.DataFrame
    tables_data: dict[str, pd.DataFrame]
    records: dict[Path, Record]


def reproduce(
    root: Path,
    out_dir: Path,
    chapters: Iterable[int] | None = None,
    only: Iterable[str] | None = None,
    jobs: int | None = None,
    progress: Callable[[Record], object] | None = None,
    overrides: tuple[str, ...] = (),
    profile: profiles.Profile | None = None,
) -> Reproduction:
    """Run what the selected figures and tables need (every experiment under ``profile``),
    then write them and the claims."""
    from nlcx import report
    from nlcx.thesis import claims

    figs, tabs = select(catalog.figures(root), catalog.tables(root), chapters, only)
    claims_needed = not only
    needed = _needed_configs(root, figs, tabs, claims_needed)
    _check_configs(needed, overrides, profile)
    titles = {f.configs[0]: (f.filename, f.title) for f in figs if f.kind == "response"}
    records = _run_all(needed, out_dir, titles, overrides, jobs or os.cpu_count() or 1, progress, profile)
    for spec in figs:
        if spec.kind in ("lyapunov", "membership"):
            _write_figure(spec, records, out_dir)
    written_tables = {}
    for table in tabs:
        written_tables[table.table] = _table(table, records, root)
        report.write_csv(out_dir / "tables" / table.filename, written_tables[table.table])
    summary: Reproduction = {"figures": [f.figure for f in figs], "tables": sorted(written_tables)}
    if not only and 5 in {f.chapter for f in figs}:
        summary["zn_variants"] = cstr.zn_variants(root, out_dir)
    if claims_needed:
        claim_table = claims.evaluate(root, records, _chapters(figs, tabs))
        report.write_csv(out_dir / "claims.csv", claim_table)
        summary["claims"] = claim_table
    summary["tables_data"] = written_tables
    summary["records"] = records
    return summary

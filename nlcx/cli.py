"""The ``nlcx`` command line."""

from __future__ import annotations

import functools
import gc
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer

from nlcx import registry
from nlcx.compiled_cache import CompileHelper
from nlcx.errors import ConfigError, NlcxError

if TYPE_CHECKING:
    from nlcx.drawing import Painter

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Reproducible experiments on the control of nonlinear systems.",
)

F = TypeVar("F", bound=Callable[..., Any])

ConfigArg = Annotated[Path, typer.Argument(help="Experiment YAML file.", show_default=False)]
OverridesArg = Annotated[
    list[str] | None,
    typer.Argument(help="Overrides key=value with dotted keys, e.g. simulation.t_end=30.", show_default=False),
]
NoReport = Annotated[bool, typer.Option("--no-report", help="Do not write report.html / report.md.")]


def one_line_errors(func: F) -> F:
    """Report nlcx errors as one line on stderr (exit 2) instead of a traceback."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except (typer.Exit, typer.Abort):
            raise
        except NlcxError as exc:
            typer.echo(str(exc), err=True)
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            typer.echo("interrupted: files already written are complete", err=True)
            raise typer.Exit(130) from None
        except Exception as exc:
            if os.environ.get("NLCX_DEBUG"):
                raise
            typer.echo(f"error: {type(exc).__name__}: {exc} (set NLCX_DEBUG=1 for a traceback)", err=True)
            raise typer.Exit(1) from None

    return wrapper  # type: ignore[return-value]


def _imported() -> None:
    """Collect garbage again from here on, leaving out what the imports built (frozen).

    :func:`main` holds the collector off while a command imports numba, pandas and
    matplotlib: collecting their object graphs over and over costs ~15 % of the imports."""
    gc.freeze()
    gc.enable()


def _painter(raw: dict[str, Any]) -> Painter | None:
    """A figure painter process (:class:`nlcx.drawing.Painter`) unless the config turns every
    figure off (unset keys take :class:`nlcx.config.OutputsSection`'s defaults)."""
    from nlcx.config import OutputsSection
    from nlcx.drawing import Painter

    outputs = raw.get("outputs") if isinstance(raw.get("outputs"), dict) else {}
    fields = OutputsSection.model_fields
    if all(outputs.get(key, fields[key].default) is False for key in ("figure", "gains_figure")):
        return None
    return Painter()


def _fmt(value: float) -> str:
    return "—" if value is None or math.isnan(value) else f"{value:.4g}"


def _summary(result: Any) -> str:
    """Per controller and regulated output: the headline metrics of the thesis's tables."""
    lines = []
    for run in result.runs:
        if run.status != "ok":
            lines.append(f"  {run.label:<14} {run.status}: {run.reason}")
            continue
        by_signal: dict[str, dict[str, float]] = {}
        for controller, signal, metric, value, *_ in result.metric_rows:
            if controller == run.label:
                by_signal.setdefault(signal, {})[metric] = value
        parts = []
        for signal, sub in by_signal.items():
            if "overshoot" in sub:
                parts.append(
                    f"{signal}: Mp {_fmt(sub['overshoot'])}% tr {_fmt(sub['rise_time'])}s "
                    f"ts {_fmt(sub['settling_time'])}s"
                )
            elif "peak_deviation" in sub:
                parts.append(f"{signal}: peak {_fmt(sub['peak_deviation'])} ts {_fmt(sub['settling_time'])}s")
        lines.append(f"  {run.label:<14} ok    " + " | ".join(parts))
    return "\n".join(lines)


@app.command()
@one_line_errors
def run(
    config: ConfigArg,
    overrides: OverridesArg = None,
    out: Annotated[Path | None, typer.Option("--out", help="Run directory (default results/<name>).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print only the run directory.")] = False,
    no_report: NoReport = False,
) -> None:
    """Run an experiment: every controller of CONFIG on its plant, then write the run directory."""
    from nlcx import config as cfg

    raw = cfg.apply_overrides(cfg.read_config(config), overrides or [])
    if "sweep" in raw:
        _sweep(config, overrides or [], out, "process", 2, None, False, False, not no_report)
        return
    painter = _painter(raw)  # imports matplotlib in another process while this one imports the engine
    helper = CompileHelper([sys.executable, "-m", "nlcx.cli", "prewarm", str(config), *(overrides or [])])
    try:
        from nlcx import engine, report

        _imported()
        with helper.watching():  # a slow load means an empty numba cache: `nlcx prewarm` compiles alongside
            engine.load_kernel()
        start = time.perf_counter()
        exp = cfg.build(cfg.interpolate(raw))  # cfg.load's steps on the config already read
        loaded = time.perf_counter()
        result = engine.run_experiment(exp)
        out_dir = out or Path(exp.section.outputs.dir or Path("results") / exp.name)
        timings = {"load": loaded - start, **result.timings}
        report.write_run(result, out_dir, timings, started=start, painter=painter)
    finally:
        if painter is not None:
            painter.close()
        helper.close()
    page = None if no_report else _write_report(out_dir)
    elapsed = time.perf_counter() - start
    if quiet:
        typer.echo(str(out_dir))
        return
    typer.echo(
        f"{exp.name}: {exp.section.plant.name}, {len(result.runs)} controller(s), "
        f"{result.prepared.grid.n_steps} steps of {result.prepared.grid.dt:g} s"
    )
    typer.echo(_summary(result))
    typer.echo(f"wrote {out_dir}/ in {elapsed:.2f} s" + (f"; report {page}" if page else ""))


@app.command(hidden=True)
@one_line_errors
def prewarm(config: ConfigArg, overrides: OverridesArg = None) -> None:
    """Compile what a run of CONFIG needs besides the kernel into numba's cache (``nlcx run``
    starts this beside itself when the cache is empty; see nlcx.engine.prewarm)."""
    from nlcx import config as cfg
    from nlcx import engine

    engine.prewarm(cfg.load(config, overrides or []))


def _sweep(
    config: Path,
    overrides: list[str],
    out: Path | None,
    executor: str,
    jobs: int,
    scheduler: str | None,
    force: bool,
    dry_run: bool,
    with_report: bool = True,
) -> None:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from nlcx import sweep

    _imported()

    if dry_run:
        base_raw, spec, base = sweep.load(config, overrides)
        variants, hashes = sweep.plan(base_raw, spec)
        typer.echo(f"{base.name}: {len(variants)} variant(s) x {len(base.controllers)} controller(s)")
        for v, h in list(zip(variants, hashes, strict=True))[:20]:
            values = ", ".join(f"{k}={val!r}" for k, val in v.values.items())
            typer.echo(f"  {v.index:>6}  seed {v.seed:>10}  {h}  {values}")
        if len(variants) > 20:
            typer.echo(f"  ... {len(variants) - 20} more")
        return
    columns = (
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        TextColumn("failed {task.fields[failed]}"), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
    )  # fmt: skip
    with Progress(*columns, transient=False) as bar:
        task = bar.add_task("variants", total=None, failed=0)

        def progress(done: int, total: int, failed: int) -> None:
            bar.update(task, completed=done, total=total, failed=failed)

        outcome = sweep.run(config, overrides, out, executor, jobs, scheduler, force, progress)
    counts = outcome.index.status.value_counts().to_dict() if not outcome.index.empty else {}
    summary = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    typer.echo(
        f"{len(outcome.index)} variants ({outcome.computed} computed, {outcome.skipped} already done): {summary}; "
        f"{outcome.wall:.1f} s -> {outcome.out_dir}/"
    )
    if with_report and not outcome.index.empty:
        typer.echo(f"report {_write_report(outcome.out_dir)}")
    if counts.get("failed"):
        failed = outcome.index[outcome.index.status == "failed"].head(3)
        for row in failed.itertuples():
            typer.echo(f"  variant {row.variant} failed: {row.message}", err=True)
        raise typer.Exit(1)


@app.command("sweep")
@one_line_errors
def sweep_command(
    config: ConfigArg,
    overrides: OverridesArg = None,
    out: Annotated[Path | None, typer.Option("--out", help="Run directory (default results/<name>).")] = None,
    executor: Annotated[str, typer.Option("--executor", help="process, serial or dask.")] = "process",
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes.")] = 2,
    scheduler: Annotated[str | None, typer.Option("--scheduler", help="Dask scheduler address.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Recompute variants that already have results.")] = False,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Print the expansion and stop.")] = False,
    no_report: NoReport = False,
) -> None:
    """Run the sweep of CONFIG (its sweep: section); a rerun resumes where it stopped."""
    if executor not in ("process", "serial", "dask"):
        raise NlcxError(f"--executor = {executor!r}: allowed values: process, serial, dask")
    _sweep(config, overrides or [], out, executor, jobs, scheduler, force, dry_run, not no_report)


@app.command()
@one_line_errors
def validate(config: ConfigArg, overrides: OverridesArg = None) -> None:
    """Check CONFIG (with overrides) without running it; exit 2 with one line if invalid."""
    from nlcx import config as cfg
    from nlcx import engine

    exp = cfg.load(config, overrides or [])
    engine.prepare(exp)
    labels = ", ".join(c.label for c in exp.controllers)
    typer.echo(f"{config}: valid ({exp.section.plant.name}; controllers: {labels})")


@app.command()
@one_line_errors
def reproduce(
    chapter: Annotated[
        list[int] | None, typer.Option("--chapter", "-c", help="Chapter(s) to reproduce (2, 3, 4).")
    ] = None,
    only: Annotated[str | None, typer.Option("--only", help="Comma-separated keys, e.g. fig-2.4,table-2.3.")] = None,
    jobs: Annotated[int | None, typer.Option("--jobs", "-j", help="Worker processes (default: all cores).")] = None,
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("results/thesis"),
    configs: Annotated[Path, typer.Option("--configs", help="Thesis experiment configs.")] = Path("configs/thesis"),
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="Override for every experiment, e.g. plant.params.equations=printed."),
    ] = None,
    profile: Annotated[
        str,
        typer.Option("--profile", help="Loop profile (configs/thesis/profiles/NAME.yaml); literal: as printed."),
    ] = "literal",
    no_report: NoReport = False,
) -> None:
    """Regenerate the thesis's figures and tables (ours beside theirs) and check its claims."""
    from nlcx.thesis import profiles
    from nlcx.thesis.reproduce import reproduce as run_reproduce

    _imported()
    chosen = profiles.load(profile, configs)

    start = time.perf_counter()
    keys = [k for k in (only or "").split(",") if k.strip()]
    done = [0]

    def progress(record: Any) -> None:
        done[0] += 1
        bad = [c for c, s in record.status.items() if s != "ok"]
        note = f" ({', '.join(bad)} unstable)" if bad else ""
        typer.echo(f"  [{done[0]:>3}] {record.name:<12} {record.wall:5.2f} s{note}")

    summary = run_reproduce(
        configs,
        out,
        chapters=chapter,
        only=keys,
        jobs=jobs,
        progress=progress,
        overrides=tuple(set_ or ()),
        profile=chosen,
    )
    typer.echo(f"profile {chosen.name}: {len(summary['figures'])} figures, {len(summary['tables'])} tables -> {out}/")
    if "claims" in summary:
        counts = summary["claims"].reproduced.value_counts().to_dict()
        typer.echo("claims: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    wall = time.perf_counter() - start
    write_reproduction_manifest(out, chosen, wall, jobs)
    typer.echo(f"done in {wall:.1f} s")
    if not no_report:
        t0 = time.perf_counter()
        page = _write_report(out, configs)
        typer.echo(f"report {page} ({time.perf_counter() - t0:.1f} s)")


def write_reproduction_manifest(out: Path, profile: Any, wall: float, jobs: int | None) -> None:
    """manifest.json of a reproduction: the command, profile, versions, commit and run time."""
    import datetime
    import json
    import os
    import sys

    from nlcx import report

    record = {
        "command": "nlcx " + " ".join(sys.argv[1:]),
        "profile": profile.name,
        "profile_source": profile.source,
        "versions": report.package_versions(),
        "git": report.git_state(),
        "wall_s": round(wall, 2),
        "jobs": jobs or os.cpu_count(),
        "started": (datetime.datetime.now() - datetime.timedelta(seconds=wall)).isoformat(timespec="seconds"),
    }
    report.write_text(out / "manifest.json", json.dumps(record, indent=2) + "\n")


def _write_report(directory: Path, configs: Path | None = None) -> Path:
    """DIR/report.html and report.md; returns the page's path."""
    from nlcx.pages.render import write_report

    html, _ = write_report(directory, configs)
    return html


@app.command()
@one_line_errors
def report(
    directory: Annotated[Path, typer.Argument(help="A reproduction, sweep or run directory.", show_default=False)],
    configs: Annotated[Path, typer.Option("--configs", help="Thesis configs (tolerances.yaml).")] = Path(
        "configs/thesis"
    ),
) -> None:
    """Write DIR/report.html and DIR/report.md: one page summarising what DIR holds."""
    if not directory.is_dir():
        raise ConfigError("DIR", str(directory), "an existing output directory")
    typer.echo(str(_write_report(directory, configs)))


@app.command()
@one_line_errors
def calibrate(
    spec: Annotated[Path, typer.Argument(help="Calibration spec YAML.", show_default=False)],
    overrides: OverridesArg = None,
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes evaluating the population.")] = 1,
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory (default results/calibration/<name>).")
    ] = None,
    write: Annotated[bool, typer.Option("--write", help="Write the fitted values into the spec's write.file.")] = False,
) -> None:
    """Fit unprinted numbers (e.g. the conventional gains) to a thesis table with the seeded GA."""
    from nlcx.thesis.calibrate import calibrate as run_calibration
    from nlcx.thesis.calibrate import load_spec, write_back

    _imported()

    name = load_spec(spec, overrides or []).name
    out_dir = out or Path("results/calibration") / name

    def progress(generation: int, best: float) -> None:
        typer.echo(f"  generation {generation:>3}: best loss {best:.5g}")

    outcome = run_calibration(spec, out_dir, jobs=jobs, overrides=overrides or [], progress=progress)
    typer.echo(outcome["tuning"].to_string(index=False))
    typer.echo(outcome["fit"].to_string(index=False))
    if write:
        typer.echo(f"wrote {write_back(spec, outcome)}")
    typer.echo(f"loss {outcome['result'].f:.5g}; results in {out_dir}/")


@app.command()
@one_line_errors
def identify(
    spec: Annotated[Path, typer.Argument(help="Identification spec YAML.", show_default=False)],
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes evaluating each population.")] = 1,
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory (default results/identify/<name>).")
    ] = None,
) -> None:
    """Fit loop hypotheses to the train tables, rank them on validation (resumable).
    A spec with ``chapter: 5`` is chapter 5's study (Table 5.8), ranked by train loss; one with
    ``kind: consistency`` asks of each printed conventional column whether any loop gives it."""
    import yaml

    from nlcx.thesis.consistency import consistency
    from nlcx.thesis.identify import identify as run_identify
    from nlcx.thesis.identify_cstr import identify_cstr

    _imported()
    raw = yaml.safe_load(spec.read_text(encoding="utf-8")) if spec.is_file() else None
    if not isinstance(raw, dict) or not isinstance(raw.get("name"), str):
        raise ConfigError("spec", str(spec), "an identification spec: a YAML mapping with a name")
    out_dir = out or Path("results/identify") / raw["name"]

    def progress(done: int, total: int, name: str) -> None:
        typer.echo(f"  [{done}/{total}] {name}")

    if raw.get("kind") == "consistency":
        columns_table = consistency(spec, out_dir, jobs=jobs, progress=progress)
        shown = columns_table[["table", "definition", "loops", "most_cells_hit", "cells", "reproduced"]]
        typer.echo(shown.to_string(index=False))
        typer.echo(f"results in {out_dir}/")
        return
    if raw.get("chapter") == 5:
        ranking = identify_cstr(spec, out_dir, jobs=jobs, progress=progress)
        columns = ["rank", "hypothesis", "train_loss", "test_median_rel_error"]
        typer.echo(ranking[columns].head(10).to_string(index=False))
        typer.echo(f"{len(ranking)} hypotheses; results in {out_dir}/")
        return
    ranking = run_identify(spec, out_dir, jobs=jobs, progress=progress)
    columns = ["rank", "hypothesis", "train_loss", "validation_median_rel_error", "validation_direction_agreement"]
    typer.echo(ranking[columns].head(10).to_string(index=False))
    typer.echo(f"{len(ranking)} hypotheses; results in {out_dir}/")


@app.command()
@one_line_errors
def diff(
    base: Annotated[Path, typer.Argument(help="Baseline directory (or CSV or Parquet file).", show_default=False)],
    new: Annotated[Path, typer.Argument(help="Directory (or CSV or Parquet file) to check.", show_default=False)],
    rtol: Annotated[
        list[str] | None, typer.Option("--rtol", help="Relative tolerance: VALUE (default) or METRIC=VALUE.")
    ] = None,
    atol: Annotated[
        list[str] | None, typer.Option("--atol", help="Absolute tolerance: VALUE (default) or METRIC=VALUE.")
    ] = None,
) -> None:
    """Compare the CSV (and Parquet) files of NEW against BASE; exit 1 and list the drift if any cell moved."""
    from nlcx.diff import diff_dirs, parse_tolerances, render

    tol = parse_tolerances(rtol or [], atol or [])
    drifts, n_files = diff_dirs(base, new, tol)
    if drifts:
        typer.echo(render(drifts))
        typer.echo(f"drift: {len(drifts)} cell(s) in {len({d.file for d in drifts})} of {n_files} file(s)")
        raise typer.Exit(1)
    typer.echo(f"no drift: {n_files} file(s) within rtol {tol.rtol} atol {tol.atol}")


def _metrics_error(key: str, value: object, problem: str, allowed: str) -> NlcxError:
    """The one-line error of ``nlcx metrics``: ``metrics error: KEY = VALUE: PROBLEM; allowed: ALLOWED``."""
    text = f"metrics error: {key} = {value}: {problem}; allowed: {allowed}"
    return NlcxError(" ".join(text.split()))  # one line, whatever a parser's message held


def _names(names: list[str], limit: int = 20) -> str:
    more = f", ... ({len(names) - limit} more)" if len(names) > limit else ""
    return (", ".join(names[:limit]) + more) or "(none)"


def _csv_column(frame: Any, column: str, key: str, file: Path) -> Any:
    """Column ``column`` of ``frame`` as finite floats; a one-line error naming ``key`` if it is not."""
    import numpy as np
    import pandas as pd

    raw = frame[column]
    values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64)
    text = np.isnan(values) & raw.notna().to_numpy()
    if text.any():
        k = int(np.argmax(text))
        numeric = [str(c) for c in frame.columns if pd.api.types.is_numeric_dtype(frame[c])]
        problem = f"not numeric in {file.name} (data row {k + 1}: {raw.iloc[k]!r})"
        raise _metrics_error(key, column, problem, f"a column of numbers: {_names(numeric)}")
    bad = ~np.isfinite(values)
    if bad.any():
        k = int(np.argmax(bad))
        problem = f"empty or non-finite in {file.name} (data row {k + 1}: {raw.iloc[k]})"
        raise _metrics_error(key, column, problem, "a finite number in every row")
    return values


def _read_step_data(file: Path, time_column: str, signals: list[str], t_step: float) -> tuple[Any, Any, list[str]]:
    """The times ``(T,)``, the signals ``(B, T)`` and their names from the CSV (or Parquet)
    ``file``, checked for :func:`nlcx.metrics.step_info`; the first problem found is a
    one-line error."""
    import numpy as np
    import pandas as pd

    allowed = "a CSV file with a header row, or a Parquet file"
    if not file.is_file():
        problem = "not a file" if file.exists() else "no such file"
        raise _metrics_error("FILE", file, problem, allowed)
    parquet = file.suffix == ".parquet"
    try:
        frame = pd.read_parquet(file) if parquet else pd.read_csv(file)
    except (OSError, ValueError) as exc:  # pandas' and pyarrow's parser errors are ValueErrors or OSErrors
        raise _metrics_error(
            "FILE", file, f"not readable as {'Parquet' if parquet else 'CSV'} ({exc})", allowed
        ) from None
    columns = [str(c) for c in frame.columns]
    frame.columns = columns
    if time_column not in columns:
        raise _metrics_error("--time", time_column, f"not a column of {file.name}", _names(columns))
    others = [c for c in columns if c != time_column]
    names = list(dict.fromkeys(signals))
    if not names:
        raise _metrics_error("--signal", "(missing)", "no column to measure", _names(others))
    for name in names:
        if name not in others:
            problem = "is the --time column" if name == time_column else f"not a column of {file.name}"
            raise _metrics_error("--signal", name, problem, _names(others))
    if len(frame) < 3:
        raise _metrics_error("FILE", file, f"{len(frame)} sample(s)", "at least 3 samples")
    t = _csv_column(frame, time_column, "--time", file)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        problem = f"not strictly increasing in {file.name} (data row {k + 1}: {t[k]:g} after {t[k - 1]:g})"
        raise _metrics_error("--time", time_column, problem, "strictly increasing times")
    y = np.vstack([_csv_column(frame, name, "--signal", file) for name in names])
    if not t[0] <= t_step <= t[-3]:
        allowed = f"{t[0]:g} <= t_step <= {t[-3]:g} (at least 3 samples from the step on)"
        raise _metrics_error("--t-step", f"{t_step:g}", f"outside the record of {file.name}", allowed)
    return t, y, names


@app.command("metrics")
@one_line_errors
def metrics_command(
    file: Annotated[Path, typer.Argument(help="CSV file with a header row, or a Parquet file.", show_default=False)],
    time_column: Annotated[str, typer.Option("--time", help="Time column, in seconds.")] = "t",
    signals: Annotated[
        list[str] | None, typer.Option("--signal", help="Column to measure; repeat for several.", show_default=False)
    ] = None,
    reference: Annotated[
        float | None,
        typer.Option("--reference", help="Target value (default: each signal's last sample).", show_default=False),
    ] = None,
    t_step: Annotated[float, typer.Option("--t-step", help="Step time in s; earlier samples are ignored.")] = 0.0,
    out: Annotated[
        Path | None, typer.Option("--out", help="Write signal, metric, value, unit to this CSV.", show_default=False)
    ] = None,
) -> None:
    """Step-response metrics of CSV columns (e.g. logged on a rig): rise and settling time, overshoot, ...

    Measured by nlcx.metrics.step_info from each signal's value at --t-step to its last sample (or --reference)."""
    import pandas as pd

    from nlcx.metrics import STEP_INFO_METRICS, STEP_INFO_UNITS, step_info

    if reference is not None and not math.isfinite(reference):
        raise _metrics_error("--reference", reference, "not finite", "a finite number")
    t, y, names = _read_step_data(file, time_column, signals or [], t_step)
    info = step_info(t, y, reference=reference, t_step=t_step)
    rows = [
        (name, key, float(info[key][b]), STEP_INFO_UNITS[key])
        for b, name in enumerate(names)
        for key in STEP_INFO_METRICS
    ]
    table = pd.DataFrame(rows, columns=["signal", "metric", "value", "unit"])
    final = "last sample" if reference is None else f"{reference:g}"
    typer.echo(
        f"{file.name}: {t.size} samples, t = {t[0]:g} to {t[-1]:g} s; step at {t_step:g} s; final value: {final}"
    )
    width = max(10, *(len(n) for n in names))
    typer.echo(f"  {'metric':<20}{'unit':<8}" + "".join(f"{n:>{width + 2}}" for n in names))
    for key in STEP_INFO_METRICS:
        values = "".join(f"{_fmt(float(info[key][b])):>{width + 2}}" for b in range(len(names)))
        typer.echo(f"  {key:<20}{STEP_INFO_UNITS[key]:<8}{values}")
    if out is not None:
        from nlcx.report import write_csv  # imports the engine: only when writing

        write_csv(out, table)
        typer.echo(f"wrote {out}")


@app.command("list")
@one_line_errors
def list_plugins(
    kind: Annotated[str | None, typer.Argument(help=f"One of: {', '.join(registry.ALL)}.")] = None,
) -> None:
    """List the registered plants, controllers, gain schedules, uncertainties and references."""
    kinds = [kind] if kind else list(registry.ALL)
    for name in kinds:
        if name not in registry.ALL:
            raise NlcxError(f"unknown kind {name!r}; allowed: {', '.join(registry.ALL)}")
        typer.echo(f"{name}:")
        for entry, summary in registry.ALL[name].describe():
            typer.echo(f"  {entry:<20} {summary}")


def main() -> None:  # pragma: no cover - console entry point
    """The ``nlcx`` command.

    The garbage collector is off while a command imports its libraries (the long commands
    switch it back on, see :func:`_imported`), and at exit everything still alive is frozen,
    so the interpreter's final collection does not walk the import graph of numba, pandas and
    matplotlib (about half a second of a three-second run)."""
    gc.disable()
    try:
        app()
    finally:
        gc.freeze()


if __name__ == "__main__":  # pragma: no cover - python -m nlcx.cli
    main()

"""The commands that run experiments: run, sweep, validate, reproduce, report, calibrate, identify."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from nlcx import safe_yaml
from nlcx.cli._app import (
    AllowEnv,
    ConfigArg,
    NoReport,
    OverridesArg,
    PluginsOpt,
    _fmt,
    _imported,
    app,
    checked_jobs,
    load_plugins,
    one_line_errors,
)
from nlcx.compiled_cache import CompileHelper
from nlcx.errors import ConfigError, NlcxError
from nlcx.plugins import load_config_imports
from nlcx.terminal import echo

if TYPE_CHECKING:
    from nlcx.drawing import Painter
    from nlcx.sweeps.cluster import ClusterSpec


def _painter(raw: dict[str, Any]) -> Painter | None:
    """A figure painter process (:class:`nlcx.drawing.Painter`) unless the config turns every
    figure off (unset keys take :class:`nlcx.config.OutputsSection`'s defaults)."""
    from nlcx.config import OutputsSection
    from nlcx.drawing import Painter

    section = raw.get("outputs")
    outputs = section if isinstance(section, dict) else {}
    fields = OutputsSection.model_fields
    if all(outputs.get(key, fields[key].default) is False for key in ("figure", "gains_figure")):
        return None
    return Painter()


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


DeviceOpt = Annotated[
    str | None,
    typer.Option(
        "--device", help="cpu or cuda: where the closed loops run (sets simulation.device; docs/guide/gpu.md)."
    ),
]


def _checked_device(device: str | None) -> str | None:
    """``--device`` checked (for cuda: a GPU found) before any work; None without it."""
    from nlcx.kernel.device import DEVICES, cuda

    if device is not None and device not in DEVICES:
        raise NlcxError(f"--device = {device!r}: allowed values: {', '.join(DEVICES)}")
    if device == "cuda":
        cuda()
    return device


def _on_device(device: str | None, overrides: list[str] | None) -> list[str]:
    """The overrides with ``simulation.device`` set to ``--device`` (checked), or unchanged without it."""
    if _checked_device(device) is None:
        return list(overrides or [])
    return [*(overrides or []), f"++simulation.device={device}"]


@app.command()
@one_line_errors
def run(
    config: ConfigArg,
    overrides: OverridesArg = None,
    out: Annotated[Path | None, typer.Option("--out", help="Run directory (default results/<name>).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print only the run directory.")] = False,
    no_report: NoReport = False,
    device: DeviceOpt = None,
    allow_env: AllowEnv = False,
    plugins: PluginsOpt = None,
) -> None:
    """Run an experiment: every controller of CONFIG on its plant, then write the run directory."""
    from nlcx import config as cfg

    load_plugins(plugins)
    overrides = _on_device(device, overrides)
    raw = load_config_imports(cfg.apply_overrides(cfg.read_config(config), overrides or []))
    if "sweep" in raw:
        _sweep(config, overrides or [], out, "process", 2, None, False, False, not no_report, allow_env=allow_env)
        return
    resolved = cfg.interpolate(raw, allow_env=allow_env)  # a refused resolver stops here, before any process starts
    painter = _painter(raw)  # imports matplotlib in another process while this one imports the engine
    flags = ["--allow-env"] if allow_env else []
    flags += [item for file in plugins or [] for item in ("--plugins", str(file.resolve()))]
    helper = CompileHelper([sys.executable, "-m", "nlcx.cli", "prewarm", str(config), *flags, *(overrides or [])])
    try:
        from nlcx import engine, rundir

        _imported()
        with helper.watching():  # a slow load means an empty numba cache: `nlcx prewarm` compiles alongside
            engine.load_kernel()
        start = time.perf_counter()
        exp = cfg.build(resolved, allow_env=allow_env)  # cfg.load's steps on the config already read
        loaded = time.perf_counter()
        out_dir = out or Path(exp.section.outputs.dir or Path("results") / exp.name)
        rundir.check_target(out_dir)  # a refused target before any work (tuners simulate)
        prepared = engine.prepare(exp)  # every check of the config before the target's lock is taken
        ready = time.perf_counter()
        with rundir.claim(out_dir):  # refused before simulating, not after
            result = engine.run_experiment(prepared)
            timings = {"load": loaded - start, **result.timings, "prepare": ready - loaded}
            rundir.save_run(
                result, out_dir, with_report=not no_report, overrides=overrides or [], timings=timings,
                painter=painter, started=start,
            )  # fmt: skip
    finally:
        if painter is not None:
            painter.close()
        helper.close()
    page = None if no_report else out_dir / "report.html"
    elapsed = time.perf_counter() - start
    if quiet:
        echo(str(out_dir))
        return
    echo(
        f"{exp.name}: {exp.section.plant.name}, {len(result.runs)} controller(s), "
        f"{result.prepared.grid.n_steps} steps of {result.prepared.grid.dt:g} s"
    )
    echo(_summary(result))
    echo(f"wrote {out_dir}/ in {elapsed:.2f} s" + (f"; report {page}" if page else ""))


@app.command(hidden=True)
@one_line_errors
def prewarm(
    config: ConfigArg, overrides: OverridesArg = None, allow_env: AllowEnv = False, plugins: PluginsOpt = None
) -> None:
    """Compile what a run of CONFIG needs besides the kernel into numba's cache (``nlcx run``
    starts this beside itself when the cache is empty; see nlcx.engine.prewarm)."""
    from nlcx import config as cfg
    from nlcx import engine

    load_plugins(plugins)
    engine.prewarm(cfg.load(config, overrides or [], allow_env=allow_env))


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
    cluster_file: Path | None = None,
    allow_env: bool = False,
) -> None:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from nlcx import sweeps as sweep
    from nlcx.sweeps import cluster as clusters

    _imported()
    cluster = clusters.load(cluster_file) if cluster_file is not None else None
    if cluster is not None:  # the cluster's workers; the memory check counts one node's
        executor, jobs = "dask", cluster.workers if cluster.kind == "local" else cluster.cores

    if dry_run:
        _print_plan(config, overrides, cluster, allow_env)
        return
    columns = (
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        TextColumn("failed {task.fields[failed]}"), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
    )  # fmt: skip
    bar = Progress(*columns, transient=False)
    tasks: list[Any] = []

    def progress(done: int, total: int, failed: int) -> None:
        if not tasks:  # shown from the first batch on: a refused plan prints its one line alone
            bar.start()
            tasks.append(bar.add_task("variants", total=None, failed=0))
        bar.update(tasks[0], completed=done, total=total, failed=failed)

    try:
        outcome = sweep.run(
            config, overrides, out, executor, jobs, scheduler, force, progress, with_report, cluster, allow_env
        )
    finally:
        bar.stop()
    counts = outcome.statuses
    summary = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    echo(
        f"{outcome.computed + outcome.skipped} variants ({outcome.computed} computed, "
        f"{outcome.skipped} already done): {summary}; "
        f"{outcome.wall:.1f} s -> {outcome.out_dir}/"
    )
    if outcome.report is not None:
        echo(f"report {outcome.report} ({outcome.report_s:.2f} s)")
    if counts.get("failed"):
        failed = outcome.index[outcome.index.status == "failed"].head(3)
        for row in failed.itertuples():
            echo(f"  variant {row.variant} failed: {row.message}", err=True)
        raise typer.Exit(1)


def _print_plan(config: Path, overrides: list[str], cluster: ClusterSpec | None, allow_env: bool) -> None:
    """``nlcx sweep --dry-run``: the sweep's plan checked (its memory before it is expanded) and
    its first variants printed, and the job script of ``cluster`` when there is one."""
    from nlcx import sweeps as sweep
    from nlcx.sweeps import cluster as clusters
    from nlcx.sweeps import sizing

    base_raw, spec, base = sweep.load(config, overrides, allow_env=allow_env)
    sizing.check(spec, base, None)  # the plan's memory, before it is expanded
    variants, hashes = sweep.plan(base_raw, spec)
    echo(f"{base.name}: {len(variants)} variant(s) x {len(base.controllers)} controller(s)")
    for v, h in list(zip(variants, hashes, strict=True))[:20]:
        values = ", ".join(f"{k}={val!r}" for k, val in v.values.items())
        echo(f"  {v.index:>6}  seed {v.seed:>10}  {h}  {values}")
    if len(variants) > 20:
        echo(f"  ... {len(variants) - 20} more")
    if cluster is not None:
        echo(f"{cluster.kind} cluster: {cluster.jobs} job(s) of {cluster.cores} worker(s); each job's script:")
        echo(clusters.job_script(cluster).rstrip())


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
    device: DeviceOpt = None,
    allow_env: AllowEnv = False,
    plugins: PluginsOpt = None,
    cluster: Annotated[
        Path | None,
        typer.Option(
            "--cluster",
            help="Cluster file (local, slurm or pbs; configs/clusters/): run on Dask workers there. "
            "With --dry-run, print the job script.",
        ),
    ] = None,
) -> None:
    """Run the sweep of CONFIG (its sweep: section); a rerun resumes where it stopped."""
    if executor not in ("process", "serial", "dask"):
        raise NlcxError(f"--executor = {executor!r}: allowed values: process, serial, dask")
    checked_jobs(jobs)
    load_plugins(plugins)
    overrides = _on_device(device, overrides)
    if cluster is not None and (scheduler or executor not in ("process", "dask")):
        raise NlcxError("--cluster: runs on Dask workers of its own; leave out --scheduler and --executor")
    _sweep(config, overrides or [], out, executor, jobs, scheduler, force, dry_run, not no_report, cluster, allow_env)


@app.command()
@one_line_errors
def validate(
    config: ConfigArg, overrides: OverridesArg = None, allow_env: AllowEnv = False, plugins: PluginsOpt = None
) -> None:
    """Check CONFIG (with overrides) without running it; exit 2 with one line if invalid. A
    sweep config's base experiment, its sweep section and its plan's size are checked."""
    from nlcx import config as cfg
    from nlcx import engine
    from nlcx import sweeps as sweep
    from nlcx.sweeps import planning, sizing

    load_plugins(plugins)
    if "sweep" in cfg.apply_overrides(cfg.read_config(config), overrides or []):
        _, spec, exp = sweep.load(config, overrides or [], allow_env=allow_env)
        size = sizing.check(spec, exp, None, columnar=spec.columnar and planning.numeric(spec))  # as a run sizes it
        planned = f"; a sweep of {size.variants:,} variants"
    else:
        exp, planned = cfg.load(config, overrides or [], allow_env=allow_env), ""
    engine.prepare(exp)
    labels = ", ".join(c.label for c in exp.controllers)
    echo(f"{config}: valid ({exp.section.plant.name}; controllers: {labels}{planned})")


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
        str | None,
        typer.Option(
            "--profile",
            help="Loop profile (configs/thesis/profiles/NAME.yaml); literal: as printed. "
            "Default: selected where the identification study's rule chose it, else literal.",
        ),
    ] = None,
    no_report: NoReport = False,
) -> None:
    """Regenerate the thesis's figures and tables (ours beside theirs) and check its claims."""
    from nlcx import rundir
    from nlcx.thesis import profiles
    from nlcx.thesis.reproduce import reproduce as run_reproduce

    checked_jobs(jobs)
    _imported()
    chosen = profiles.load(profile or profiles.default_name(configs), configs)

    start = time.perf_counter()
    keys = [k for k in (only or "").split(",") if k.strip()]
    done = [0]

    def progress(record: Any) -> None:
        done[0] += 1
        bad = [c for c, s in record.status.items() if s != "ok"]
        note = f" ({', '.join(bad)} unstable)" if bad else ""
        echo(f"  [{done[0]:>3}] {record.name:<12} {record.wall:5.2f} s{note}")

    with rundir.staged(out) as stage:  # renamed to OUT when complete, report included
        summary = run_reproduce(
            configs, stage, chapters=chapter, only=keys, jobs=jobs, progress=progress,
            overrides=tuple(set_ or ()), profile=chosen,
        )  # fmt: skip
        echo(f"profile {chosen.name}: {len(summary['figures'])} figures, {len(summary['tables'])} tables -> {out}/")
        if "claims" in summary:
            counts = summary["claims"].reproduced.value_counts().to_dict()
            echo("claims: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
        wall = time.perf_counter() - start
        write_reproduction_manifest(stage, chosen, wall, jobs, overrides=set_ or (), started=start)
        echo(f"done in {wall:.1f} s")
        t0 = time.perf_counter()
        failure = None if no_report else rundir.write_pages(stage, configs)
    if failure is not None:
        raise rundir.ReportError(out, failure)
    if not no_report:
        echo(f"report {out / 'report.html'} ({time.perf_counter() - t0:.1f} s)")


@app.command()
@one_line_errors
def baselines(
    configs: Annotated[Path, typer.Option("--configs", help="The baseline configs.")] = Path("configs/baselines"),
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("results/baselines"),
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes of the sweeps.")] = 2,
    only: Annotated[
        str | None, typer.Option("--only", help="Comma-separated pendulums (x, xy, xz, xyz); default: all.")
    ] = None,
    variants: Annotated[int, typer.Option("--variants", help="Variants of each pendulum's robustness sweep.")] = 200,
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="Override for every config, e.g. simulation.t_end=5."),
    ] = None,
    no_report: NoReport = False,
) -> None:
    """AGS PID against the baselines (LQR, sliding mode) on the four pendulums, in the thesis's
    scenarios and a robustness sweep (docs/baselines.md): one directory, one report."""
    from nlcx import rundir
    from nlcx.limits import check_count
    from nlcx.thesis import baselines as study

    checked_jobs(jobs)
    check_count("--variants", variants, 1, 100_000, "variants of each robustness sweep")
    pendulums = [p.strip() for p in (only or ",".join(study.PENDULUMS)).split(",") if p.strip()]
    study.check_pendulums(pendulums)
    study.configs_of(configs, pendulums)  # every config there, before any work
    _imported()
    start = time.perf_counter()

    def progress(what: str, seconds: float) -> None:
        echo(f"  {what:<40} {seconds:6.2f} s")

    with rundir.staged(out) as stage:
        study.run(configs, stage, pendulums=pendulums, variants=variants, jobs=jobs, overrides=tuple(set_ or ()),
                  progress=progress)  # fmt: skip
        wall = time.perf_counter() - start
        from nlcx import manifest, report

        record = {"nlcx_output": "baselines", "command": "nlcx " + " ".join(sys.argv[1:]),
                  **report.provenance(set_ or (), start), "pendulums": pendulums, "variants": variants,
                  **report.environment(), "wall_s": round(wall, 2), "jobs": jobs}  # fmt: skip
        manifest.write(stage, record)
        echo(f"done in {wall:.1f} s")
        failure = None if no_report else rundir.write_pages(stage)
    if failure is not None:
        raise rundir.ReportError(out, failure)
    echo(f"wrote {out}/" + ("" if no_report else f"; report {out / 'report.html'}"))


def write_reproduction_manifest(
    out: Path,
    profile: Any,
    wall: float,
    jobs: int | None,
    overrides: Sequence[str] = (),
    started: float | None = None,
) -> None:
    """manifest.json of a reproduction: its kind (``nlcx_output``: reproduction), the command,
    its ``overrides`` (``--set``), start and duration from the ``time.perf_counter()`` instant
    ``started`` (:func:`nlcx.report.provenance`), the profile, where it ran and the versions and
    commit (:func:`nlcx.report.environment`), the wall time ``wall`` and the workers."""
    import os
    import sys

    from nlcx import manifest, report

    record = {
        "nlcx_output": "reproduction",
        "command": "nlcx " + " ".join(sys.argv[1:]),
        **report.provenance(overrides, started),
        "profile": profile.name,
        "profile_source": profile.source,
        **report.environment(),
        "wall_s": round(wall, 2),
        "jobs": jobs or os.cpu_count(),
    }
    manifest.write(out, record)


@app.command()
@one_line_errors
def report(
    directory: Annotated[Path, typer.Argument(help="A reproduction, sweep or run directory.", show_default=False)],
    configs: Annotated[Path, typer.Option("--configs", help="Thesis configs (tolerances.yaml).")] = Path(
        "configs/thesis"
    ),
) -> None:
    """Write DIR/report.html and DIR/report.md: one page summarising what DIR holds (an output
    directory nlcx wrote; every table it reads is checked against the manifest first)."""
    from nlcx import rundir

    rundir.check_marked(directory)  # before the lock: a refused directory gets no lock file beside it
    with rundir.locked(directory, key="DIR"):  # not while another process writes or replaces it
        rundir.check_marked(directory)
        failure = rundir.write_pages(directory, configs, verify=True)
    if failure is not None:
        raise rundir.ReportError(directory, failure)
    echo(str(directory / "report.html"))


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
    from nlcx import rundir
    from nlcx.thesis.calibrate import calibrate as run_calibration
    from nlcx.thesis.calibrate import load_spec, write_back

    checked_jobs(jobs)
    _imported()

    name = load_spec(spec, overrides or []).name
    out_dir = out or Path("results/calibration") / name

    def progress(generation: int, best: float) -> None:
        echo(f"  generation {generation:>3}: best loss {best:.5g}")

    with rundir.claim_in_place(out_dir, "calibration"):
        outcome = run_calibration(spec, out_dir, jobs=jobs, overrides=overrides or [], progress=progress)
    echo(outcome["tuning"].to_string(index=False))
    echo(outcome["fit"].to_string(index=False))
    if write:
        echo(f"wrote {write_back(spec, outcome)}")
    echo(f"loss {outcome['result'].f:.5g}; results in {out_dir}/")


@app.command()
@one_line_errors
def identify(
    spec: Annotated[Path, typer.Argument(help="Identification spec YAML.", show_default=False)],
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes (fits on the GPU run in this one).")] = 1,
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory (default results/identify/<name>).")
    ] = None,
    device: DeviceOpt = None,
) -> None:
    """Fit loop hypotheses to the train tables, rank them on validation (resumable).
    A spec with ``chapter: 5`` is chapter 5's study (Table 5.8), ranked by train loss; one with
    ``kind: consistency`` asks of each printed conventional column whether any loop gives it."""

    from nlcx import manifest, rundir
    from nlcx.thesis.consistency import consistency
    from nlcx.thesis.identify import identify as run_identify
    from nlcx.thesis.identify_cstr import identify_cstr

    checked_jobs(jobs)
    _imported()
    raw = safe_yaml.load_file(spec)
    if not isinstance(raw, dict) or not isinstance(raw.get("name"), str):
        raise ConfigError("spec", str(spec), "an identification spec: a YAML mapping with a name")
    out_dir = out or Path("results/identify") / raw["name"]
    pendulum_study = raw.get("kind") != "consistency" and raw.get("chapter") != 5
    if device not in (None, "cpu") and not pendulum_study:
        raise NlcxError(f"--device = {device!r}: a consistency or chapter 5 study runs on the cpu only")

    def progress(done: int, total: int, name: str) -> None:
        echo(f"  [{done}/{total}] {name}")

    with rundir.claim_in_place(out_dir, "identification"):  # resumed in place: locked, not staged
        if raw.get("kind") == "consistency":
            table = consistency(spec, out_dir, jobs=jobs, progress=progress)
        elif raw.get("chapter") == 5:
            table = identify_cstr(spec, out_dir, jobs=jobs, progress=progress)
        else:
            table = run_identify(spec, out_dir, jobs=jobs, progress=progress, device=_checked_device(device))
        manifest.update(out_dir, manifest.load(out_dir).get("checksums", {}))  # every file's checksum, anew
    if raw.get("kind") == "consistency":
        shown = table[["table", "definition", "loops", "most_cells_hit", "cells", "reproduced"]]
        echo(shown.to_string(index=False))
        echo(f"results in {out_dir}/")
        return
    if raw.get("chapter") == 5:
        columns = ["rank", "hypothesis", "train_loss", "test_median_rel_error"]
    else:
        columns = ["rank", "hypothesis", "train_loss", "validation_median_rel_error", "validation_direction_agreement"]
    echo(table[columns].head(10).to_string(index=False))
    echo(f"{len(table)} hypotheses; results in {out_dir}/")

"""The commands that run experiments and report on their outputs: run, sweep, validate, report."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from nlcx import runtime
from nlcx.cli._app import (
    AllowEnv,
    ConfigArg,
    NoReport,
    OverridesArg,
    PluginsOpt,
    app,
    checked_jobs,
    fmt,
    load_plugins,
    one_line_errors,
)
from nlcx.compiled_cache import COMPILING, CompileHelper
from nlcx.errors import NlcxError
from nlcx.plugins import load_config_imports
from nlcx.terminal import echo

if TYPE_CHECKING:
    from rich.progress import TaskID

    from nlcx.drawing import Painter
    from nlcx.engine import ExperimentResult
    from nlcx.sweeps.cluster import ClusterSpec


def _painter(raw: dict[str, object]) -> Painter | None:
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


def _summary(result: ExperimentResult) -> str:
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
                    f"{signal}: Mp {fmt(sub['overshoot'])}% tr {fmt(sub['rise_time'])}s ts {fmt(sub['settling_time'])}s"
                )
            elif "peak_deviation" in sub:
                parts.append(f"{signal}: peak {fmt(sub['peak_deviation'])} ts {fmt(sub['settling_time'])}s")
        lines.append(f"  {run.label:<14} ok    " + " | ".join(parts))
    return "\n".join(lines)


DeviceOpt = Annotated[
    str | None,
    typer.Option(
        "--device", help="cpu or cuda: where the closed loops run (sets simulation.device; docs/guide/gpu.md)."
    ),
]


def checked_device(device: str | None) -> str | None:
    """``--device`` checked (for cuda: a GPU found) before any work; None without it."""
    from nlcx.kernel.device import DEVICES, cuda

    if device is not None and device not in DEVICES:
        raise NlcxError(f"--device = {device!r}: allowed values: {', '.join(DEVICES)}")
    if device == "cuda":
        cuda()
    return device


def _on_device(device: str | None, overrides: list[str] | None) -> list[str]:
    """The overrides with ``simulation.device`` set to ``--device`` (checked), or unchanged without it."""
    if checked_device(device) is None:
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
    command = runtime.module_command("nlcx.cli", "prewarm", str(config), *flags, *(overrides or []))
    # a kernel that numba compiles (its disk cache empty or stale): said in one line on stderr (not with -q)
    helper = CompileHelper(command, notice=None if quiet else lambda: echo(COMPILING, err=True))
    try:
        from nlcx import engine, rundir

        runtime.imports_done()
        with helper.watching():  # a compiled kernel means a cold numba cache: `nlcx prewarm` compiles alongside
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
    """Compile what a run of CONFIG needs besides the kernel into numba's cache (nlcx run
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
    from rich.console import Console
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

    runtime.imports_done()
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
    bar = Progress(*columns, console=Console(), transient=False)  # as wide as the terminal is now
    tasks: list[TaskID] = []

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

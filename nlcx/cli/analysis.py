"""The commands that analyse a configured loop without simulating it: linearize."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer

from nlcx import rundir, runtime
from nlcx.cli._app import ConfigArg, OverridesArg, PluginsOpt, app, load_plugins, one_line_errors
from nlcx.errors import ConfigError
from nlcx.terminal import echo

#: The arguments of :func:`nlcx.analysis.linearize` that are options of the command.
_OPTIONS = ("controller", "at", "along", "points")


@contextmanager
def _as_options() -> Iterator[None]:
    """Name a bad argument of :mod:`nlcx.analysis` as the command's option (``at`` as ``--at``)."""
    try:
        yield
    except ConfigError as exc:
        if exc.path not in _OPTIONS:
            raise
        raise ConfigError(f"--{exc.path}", exc.value, exc.allowed) from None


@app.command()
@one_line_errors
def linearize(
    config: ConfigArg,
    overrides: OverridesArg = None,
    controller: Annotated[
        str | None,
        typer.Option(
            "--controller", help="Controller to analyse (default: the first PID with a scheduled loop, else the first)."
        ),
    ] = None,
    at: Annotated[
        str | None,
        typer.Option("--at", help="Freeze the schedules at t=T (time, s) or e=E (error r - y); default t=0 and e=0."),
    ] = None,
    along: Annotated[
        str | None,
        typer.Option("--along", help="Also sweep the frozen point along t (0 to t_end) or e (0 to the largest error)."),
    ] = None,
    points: Annotated[int, typer.Option("--points", help="Frozen points of the --along sweep.")] = 51,
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory (default results/linearize/<name>).")
    ] = None,
    plugins: PluginsOpt = None,
) -> None:
    """Linearise CONFIG's plant about its operating point, freeze its PID's gain schedules and
    write the closed-loop poles and the margins with the loop broken at the plant input."""
    from nlcx.analysis.linearization import analyse
    from nlcx.analysis.output import save_analysis, summary

    runtime.imports_done()
    load_plugins(plugins)
    start = time.perf_counter()
    if out is not None:
        rundir.check_target(out)  # refused before the analysis, not after
    with _as_options():
        result, sweep = analyse(config, controller, at, along, points=points, overrides=overrides or [])
    out_dir = out or Path("results") / "linearize" / result.experiment.name
    save_analysis(out_dir, result, sweep, overrides or [], start)
    echo("\n".join(summary(result)))
    echo(f"wrote {out_dir}/")

"""The commands that read outputs: diff, metrics, list."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from nlcx import registry
from nlcx.cli._app import _fmt, app, one_line_errors
from nlcx.errors import NlcxError


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

"""The commands that read outputs and describe what nlcx knows: diff, metrics, list, schema."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from nlcx import registry
from nlcx.cli._app import PluginsOpt, app, fmt, load_plugins, one_line_errors
from nlcx.cli.metric_files import (
    CONTROLLER,
    Measured,
    Settings,
    blocks_of,
    checked_settings,
    measure_block,
    metrics_error,
    name_list,
    read_frame,
    reference_option,
    signals_of,
    source_of,
)
from nlcx.errors import NlcxError, did_you_mean
from nlcx.terminal import echo


@app.command()
@one_line_errors
def diff(
    base: Annotated[
        Path, typer.Argument(help="Baseline directory (or CSV or Parquet file or dataset).", show_default=False)
    ],
    new: Annotated[
        Path, typer.Argument(help="Directory (or CSV or Parquet file or dataset) to check.", show_default=False)
    ],
    rtol: Annotated[
        list[str] | None, typer.Option("--rtol", help="Relative tolerance: VALUE (default) or METRIC=VALUE.")
    ] = None,
    atol: Annotated[
        list[str] | None, typer.Option("--atol", help="Absolute tolerance: VALUE (default) or METRIC=VALUE.")
    ] = None,
    only: Annotated[
        list[str] | None,
        typer.Option(
            "--only",
            help="Compare only the tables whose path under BASE matches this pattern (fnmatch, e.g. "
            "'metrics.*' for a sweep's metrics as CSV or Parquet); repeat for several.",
            show_default=False,
        ),
    ] = None,
    cells: Annotated[
        bool, typer.Option("--cells", help="List the drifted cells (the first of each file), not only their count.")
    ] = False,
) -> None:
    """Compare the CSV and Parquet tables of NEW against BASE; exit 1 if any cell moved.

    First the resolved configs' differences (key: old → new, from each directory's
    config.yaml), then per file the drifted cells' count and largest |diff| (--cells lists
    them). A table held as CSV in one and as Parquet in the other (a sweep's metrics.csv and
    metrics.parquet) is compared as one table; tables of the same bytes are not parsed."""
    from nlcx.diff import config_changes, diff_dirs, file_summaries, parse_tolerances, render, summary

    tol = parse_tolerances(rtol or [], atol or [])
    report = diff_dirs(base, new, tol, only or [])
    changes = config_changes(base, new)
    if changes is not None:
        echo("\n".join(["config:", *(f"  {line}" for line in changes)]) if changes else "config: identical")
    if report.drifted:
        echo("\n".join(file_summaries(report)))
        if details := render(report, cells=cells):  # status changes, cells, notes
            echo(details)
        echo(summary(report))
        raise typer.Exit(1)
    echo(f"no drift: {report.n_files} file(s) within rtol {tol.rtol} atol {tol.atol}")


# ----------------------------------------------------------------------------- nlcx metrics


def _metric_order() -> list[str]:
    from nlcx.metrics import ERROR_METRICS, REGULATION_METRICS, STEP_INFO_METRICS

    return list(dict.fromkeys([*STEP_INFO_METRICS, *REGULATION_METRICS, *ERROR_METRICS]))


def _unit(metric: str) -> str:
    from nlcx.metrics import METRIC_UNITS, STEP_INFO_UNITS

    return STEP_INFO_UNITS.get(metric) or METRIC_UNITS[metric]


def _heading(file: Path, measured: Measured) -> str:
    """``FILE[, controller NAME]: N samples, t = A to B s; TARGETS``: one description for all
    signals when they share it, else ``signal: description`` each."""
    block, t = measured.block, measured.block.t
    title = file.name if block.name is None else f"{file.name}, controller {block.name}"
    shared = {target.describe() for target in measured.targets.values()}
    if len(shared) == 1:
        targets = shared.pop()
    else:
        targets = "; ".join(f"{n}: {t.describe(' to ')}" for n, t in measured.targets.items())
    return f"{title}: {t.size} samples, t = {t[0]:g} to {t[-1]:g} s; {targets}"


def _table_lines(measured: Measured) -> list[str]:
    """One row per metric that any signal has (4 significant digits; — where a signal has none
    or it is undefined), one column per signal."""
    names = list(measured.values)
    width = max(10, *(len(n) for n in names))
    lines = [f"  {'metric':<20}{'unit':<8}" + "".join(f"{n:>{width + 2}}" for n in names)]
    for key in _metric_order():
        if not any(key in values for values in measured.values.values()):
            continue
        cells = "".join(f"{fmt(measured.values[n].get(key, math.nan)):>{width + 2}}" for n in names)
        lines.append(f"  {key:<20}{_unit(key):<8}{cells}")
    return lines


_NAN_NOTES = {
    "settling_time": "did not settle within the record",
    "rise_time": "did not reach the upper rise level",
}


def _notes(measured: list[Measured], s: Settings) -> list[str]:
    """One line per way of measuring other than a step: which signals, why, and what is reported."""
    regulated = {f"{n} ({t.reason})": None for m in measured for n, t in m.targets.items() if t.kind == "regulated"}
    tracked = {f"{n} ({t.reason})": None for m in measured for n, t in m.targets.items() if t.kind == "tracked"}
    lines = []
    if regulated:
        lines.append(
            f"note: measured as regulated, there being no step to measure: {', '.join(regulated)}; reported: "
            f"peak deviation and its time, settling time inside {100 * s.settling_band:g} % of the peak deviation, "
            f"steady-state error over the last {s.ss_window:g} s (nlcx's regulation metrics, docs/metrics.md); "
            "no step metrics"
        )
    if tracked:
        lines.append(
            f"note: measured as tracking: {', '.join(tracked)}; reported: integrals of the reference minus the "
            "signal (ise, iae, itae), its largest and RMS value; no step metrics (--reference VALUE measures a step)"
        )
    return lines


def _rows(measured: list[Measured]) -> list[tuple[str, str, str, float, str, str]]:
    """(controller, signal, metric, value, unit, note) of every value measured."""
    rows = []
    for m in measured:
        for name, values in m.values.items():
            target = m.targets[name]
            for key, value in values.items():
                note = _NAN_NOTES.get(key, "undefined") if math.isnan(value) else ""
                note = "; ".join(filter(None, [f"{target.kind}: {target.reason}" if target.reason else "", note]))
                rows.append((m.block.name or "", name, key, value, _unit(key), note))
    return rows


def _write_metrics(out: Path, rows: list[tuple[str, str, str, float, str, str]], own: bool) -> None:
    """``--out``: nlcx's own files as controller, signal, metric, value, unit, note; any other
    file as signal, metric, value, unit."""
    import pandas as pd

    from nlcx.report import write_csv  # imports the engine: only when writing

    columns = ["controller", "signal", "metric", "value", "unit", "note"]
    table = pd.DataFrame(rows, columns=columns)
    write_csv(out, table if own else table[["signal", "metric", "value", "unit"]])


#: The options of ``nlcx metrics``.
MetricsFileArg = Annotated[
    Path, typer.Argument(help="CSV file with a header row, or a Parquet file.", show_default=False)
]
TimeColumnOpt = Annotated[str, typer.Option("--time", help="Time column, in seconds.")]
SignalsOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--signal",
        help="Column to measure; repeat for several (default: every column s with a reference column s_ref, "
        "else every column of numbers).",
        show_default=False,
    ),
]
ReferenceOpt = Annotated[
    str | None,
    typer.Option(
        "--reference",
        help="Target: a number, or a column (default: the signal's column s_ref if there is one, else its "
        "last sample).",
        show_default=False,
    ),
]
StepTimeOpt = Annotated[
    float | None,
    typer.Option(
        "--t-step",
        help="Step time in s; earlier samples are ignored (default: the change of a reference column that "
        "steps once, else 0).",
        show_default=False,
    ),
]
SettlingBandOpt = Annotated[
    float,
    typer.Option(
        "--settling-band", help="Settling band: a fraction of the step, or of a regulated signal's peak deviation."
    ),
]
RiseLimitsOpt = Annotated[
    tuple[float, float], typer.Option("--rise-limits", help="Rise time between these fractions of the step.")
]
SteadyWindowOpt = Annotated[
    float, typer.Option("--ss-window", help="Window of a regulated signal's steady-state error, s.")
]
MetricsOutOpt = Annotated[
    Path | None,
    typer.Option("--out", help="Write the metrics in long form to this CSV.", show_default=False),
]


@app.command("metrics")
@one_line_errors
def metrics_command(
    file: MetricsFileArg,
    time_column: TimeColumnOpt = "t",
    signals: SignalsOpt = None,
    reference: ReferenceOpt = None,
    t_step: StepTimeOpt = None,
    settling_band: SettlingBandOpt = 0.02,
    rise_limits: RiseLimitsOpt = (0.1, 0.9),
    ss_window: SteadyWindowOpt = 1.0,
    out: MetricsOutOpt = None,
) -> None:
    """Step-response metrics of the columns of a CSV or Parquet file: logged on a rig, or nlcx's own time series.

    Each signal is measured by nlcx.metrics.step_info from its value at --t-step to its final value:
    its last sample, --reference, or its reference column s_ref. Against a reference column that is
    constant 0 a signal is measured as regulated (peak deviation, settling inside a band of it), and
    against one that varies (not a step) as tracking (error integrals); a note says which. A file
    with a controller column (nlcx's time series) is measured per controller."""
    s = checked_settings(settling_band, rise_limits, ss_window)
    frame = read_frame(file)
    columns = list(frame.columns)
    if time_column not in columns:
        problem = f"not a column of {file.name}{did_you_mean(time_column, columns)}"
        raise metrics_error("--time", time_column, problem, name_list(columns))
    ref = reference_option(reference, frame, file, time_column)
    names = signals_of(frame, file, time_column, signals or [], ref)
    sources = {name: source_of(name, ref, columns) for name in names}
    measured = [measure_block(b, file, names, sources, t_step, s) for b in blocks_of(frame, file, time_column)]
    own = CONTROLLER in columns or any(isinstance(v, str) for v in sources.values())
    for m in measured:
        echo(_heading(file, m))
        echo("\n".join(_table_lines(m)))
    for line in _notes(measured, s):
        echo(line)
    if out is not None:
        _write_metrics(out, _rows(measured), own)
        echo(f"wrote {out}")


# ----------------------------------------------------------------------------- nlcx list

#: Where each kind's plugins are configured in an experiment config.
_SECTIONS = {
    "plants": "plant.params",
    "controllers": "controllers.<label>",
    "schedules": "controllers.<label>.loops.<loop>.schedule",
    "uncertainties": "uncertainty.<label>",
    "references": "reference.<signal>",
    "tuners": "controllers.<label>.tune",
}


def _kind(text: str) -> str:
    kind = registry.kind_named(text)
    if kind is None:
        words = [*registry.ALL, *registry.SINGULAR.values()]
        hint = did_you_mean(text, words)
        raise NlcxError(f"list error: KIND = {text}: unknown kind{hint}; allowed: {', '.join(registry.ALL)}")
    return kind


def _aligned(rows: list[tuple[str, ...]], indent: str = "  ") -> list[str]:
    """Rows as columns padded to their widest cell (the last column left as it is)."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]) - 1)]
    return [
        (indent + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=False)) + "  " + r[-1]).rstrip() for r in rows
    ]


def _plugin_lines(doc: registry.PluginDoc, section: str) -> list[str]:
    """What ``nlcx list KIND NAME`` prints: the plugin, its signals and its models' fields."""
    lines = [f"{doc.kind} {doc.name}: {doc.summary}".rstrip()]
    for group, signals in doc.signals:
        lines.append(f"{group}:")
        lines += _aligned([("name", "unit", "label"), *signals])
    for i, model in enumerate(doc.models):
        what = "parameters" if doc.kind == "plant" else "configuration"
        title = f"{what} ({section}), {model.name}" if i == 0 else model.name
        lines.append(f"{title}: {model.summary}".rstrip())
        if model.fields:
            header = ("name", "type", "unit", "default", "description")
            lines += _aligned([header, *((f.name, f.type, f.unit, f.default, f.description) for f in model.fields)])
    return lines


@app.command("list")
@one_line_errors
def list_plugins(
    kind: Annotated[
        str | None, typer.Argument(help=f"One of: {', '.join(registry.ALL)} (or the singular).", show_default=False)
    ] = None,
    name: Annotated[
        str | None,
        typer.Argument(help="A registered name: show its signals and parameters.", show_default=False),
    ] = None,
    plugins: PluginsOpt = None,
) -> None:
    """List the registered plants, controllers, gain schedules, uncertainties, references and tuners.

    With KIND and NAME: that plugin's states, inputs and outputs (plants) and the fields of its
    parameters or configuration, with their types, units, defaults and descriptions."""
    load_plugins(plugins)
    kinds = [_kind(kind)] if kind else list(registry.ALL)
    if name is not None:
        reg = registry.ALL[kinds[0]]
        if name not in reg.names():
            raise NlcxError(f"list error: NAME = {name}: {reg.unknown_message(name)}")
        echo("\n".join(_plugin_lines(reg.explain(name), _SECTIONS[kinds[0]])))
        return
    for each in kinds:
        echo(f"{each}:")
        for entry, summary in registry.ALL[each].describe():
            echo(f"  {entry:<20} {summary}")


# ----------------------------------------------------------------------------- nlcx schema


@app.command("schema")
@one_line_errors
def schema_command(
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write the schema to this file (default: print it).", show_default=False),
    ] = None,
    plugins: PluginsOpt = None,
) -> None:
    """The JSON Schema of an experiment config, for an editor to complete and check the YAML.

    It knows every registered plugin: a plant's parameters by its name, the configuration of each
    controller, gain schedule, uncertainty, reference and tuner by its kind."""
    from nlcx.schema import experiment_schema, schema_text

    load_plugins(plugins)
    text = schema_text(experiment_schema())
    if out is None:
        echo(text, nl=False)
        return
    from nlcx.drawing import atomic_write

    atomic_write(out, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    echo(f"wrote {out}")

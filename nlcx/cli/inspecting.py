"""The commands that read outputs and describe what nlcx knows: diff, metrics, list, schema."""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import typer

from nlcx import registry
from nlcx.cli._app import _fmt, app, one_line_errors
from nlcx.errors import NlcxError

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd


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
    only: Annotated[
        list[str] | None,
        typer.Option(
            "--only",
            help="Compare only the files whose path under BASE matches this pattern (fnmatch, e.g. "
            "'*metrics.csv'); repeat for several.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Compare the CSV (and Parquet) files of NEW against BASE; exit 1 and list the drift if any cell moved."""
    from nlcx.diff import diff_dirs, parse_tolerances, render, summary

    tol = parse_tolerances(rtol or [], atol or [])
    drifts, n_files = diff_dirs(base, new, tol, only or [])
    if drifts:
        typer.echo(render(drifts))
        typer.echo(summary(drifts, n_files))
        raise typer.Exit(1)
    typer.echo(f"no drift: {n_files} file(s) within rtol {tol.rtol} atol {tol.atol}")


# ----------------------------------------------------------------------------- nlcx metrics


def _metrics_error(key: str, value: object, problem: str, allowed: str) -> NlcxError:
    """The one-line error of ``nlcx metrics``: ``metrics error: KEY = VALUE: PROBLEM; allowed: ALLOWED``."""
    text = f"metrics error: {key} = {value}: {problem}; allowed: {allowed}"
    return NlcxError(" ".join(text.split()))  # one line, whatever a parser's message held


def _names(names: list[str], limit: int = 20) -> str:
    more = f", ... ({len(names) - limit} more)" if len(names) > limit else ""
    return (", ".join(names[:limit]) + more) or "(none)"


#: The column of nlcx's time series that names the controller of each sample.
CONTROLLER = "controller"
#: Suffix of the column holding a signal's reference in nlcx's time series (``x`` -> ``x_ref``).
REF_SUFFIX = "_ref"


@dataclass(frozen=True)
class _Settings:
    """The metric definitions (nlcx's ``metrics:`` section, docs/metrics.md)."""

    settling_band: float
    rise_limits: tuple[float, float]
    ss_window: float


@dataclass(frozen=True)
class _Block:
    """The samples of one controller (``name``), or of the whole file (``name`` None)."""

    name: str | None
    frame: pd.DataFrame
    t: np.ndarray

    def where(self) -> str:
        return "" if self.name is None else f"controller {self.name}, "


@dataclass(frozen=True)
class _Target:
    """What a signal is measured against, and how.

    ``step``: :func:`nlcx.metrics.step_info` from ``t_step`` to ``final`` (None: the signal's
    last sample); ``regulated``: :func:`nlcx.metrics.regulation_metrics` about the constant
    ``final``; ``tracked``: :func:`nlcx.metrics.error_integrals` of the reference column minus
    the signal. ``column``: the reference column; ``reason``: why a signal is measured so."""

    kind: Literal["step", "regulated", "tracked"]
    final: float | None
    t_step: float
    column: str | None = None
    reason: str = ""

    def describe(self, separator: str = "; final value: ") -> str:
        """E.g. ``step at 0 s; final value: x_ref = 1`` (``separator`` between the step time and
        the final value), ``regulated to theta_ref = 0``, ``tracking x_ref from 0 s``."""
        if self.kind == "regulated":
            return f"regulated to {self.column} = {self.final:g}"
        if self.kind == "tracked":
            return f"tracking {self.column} from {self.t_step:g} s"
        if self.final is None:
            final = "last sample"
        else:
            final = f"{self.final:g}" if self.column is None else f"{self.column} = {self.final:g}"
        return f"step at {self.t_step:g} s{separator}{final}"


def _csv_column(frame: Any, column: str, key: str, file: Path, where: str = "") -> Any:
    """Column ``column`` of ``frame`` as finite floats; a one-line error naming ``key`` if it is
    not (``where``: the controller whose rows ``frame`` holds, as the message names it)."""
    import numpy as np
    import pandas as pd

    raw = frame[column]
    values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64)
    text = np.isnan(values) & raw.notna().to_numpy()
    if text.any():
        k = int(np.argmax(text))
        numeric = [str(c) for c in frame.columns if pd.api.types.is_numeric_dtype(frame[c])]
        problem = f"not numeric in {file.name} ({where}data row {raw.index[k] + 1}: {raw.iloc[k]!r})"
        raise _metrics_error(key, column, problem, f"a column of numbers: {_names(numeric)}")
    bad = ~np.isfinite(values)
    if bad.any():
        k = int(np.argmax(bad))
        problem = f"empty or non-finite in {file.name} ({where}data row {raw.index[k] + 1}: {raw.iloc[k]})"
        raise _metrics_error(key, column, problem, "a finite number in every row")
    return values


def _read_frame(file: Path) -> pd.DataFrame:
    """The CSV (or Parquet) ``file`` with text column names; a one-line error if unreadable."""
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
    frame.columns = [str(c) for c in frame.columns]
    return frame


def _reference_option(text: str | None, frame: pd.DataFrame, file: Path, time_column: str) -> float | str | None:
    """``--reference``: a number (what parses as one; it must be finite) or a column of numbers."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is not None:
        if not math.isfinite(value):
            raise _metrics_error("--reference", text, "not finite", "a finite number, or a column")
        return value
    columns = [str(c) for c in frame.columns if c not in (time_column, CONTROLLER)]
    if text not in columns:
        close = difflib.get_close_matches(text, columns, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise _metrics_error(
            "--reference",
            text,
            f"neither a number nor a column of {file.name}{hint}",
            f"a number, or {_names(columns)}",
        )
    return text


def _default_signals(frame: pd.DataFrame, time_column: str, reference: float | str | None) -> list[str]:
    """With no ``--signal``: every signal ``s`` with a reference column ``s_ref`` (the plant
    outputs of nlcx's time series), else every numeric column but time (and the reference)."""
    import pandas as pd

    columns = [c for c in frame.columns if c not in (time_column, CONTROLLER)]
    followed = [c for c in columns if c + REF_SUFFIX in columns]
    if followed:
        return followed
    return [c for c in columns if c != reference and pd.api.types.is_numeric_dtype(frame[c])]


def _signals_of(frame: pd.DataFrame, file: Path, time_column: str, signals: list[str], reference: Any) -> list[str]:
    """The columns to measure: ``--signal`` (each once), or :func:`_default_signals`."""
    others = [c for c in frame.columns if c != time_column]
    names = list(dict.fromkeys(signals)) or _default_signals(frame, time_column, reference)
    if not names:
        problem = f"no column of numbers besides {time_column} in {file.name}"
        raise _metrics_error("--signal", "(missing)", problem, f"a column of numbers: {_names(others)}")
    for name in names:
        if name not in others:
            problem = "is the --time column" if name == time_column else f"not a column of {file.name}"
            raise _metrics_error("--signal", name, problem, _names(others))
    return names


def _blocks(frame: pd.DataFrame, file: Path, time_column: str) -> list[_Block]:
    """The file's samples per controller (in the order they first appear) when it has a
    ``controller`` column (nlcx's time series stack its controllers' runs), else all of them;
    each block's times checked (at least 3, numbers, strictly increasing)."""
    import numpy as np

    if CONTROLLER in frame.columns:
        labels = frame[CONTROLLER].fillna("").astype(str).to_numpy()
        parts = [(name, frame[labels == name]) for name in dict.fromkeys(labels)]
    else:
        parts = [(None, frame)]
    blocks = []
    for name, part in parts:
        where = "" if name is None else f"controller {name}, "
        if len(part) < 3:
            samples = f"{len(part)} sample(s)" + ("" if name is None else f" of controller {name}")
            raise _metrics_error("FILE", file, samples, "at least 3 samples")
        t = _csv_column(part, time_column, "--time", file, where)
        back = np.flatnonzero(np.diff(t) <= 0)
        if back.size:
            k = int(back[0]) + 1
            row = int(part.index[k]) + 1
            problem = f"not strictly increasing in {file.name} ({where}data row {row}: {t[k]:g} after {t[k - 1]:g})"
            raise _metrics_error("--time", time_column, problem, "strictly increasing times")
        blocks.append(_Block(name, part, t))
    return blocks


def _source(name: str, reference: float | str | None, columns: list[str]) -> float | str | None:
    """What ``name`` is measured against: ``--reference`` if given, else its column ``name_ref``
    if the file has one, else (None) its last sample."""
    if reference is not None:
        return reference
    return name + REF_SUFFIX if name + REF_SUFFIX in columns else None


def _target(t: np.ndarray, y: np.ndarray, r: np.ndarray | None, source: Any, t_step: float | None) -> _Target:
    """How a signal with samples ``y`` is measured against ``source`` (a number, None: its last
    sample, or a column whose samples are ``r``); ``t_step``: ``--t-step`` if given.

    A reference column that holds one value is a step to it, unless that value is 0 or the
    one the signal starts at: then there is no step, and the signal is regulated (nlcx's
    metrics for a constant reference). A column that changes once is a step at that change
    (its ``t_step`` unless ``--t-step`` is given); any other is tracked."""
    import numpy as np

    start = 0.0 if t_step is None else t_step
    if r is None:
        return _Target("step", source, start)
    changes = np.flatnonzero(r[1:] != r[:-1])
    final = float(r[-1])
    if changes.size == 0:
        at_start = float(np.interp(start, t, y))
        if final == 0.0 or final == at_start:
            why = "is constant 0" if final == 0.0 else f"is constant {final:g}, the value the signal starts at"
            return _Target("regulated", final, start, source, f"{source} {why}")
        return _Target("step", final, start, source)
    if changes.size == 1:
        return _Target("step", final, float(t[changes[0] + 1]) if t_step is None else t_step, source)
    return _Target("tracked", None, start, source, f"{source} varies and is not one step")


def _check_t_step(block: _Block, file: Path, target: _Target) -> None:
    t = block.t
    if not t[0] <= target.t_step <= t[-3]:
        allowed = f"{t[0]:g} <= t_step <= {t[-3]:g} (at least 3 samples from the step on)"
        problem = f"outside the record of {file.name}" + ("" if block.name is None else f" (controller {block.name})")
        raise _metrics_error("--t-step", f"{target.t_step:g}", problem, allowed)


def _measure(t: np.ndarray, y: np.ndarray, r: np.ndarray | None, target: _Target, s: _Settings) -> dict[str, float]:
    """The metrics of one signal by its target's kind (see :class:`_Target`)."""
    import numpy as np

    from nlcx.metrics import error_integrals, regulation_metrics, step_info

    if target.kind == "step":
        info = step_info(
            t, y, reference=target.final, t_step=target.t_step, settling_band=s.settling_band, rise_limits=s.rise_limits
        )
        return {key: float(value) for key, value in info.items()}
    if target.kind == "regulated":
        i0 = int(np.searchsorted(t, target.t_step, side="left"))
        values = regulation_metrics(t[i0:], y[i0:], reference=target.final, band=s.settling_band, ss_window=s.ss_window)
    else:
        assert r is not None
        values = error_integrals(t, r - y, t0=target.t_step)
    return {key: float(value) for key, value in values.items()}


@dataclass(frozen=True)
class _Measured:
    """One controller's (or the file's) metrics: per signal, its target and values."""

    block: _Block
    targets: dict[str, _Target]
    values: dict[str, dict[str, float]]


def _measure_block(
    block: _Block, file: Path, names: list[str], sources: dict[str, Any], t_step: float | None, s: _Settings
) -> _Measured:
    where = block.where()
    targets, values = {}, {}
    for name in names:
        y = _csv_column(block.frame, name, "--signal", file, where)
        source = sources[name]
        r = _csv_column(block.frame, source, "--reference", file, where) if isinstance(source, str) else None
        targets[name] = _target(block.t, y, r, source, t_step)
        _check_t_step(block, file, targets[name])
        values[name] = _measure(block.t, y, r, targets[name], s)
    return _Measured(block, targets, values)


def _metric_order() -> list[str]:
    from nlcx.metrics import ERROR_METRICS, REGULATION_METRICS, STEP_INFO_METRICS

    return list(dict.fromkeys([*STEP_INFO_METRICS, *REGULATION_METRICS, *ERROR_METRICS]))


def _unit(metric: str) -> str:
    from nlcx.metrics import METRIC_UNITS, STEP_INFO_UNITS

    return STEP_INFO_UNITS.get(metric) or METRIC_UNITS[metric]


def _heading(file: Path, measured: _Measured) -> str:
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


def _table_lines(measured: _Measured) -> list[str]:
    """One row per metric that any signal has (4 significant digits; — where a signal has none
    or it is undefined), one column per signal."""
    names = list(measured.values)
    width = max(10, *(len(n) for n in names))
    lines = [f"  {'metric':<20}{'unit':<8}" + "".join(f"{n:>{width + 2}}" for n in names)]
    for key in _metric_order():
        if not any(key in values for values in measured.values.values()):
            continue
        cells = "".join(f"{_fmt(measured.values[n].get(key, math.nan)):>{width + 2}}" for n in names)
        lines.append(f"  {key:<20}{_unit(key):<8}{cells}")
    return lines


_NAN_NOTES = {
    "settling_time": "did not settle within the record",
    "rise_time": "did not reach the upper rise level",
}


def _notes(measured: list[_Measured], s: _Settings) -> list[str]:
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


def _rows(measured: list[_Measured]) -> list[tuple[str, str, str, float, str, str]]:
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


def _settings(settling_band: float, rise_limits: tuple[float, float], ss_window: float) -> _Settings:
    """The metric options, checked as nlcx's ``metrics:`` section checks them."""
    if not 0 < settling_band < 1:
        raise _metrics_error("--settling-band", f"{settling_band:g}", "outside (0, 1)", "0 < band < 1")
    lo, hi = rise_limits
    if not 0 <= lo < hi <= 1:
        raise _metrics_error("--rise-limits", f"{lo:g} {hi:g}", "not ordered within [0, 1]", "0 <= LOW < HIGH <= 1")
    if not (math.isfinite(ss_window) and ss_window > 0):
        raise _metrics_error("--ss-window", f"{ss_window:g}", "not a positive number of seconds", "a time > 0 s")
    return _Settings(settling_band, (lo, hi), ss_window)


def _write_metrics(out: Path, rows: list[tuple[str, str, str, float, str, str]], own: bool) -> None:
    """``--out``: nlcx's own files as controller, signal, metric, value, unit, note; any other
    file as signal, metric, value, unit."""
    import pandas as pd

    from nlcx.report import write_csv  # imports the engine: only when writing

    columns = ["controller", "signal", "metric", "value", "unit", "note"]
    table = pd.DataFrame(rows, columns=columns)
    write_csv(out, table if own else table[["signal", "metric", "value", "unit"]])


@app.command("metrics")
@one_line_errors
def metrics_command(
    file: Annotated[Path, typer.Argument(help="CSV file with a header row, or a Parquet file.", show_default=False)],
    time_column: Annotated[str, typer.Option("--time", help="Time column, in seconds.")] = "t",
    signals: Annotated[
        list[str] | None,
        typer.Option(
            "--signal",
            help="Column to measure; repeat for several (default: every column s with a reference column s_ref, "
            "else every column of numbers).",
            show_default=False,
        ),
    ] = None,
    reference: Annotated[
        str | None,
        typer.Option(
            "--reference",
            help="Target: a number, or a column (default: the signal's column s_ref if there is one, else its "
            "last sample).",
            show_default=False,
        ),
    ] = None,
    t_step: Annotated[
        float | None,
        typer.Option(
            "--t-step",
            help="Step time in s; earlier samples are ignored (default: the change of a reference column that "
            "steps once, else 0).",
            show_default=False,
        ),
    ] = None,
    settling_band: Annotated[
        float,
        typer.Option(
            "--settling-band", help="Settling band: a fraction of the step, or of a regulated signal's peak deviation."
        ),
    ] = 0.02,
    rise_limits: Annotated[
        tuple[float, float], typer.Option("--rise-limits", help="Rise time between these fractions of the step.")
    ] = (0.1, 0.9),
    ss_window: Annotated[
        float, typer.Option("--ss-window", help="Window of a regulated signal's steady-state error, s.")
    ] = 1.0,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write the metrics in long form to this CSV.", show_default=False),
    ] = None,
) -> None:
    """Step-response metrics of the columns of a CSV or Parquet file: logged on a rig, or nlcx's own time series.

    Each signal is measured by nlcx.metrics.step_info from its value at --t-step to its final value:
    its last sample, --reference, or its reference column s_ref. Against a reference column that is
    constant 0 a signal is measured as regulated (peak deviation, settling inside a band of it), and
    against one that varies (not a step) as tracking (error integrals); a note says which. A file
    with a controller column (nlcx's time series) is measured per controller."""
    s = _settings(settling_band, rise_limits, ss_window)
    frame = _read_frame(file)
    columns = list(frame.columns)
    if time_column not in columns:
        raise _metrics_error("--time", time_column, f"not a column of {file.name}", _names(columns))
    ref = _reference_option(reference, frame, file, time_column)
    names = _signals_of(frame, file, time_column, signals or [], ref)
    sources = {name: _source(name, ref, columns) for name in names}
    measured = [_measure_block(b, file, names, sources, t_step, s) for b in _blocks(frame, file, time_column)]
    own = CONTROLLER in columns or any(isinstance(v, str) for v in sources.values())
    for m in measured:
        typer.echo(_heading(file, m))
        typer.echo("\n".join(_table_lines(m)))
    for line in _notes(measured, s):
        typer.echo(line)
    if out is not None:
        _write_metrics(out, _rows(measured), own)
        typer.echo(f"wrote {out}")


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
        close = difflib.get_close_matches(text, words, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
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
) -> None:
    """List the registered plants, controllers, gain schedules, uncertainties, references and tuners.

    With KIND and NAME: that plugin's states, inputs and outputs (plants) and the fields of its
    parameters or configuration, with their types, units, defaults and descriptions."""
    kinds = [_kind(kind)] if kind else list(registry.ALL)
    if name is not None:
        reg = registry.ALL[kinds[0]]
        if name not in reg.names():
            raise NlcxError(f"list error: NAME = {name}: {reg.unknown_message(name)}")
        typer.echo("\n".join(_plugin_lines(reg.explain(name), _SECTIONS[kinds[0]])))
        return
    for each in kinds:
        typer.echo(f"{each}:")
        for entry, summary in registry.ALL[each].describe():
            typer.echo(f"  {entry:<20} {summary}")


# ----------------------------------------------------------------------------- nlcx schema


@app.command("schema")
@one_line_errors
def schema_command(
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write the schema to this file (default: print it).", show_default=False),
    ] = None,
) -> None:
    """The JSON Schema of an experiment config, for an editor to complete and check the YAML.

    It knows every registered plugin: a plant's parameters by its name, the configuration of each
    controller, gain schedule, uncertainty, reference and tuner by its kind."""
    from nlcx.schema import experiment_schema, schema_text

    text = schema_text(experiment_schema())
    if out is None:
        typer.echo(text, nl=False)
        return
    from nlcx.drawing import atomic_write

    atomic_write(out, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    typer.echo(f"wrote {out}")

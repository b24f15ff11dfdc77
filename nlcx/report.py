"""Run directories: metrics.csv, timeseries.csv (or .parquet), figures, config.yaml and manifest.json.

Every file is written atomically (to a temporary file in the same directory, then renamed),
so an interrupted run never leaves a half-written file behind.
"""

from __future__ import annotations

import platform
import socket
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict, cast

import numpy as np
import yaml

from nlcx import manifest as manifests
from nlcx import plugins
from nlcx._version import __version__
from nlcx.drawing import FigurePlan, Painter, atomic_write, draw_all
from nlcx.engine import METRIC_COLUMNS, ExperimentResult, Run
from nlcx.figure_plans import gains_plan, output_plan

if TYPE_CHECKING:
    import pandas as pd  # nlcx run writes its CSV files from columns, without pandas
    import pyarrow as pa

    from nlcx.plants.base import Plant

PACKAGES = (
    "numpy", "scipy", "numba", "llvmlite", "pandas", "pyarrow", "pydantic", "matplotlib", "PyYAML", "typer", "pymoo",
    "control",
)  # fmt: skip


def write_text(path: Path, text: str) -> None:
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def write_bytes(path: Path, data: bytes) -> None:
    atomic_write(path, lambda tmp: tmp.write_bytes(data))


def _write_table(path: Path, table: pa.Table) -> None:
    """``table`` as a CSV by Arrow's writer: ten times pandas' speed on long time series, and
    floats in their shortest round-trip form, so the same numbers always give the same bytes.
    A missing value (null, or NaN in a float column) is an empty field."""
    import pyarrow.csv as pacsv

    options = pacsv.WriteOptions(quoting_style="needed")
    atomic_write(path, lambda tmp: pacsv.write_csv(table, str(tmp), options))


def write_csv(path: Path, frame: pd.DataFrame, empty_as_missing: bool = False) -> None:
    """``frame`` as a CSV (:func:`_write_table`); a column of mixed values (e.g. tuning.csv's)
    is written as text. ``empty_as_missing``: an empty text as a missing value (an empty
    field, not ``""``), as a reader that takes empty fields for missing ones writes it back."""
    import pyarrow as pa

    frame = frame.copy()
    for col in frame.columns:
        if frame[col].dtype == object and len({type(v) for v in frame[col] if v is not None}) > 1:
            frame[col] = [v if isinstance(v, str) else repr(v) for v in frame[col]]
    table = pa.Table.from_pandas(frame, preserve_index=False)
    _write_table(path, empty_text_as_null(table) if empty_as_missing else table)


def empty_text_as_null(table: pa.Table) -> pa.Table:
    """``table`` with every empty string of its text columns a null."""
    import pyarrow as pa
    import pyarrow.compute as pc

    columns = [
        pc.if_else(pc.equal(col, ""), pa.scalar(None, col.type), col)
        if pa.types.is_string(col.type) or pa.types.is_large_string(col.type)
        else col
        for col in table.columns
    ]
    return pa.table(columns, names=table.column_names)


def _arrow_column(values: np.ndarray | Sequence[str]) -> pa.Array:
    """A float array as Arrow's float64 (NaN as null, as pandas hands it to Arrow), a sequence
    of strings as Arrow's strings; built from their buffers, because ``pyarrow.array`` imports
    pandas to check what it was given."""
    import pyarrow as pa

    if isinstance(values, np.ndarray) and values.dtype.kind == "f":
        data = np.ascontiguousarray(values, dtype=np.float64)
        missing = np.isnan(data)
        n_missing = int(missing.sum())
        validity = pa.py_buffer(np.packbits(~missing, bitorder="little")) if n_missing else None
        return pa.Array.from_buffers(pa.float64(), data.size, [validity, pa.py_buffer(data)], null_count=n_missing)
    encoded = [v.encode() for v in values]
    offsets = np.zeros(len(encoded) + 1, dtype=np.int64)
    np.cumsum([len(e) for e in encoded], out=offsets[1:])
    buffers = [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(encoded))]
    return pa.Array.from_buffers(pa.large_string(), len(encoded), buffers)


def _arrow_table(columns: Mapping[str, np.ndarray | Sequence[str]]) -> pa.Table:
    """Columns (name -> float array or strings) as an Arrow table (:func:`_arrow_column`)."""
    import pyarrow as pa

    return pa.table({name: _arrow_column(values) for name, values in columns.items()})


def write_columns(path: Path, columns: Mapping[str, np.ndarray | Sequence[str]]) -> None:
    """Columns (name -> float array or strings) as a CSV without importing pandas: the bytes
    :func:`write_csv` writes for the DataFrame of the same columns."""
    _write_table(path, _arrow_table(columns))


def write_parquet(path: Path, columns: Mapping[str, np.ndarray | Sequence[str]]) -> None:
    """Columns (name -> float array or strings) as a Parquet file, zstd-compressed: the table
    :func:`write_columns` writes as CSV (NaN as null), every float as its 8 bytes, and the
    same bytes for the same columns (and pyarrow version)."""
    import pyarrow.parquet as pq

    table = _arrow_table(columns)
    atomic_write(path, lambda tmp: pq.write_table(table, str(tmp), compression="zstd"))


def write_timeseries(stem: Path, columns: Mapping[str, np.ndarray | Sequence[str]], fmt: str) -> Path:
    """The time series ``columns`` as ``stem``.csv or ``stem``.parquet (``outputs.timeseries_format``)."""
    path = stem.with_name(f"{stem.name}.{fmt}")
    (write_parquet if fmt == "parquet" else write_columns)(path, columns)
    return path


def metric_columns(result: ExperimentResult) -> dict[str, np.ndarray | list[str]]:
    """The columns of ``result.metrics`` (:data:`~nlcx.engine.METRIC_COLUMNS`), from its rows."""
    rows = result.metric_rows
    columns: dict[str, np.ndarray | list[str]] = {}
    for i, name in enumerate(METRIC_COLUMNS):
        values = [row[i] for row in rows]
        columns[name] = np.array(values, dtype=np.float64) if name == "value" else values
    return columns


def _run_columns(run: Run, plant: Plant) -> dict[str, np.ndarray]:
    """A run's samples by column: t, states, inputs, references, loop logs."""
    cols = {"t": run.t}
    for i, name in enumerate(plant.state_names):
        cols[name] = run.x[:, i]
    for i, name in enumerate(plant.input_names):
        cols[name] = run.u[:, i]
    offsets = run.controller.reference_offsets or (0.0,) * len(run.controller.reference_signals)
    for i, (name, off) in enumerate(zip(run.controller.reference_signals, offsets, strict=True)):
        cols[f"{name}_ref" if off == 0 else f"{name}_ref{off:+g}"] = run.r[:, i]
    if run.log is not None:
        for i, name in enumerate(run.controller.log_names):
            cols[name] = run.log[:, i]
    return cols


def timeseries_columns(result: ExperimentResult) -> dict[str, np.ndarray]:
    """Every sample of every run (a result has at least one), runs one after another: t,
    controller, states, inputs, references, loop logs. A column a run lacks (another
    controller's log) is NaN in its rows."""
    per_run = [_run_columns(run, result.prepared.plant) for run in result.runs]
    names = list(dict.fromkeys(["t", "controller", *(name for cols in per_run for name in cols)]))
    out: dict[str, np.ndarray] = {}
    for name in names:
        if name == "controller":
            out[name] = np.concatenate([np.full(run.t.size, run.label, dtype=object) for run in result.runs])
            continue
        out[name] = np.concatenate([cols.get(name, np.full(cols["t"].size, np.nan)) for cols in per_run])
    return out


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version(), "nlcx": __version__}
    for name in PACKAGES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


class GitState(TypedDict):
    """The nlcx source tree's commit and whether it has changes (None: not a git checkout)."""

    commit: str | None
    dirty: bool | None


class Environment(TypedDict):
    """Where an output was made (:func:`environment`)."""

    host: str
    platform: str
    versions: dict[str, str]
    git: GitState


class Provenance(TypedDict):
    """How an output was made (:func:`provenance`)."""

    argv: list[str]
    overrides: list[str]
    started: str
    duration_s: float


def git_state() -> GitState:
    """Commit and dirty flag of the nlcx source tree, when it is a git checkout."""
    root = Path(__file__).resolve().parent.parent
    if not (root / ".git").exists():
        return {"commit": None, "dirty": None}
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--verify", "-q", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        commit = head.stdout.strip() if head.returncode == 0 else ""
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    return {"commit": commit or None, "dirty": bool(dirty)}


def utc_iso(timestamp: float) -> str:
    """A POSIX timestamp as UTC in ISO 8601, to the millisecond (``2024-05-01T12:00:00.000+00:00``)."""
    return datetime.fromtimestamp(timestamp, tz=timezone.utc).isoformat(timespec="milliseconds")


def environment() -> Environment:
    """Where an output was made: ``host`` (:func:`socket.gethostname`), ``platform``
    (:func:`platform.platform`), the package ``versions`` and the ``git`` state of nlcx."""
    return {
        "host": socket.gethostname(),
        "platform": platform.platform(),
        "versions": package_versions(),
        "git": git_state(),
    }


def provenance(overrides: Sequence[str] = (), started: float | None = None) -> Provenance:
    """How an output was made: ``argv`` (this process's command line, :data:`sys.argv`), the
    ``overrides`` as given, ``started`` (UTC, ISO 8601) and ``duration_s``, from the
    ``time.perf_counter()`` instant ``started`` (default: now) until now."""
    now = time.perf_counter()
    begun = now if started is None else started
    return {
        "argv": list(sys.argv),
        "overrides": [str(item) for item in overrides],
        "started": utc_iso(time.time() - (now - begun)),
        "duration_s": round(now - begun, 4),
    }


def manifest(
    result: ExperimentResult,
    timings: dict[str, float],
    overrides: Sequence[str] = (),
    started: float | None = None,
    where: Environment | None = None,
) -> dict[str, object]:
    """manifest.json of a run directory: its name and kind (``nlcx_output``: run), how and where
    it was made (:func:`provenance` from ``started``, :func:`environment` or ``where``), whether
    the config could read the process's environment (``allow_env``), the seeds, the timings,
    each run's status and (filled in by :func:`write_run`) the files."""
    exp = result.prepared.experiment
    ss = result.prepared.seed_sequence
    return {
        "name": exp.name,
        "nlcx_output": "run",
        **provenance(overrides, started),
        "allow_env": exp.allow_env,
        "imports": plugins.loaded(),
        **(environment() if where is None else where),
        "seed": {
            "entropy": int(cast(int, ss.entropy)),  # prepare seeds it with the config's integer seed
            # the children prepare spawned, one an uncertainty in config order (spawn(0) listed none)
            "uncertainty_spawn_keys": [[*ss.spawn_key, i] for i in range(ss.n_children_spawned)],
        },
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
        "outputs": [[s.name, s.unit, s.label] for s in result.prepared.plant.outputs],
        "states": result.prepared.plant.state_names,
        "inputs": result.prepared.plant.input_names,
        "output_matrix": result.prepared.plant.C.tolist(),
        "runs": [
            {
                "controller": run.label,
                "kind": run.controller.kind,
                "status": run.status,
                "reason": run.reason,
                "samples": int(run.t.size),
                "t_fail": None if np.isnan(run.t_fail) else run.t_fail,
            }
            for run in result.runs
        ],
        "files": [],
    }


def write_run(
    result: ExperimentResult,
    out_dir: Path,
    timings: dict[str, float],
    started: float | None = None,
    painter: Painter | None = None,
    overrides: Sequence[str] = (),
) -> list[Path]:
    """Write the files of a run directory into ``out_dir``; manifest.json last, listing the
    files, the timings and the ``overrides`` the run was built with.

    ``started`` (a ``time.perf_counter()`` value) makes the manifest record the wall time
    from then until the manifest is written, and the start (default: when writing began).
    The figures are planned first and drawn by ``painter`` (another process) if given, else
    here in a thread, while this thread writes config.yaml and the CSV files (from columns,
    without pandas; tuning.csv, written only when tuners or controllers report values, through
    a DataFrame) and gathers the manifest's :func:`environment`. This writes into ``out_dir``
    as it stands: :func:`nlcx.rundir.save_run` stages, locks and renames the whole directory.
    """
    write_start = time.perf_counter()
    exp = result.prepared.experiment
    outputs = exp.section.outputs
    figures: list[tuple[Path, FigurePlan]] = []
    if outputs.figure:
        figures.append((out_dir / "figure.png", output_plan(result, exp.section.title)))
    if outputs.gains_figure:
        figures.append((out_dir / "gains.png", gains_plan(result)))
    written: list[Path] = []
    with ThreadPoolExecutor(max_workers=1) as pool:
        drawn = pool.submit(painter.paint if painter is not None else draw_all, figures)
        path = out_dir / "config.yaml"
        write_text(path, yaml.safe_dump(exp.resolved(), sort_keys=False, allow_unicode=True))
        written.append(path)
        path = out_dir / "metrics.csv"
        write_columns(path, metric_columns(result))
        written.append(path)
        if result.prepared.tuning:
            import pandas as pd

            path = out_dir / "tuning.csv"
            write_csv(path, pd.DataFrame(result.prepared.tuning, columns=["controller", "tuner", "parameter", "value"]))
            written.append(path)
        if outputs.timeseries:  # pyarrow encodes without holding the GIL
            columns = timeseries_columns(result)
            written.append(write_timeseries(out_dir / "timeseries", columns, outputs.timeseries_format))
        where = environment()  # while the figures are drawn
        drawn.result()
    written += [path for path, _ in figures]
    timings = {**timings, "write": time.perf_counter() - write_start}
    if started is not None:
        timings["wall"] = time.perf_counter() - started
    info = manifest(result, timings, overrides, write_start if started is None else started, where)
    info["files"] = [p.name for p in written]
    manifests.write(out_dir, info)  # the mark, and the checksum of every file
    return [*written, out_dir / "manifest.json"]

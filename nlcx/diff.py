"""``nlcx diff BASE NEW``: compare metric CSVs cell by cell, with per-metric tolerances.

Every table under BASE, a CSV or Parquet file (e.g. a time series written with
``outputs.timeseries_format: parquet``) or a Parquet dataset (a directory ``*.parquet`` of
part files: a sweep's ``metrics.parquet`` and ``sweep.parquet``, one table each), is matched
with the table at the same relative path under NEW, or, where NEW holds that table in the
other form, with that one (``metrics.csv`` with ``metrics.parquet``); ``only``: the tables
whose relative path matches one of the given patterns. A sweep's tables are read as
:func:`nlcx.results.read_output_table` reads them, so a sweep written as CSV and the same
sweep written as Parquet hold the same cells. Rows are matched on their text columns (e.g.
controller, signal, metric) and every numeric column is compared: a cell drifts when
|new - base| > atol + rtol |base| (NaN equals NaN). Tolerances are given per metric: in
long-form files the ``metric`` column names the metric, otherwise the column name does, and
``default`` applies to the rest.

Two kinds of text column are not part of a row's key:

- a note (:data:`DESCRIPTIVE`: ``note``, ``message``, ``reason``) describes its row; a changed
  note is a changed cell.
- a status (:func:`status_columns`: ``status``, ``nlcx_status``, ...) is the outcome of a run.
  The rows of a run share its key columns other than :data:`ROW_KEYS` (e.g. its controller,
  or its variant and controller in a sweep). A run whose statuses changed (ok -> unstable)
  is one drift, ``status: ok -> unstable``, and its rows, which then differ (an unstable run
  has a failure time instead of metrics), are not compared; elsewhere a status is compared
  cell by cell as a note is.
"""

from __future__ import annotations

import fnmatch
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from nlcx.errors import NlcxError
from nlcx.pages.output_tables import STEMS, is_table, read_table

#: Text columns that describe a row rather than identify it: compared as cells.
DESCRIPTIVE = ("note", "message", "reason")
#: Text columns that tell the rows of one run apart; the other key columns identify the run.
ROW_KEYS = ("signal", "metric", "unit")


@dataclass
class Tolerances:
    rtol: dict[str, float] = field(default_factory=lambda: {"default": 1e-6})
    atol: dict[str, float] = field(default_factory=lambda: {"default": 1e-9})

    def of(self, metric: str) -> tuple[float, float]:
        return self.rtol.get(metric, self.rtol["default"]), self.atol.get(metric, self.atol["default"])


def parse_tolerances(rtol: list[str], atol: list[str]) -> Tolerances:
    """``["1e-6", "settling_time=1e-3"]`` -> default 1e-6, settling_time 1e-3."""
    tol = Tolerances()
    for option, values, target in (("--rtol", rtol, tol.rtol), ("--atol", atol, tol.atol)):
        for text in values:
            name, sep, value = text.rpartition("=")
            key = name if sep else "default"
            try:
                number = float(value)
            except ValueError:
                raise NlcxError(f"{option} {text!r}: expected VALUE or METRIC=VALUE with a number") from None
            if number < 0:
                raise NlcxError(f"{option} {text!r}: a tolerance must be >= 0")
            target[key] = number
    return tol


@dataclass
class Drift:
    file: str
    key: str
    column: str
    base: float | str
    new: float | str

    @property
    def abs_diff(self) -> float:
        try:
            return abs(float(self.new) - float(self.base))
        except (TypeError, ValueError):
            return math.nan

    @property
    def status_change(self) -> bool:
        """Whether this is a run's changed status (see the module's docstring)."""
        return is_status_column(self.column)


#: The tables compared: CSVs, Parquet files and Parquet datasets (directories).
SUFFIXES = (".csv", ".parquet")


def is_status_column(column: str) -> bool:
    """``status`` and ``<something>_status`` (e.g. the thesis tables' ``nlcx_status``)."""
    return column == "status" or column.endswith("_status")


def status_columns(columns: Sequence[str]) -> list[str]:
    return [c for c in columns if is_status_column(c)]


def _read(path: Path) -> pd.DataFrame:
    """A table: a sweep's (``metrics`` or ``sweep``, either form, and a run's metrics.csv) as
    :func:`nlcx.results.read_output_table` reads it; any other CSV with an empty cell as NaN,
    any other text kept; any other Parquet file or dataset with null as NaN."""
    if path.stem in STEMS:
        return read_table(path)
    if path.suffix == ".parquet":
        return pd.read_parquet(path)
    return pd.read_csv(path, keep_default_na=False, na_values=[""])


def _text(frame: pd.DataFrame, columns: list[str]) -> pd.Series:
    """The cells of ``columns`` joined as ``a | b`` per row (a missing cell as empty text); the
    row's position where there is no column (a table without rows: no text)."""
    if not columns:
        return pd.Series(frame.index.map(str), index=frame.index)
    if frame.empty:  # joining the cells of no row would give a frame, not a series
        return pd.Series("", index=frame.index, dtype=object)
    cells = frame[columns].map(lambda v: "" if pd.isna(v) else str(v))
    return cells.agg(" | ".join, axis=1)


def _keyed(frame: pd.DataFrame, keys: list[str], run_keys: list[str]) -> pd.DataFrame:
    """``frame`` with its row key ``_key`` (repeated keys told apart by ``_occurrence``), the
    row's name in a drift, ``_label`` (``KEY #k`` for the k-th row of a repeated key, e.g. a
    sample of a controller's time series) and the key of its run, ``_run``."""
    out = frame.copy()
    out["_key"] = _text(out, keys)
    groups = out.groupby("_key")
    out["_occurrence"] = groups.cumcount()
    repeated = groups["_key"].transform("size").to_numpy() > 1
    out["_label"] = out["_key"].where(~repeated, out["_key"] + " #" + out["_occurrence"].astype(str))
    out["_run"] = _text(out, run_keys) if run_keys else "(all rows)"
    return out


def _statuses(frame: pd.DataFrame, columns: list[str]) -> dict[str, str]:
    """Per run: its distinct statuses, in order, as ``ok`` or ``ok / unstable``."""
    text = _text(frame, columns)
    out: dict[str, list[str]] = {}
    for run, status in zip(frame["_run"], text, strict=True):
        seen = out.setdefault(run, [])
        if status not in seen:
            seen.append(status)
    return {run: " / ".join(values) for run, values in out.items()}


def _status_changes(name: str, base: pd.DataFrame, new: pd.DataFrame, columns: list[str]) -> list[Drift]:
    """One drift per run (in both files) whose statuses changed."""
    if not columns:
        return []
    before, after = _statuses(base, columns), _statuses(new, columns)
    label = " | ".join(columns)
    return [
        Drift(name, run, label, status, after[run])
        for run, status in before.items()
        if run in after and after[run] != status
    ]


def _cell_drifts(name: str, both: pd.DataFrame, numeric: list[str], keys: list[str], tol: Tolerances) -> list[Drift]:
    """The numeric cells of matched rows that moved beyond their tolerance."""
    drifts = []
    metric_names = both["metric_base"] if "metric" in keys else None
    for col in numeric:
        bv = pd.to_numeric(both[f"{col}_base"], errors="coerce").to_numpy(dtype=float)
        nv = pd.to_numeric(both[f"{col}_new"], errors="coerce").to_numpy(dtype=float)
        names = metric_names.to_numpy() if metric_names is not None else np.full(len(both), col)
        rt = np.array([tol.of(str(m))[0] for m in names]) if len(both) else np.zeros(0)
        at = np.array([tol.of(str(m))[1] for m in names]) if len(both) else np.zeros(0)
        same = (np.isnan(bv) & np.isnan(nv)) | (bv == nv)  # NaN against NaN; an infinity against itself
        with np.errstate(invalid="ignore"):
            close = np.abs(nv - bv) <= at + rt * np.abs(bv)
        bad = ~(same | close)
        for k in np.nonzero(bad)[0]:
            drifts.append(Drift(name, str(both["_label"].iloc[k]), col, bv[k], nv[k]))
    return drifts


def _text_drifts(name: str, both: pd.DataFrame, columns: list[str]) -> list[Drift]:
    """The text cells (notes, statuses) of matched rows that changed."""
    drifts = []
    for col in columns:
        before = both[f"{col}_base"].map(lambda v: "" if pd.isna(v) else str(v))
        after = both[f"{col}_new"].map(lambda v: "" if pd.isna(v) else str(v))
        for k in np.flatnonzero((before != after).to_numpy()):
            drifts.append(Drift(name, str(both["_label"].iloc[k]), col, before.iloc[k], after.iloc[k]))
    return drifts


def _numeric(name: str, base: pd.Series, new: pd.Series) -> bool:
    """Whether a column is compared as numbers: numbers in BASE (cells of NEW that are not are
    NaN), unless BASE's are all empty and NEW's are text (e.g. notes, none in BASE); never a
    note, a status or a sweep's ``variant`` (a key)."""
    if name == "variant" or name in DESCRIPTIVE or is_status_column(name):
        return False
    return pd.api.types.is_numeric_dtype(base) and (pd.api.types.is_numeric_dtype(new) or bool(base.notna().any()))


def compare_frames(name: str, base: pd.DataFrame, new: pd.DataFrame, tol: Tolerances) -> list[Drift]:
    """Drifting cells, changed statuses, missing and extra rows of one file."""
    if list(new.columns) != list(base.columns):
        return [Drift(name, "(columns)", "", ", ".join(base.columns), ", ".join(new.columns))]
    numeric = [c for c in base.columns if _numeric(c, base[c], new[c])]
    status = status_columns([c for c in base.columns if c not in numeric])
    described = [c for c in base.columns if c not in numeric and (c in DESCRIPTIVE or c in status)]
    keys = [c for c in base.columns if c not in numeric and c not in described]
    run_keys = [c for c in keys if c not in ROW_KEYS]
    b, n = _keyed(base, keys, run_keys), _keyed(new, keys, run_keys)
    drifts = _status_changes(name, b, n, status)
    changed = {d.key for d in drifts}
    b, n = b[~b["_run"].isin(changed)], n[~n["_run"].isin(changed)]
    merged = b.merge(n, on=["_key", "_occurrence"], how="outer", suffixes=("_base", "_new"), indicator=True)
    merged["_label"] = merged["_label_base"].fillna(merged["_label_new"])
    unmatched = merged[merged["_merge"] != "both"]
    for label, merge in zip(unmatched["_label"], unmatched["_merge"], strict=True):
        missing = merge == "left_only"
        drifts.append(
            Drift(name, label, "(row)", "present" if missing else "", "missing in NEW" if missing else "extra in NEW")
        )
    both = merged[merged["_merge"] == "both"]
    return drifts + _cell_drifts(name, both, numeric, keys, tol) + _text_drifts(name, both, described)


def _tables_under(base: Path) -> list[Path]:
    """The tables under the directory ``base``, in path order: its CSV and Parquet files and
    its Parquet datasets (:func:`~nlcx.pages.output_tables.is_table`), each dataset once, not
    its part files."""
    found = sorted(p for p in base.rglob("*") if p.suffix in SUFFIXES and is_table(p))
    return [p for p in found if not any(part.endswith(".parquet") for part in p.relative_to(base).parts[:-1])]


def _compared_files(base: Path, only: Sequence[str]) -> list[tuple[Path, str]]:
    """(path, relative path) of the tables of ``base`` to compare: those matching a pattern of
    ``only`` (fnmatch on the relative path), or all. ``base`` itself is one table when it is
    a file or a Parquet dataset."""
    one = is_table(base)
    files = [base] if one else _tables_under(base)
    pairs = [(p, p.name if one else p.relative_to(base).as_posix()) for p in files]
    if not only:
        return pairs
    chosen = [(p, rel) for p, rel in pairs if any(fnmatch.fnmatchcase(rel, pattern) for pattern in only)]
    if not chosen:
        names = [rel for _, rel in pairs]
        listed = ", ".join(names[:20]) + (f", ... ({len(names) - 20} more)" if len(names) > 20 else "")
        raise NlcxError(
            f"diff error: --only = {' '.join(only)}: matches no file of {base}; allowed: a pattern on the "
            f"relative paths: {listed or '(no CSV or Parquet file)'}"
        )
    return chosen


def _counterpart(new: Path, rel: str) -> Path | None:
    """The table of ``new`` (a table itself, or a directory) that BASE's table ``rel`` is
    compared with: the one at ``rel``, else the same table in the other form (a CSV's
    Parquet file or dataset, a Parquet's CSV); None when NEW has neither."""
    if is_table(new):
        return new
    same = new / rel
    if is_table(same):
        return same
    if same.suffix not in SUFFIXES:
        return None
    other = same.with_suffix(".parquet" if same.suffix == ".csv" else ".csv")
    return other if is_table(other) else None


def diff_dirs(base: Path, new: Path, tol: Tolerances, only: Sequence[str] = ()) -> tuple[list[Drift], int]:
    """All drifts between the CSV and Parquet files under ``base`` and ``new`` (``only``: the
    files whose relative path matches one of these fnmatch patterns); and how many files were
    compared."""
    if not base.exists():
        raise NlcxError(f"{base}: no such baseline directory or file")
    if not new.exists():
        raise NlcxError(f"{new}: no such directory or file")
    files = _compared_files(base, only)
    drifts: list[Drift] = []
    for path, rel in files:
        other = _counterpart(new, rel)
        if other is None:
            drifts.append(Drift(rel, "(file)", "", "present", "missing"))
            continue
        drifts += compare_frames(rel, _read(path), _read(other), tol)
    return drifts, len(files)


def summary(drifts: list[Drift], n_files: int) -> str:
    """``drift: N cell(s) in F of M file(s): FILE K, FILE K (S status change(s)), ...``: how many
    drifts each file holds, so that a few moved metrics stand out beside a long time series."""
    counts = Counter(d.file for d in drifts)
    status = Counter(d.file for d in drifts if d.status_change)
    per_file = ", ".join(
        f"{name} {count}" + (f" ({status[name]} status change(s))" if status[name] else "")
        for name, count in counts.items()
    )
    return f"drift: {len(drifts)} cell(s) in {len(counts)} of {n_files} file(s): {per_file}"


def render(drifts: list[Drift], limit: int = 50, per_file: int = 10) -> str:
    """A readable account of what changed: each run's changed status on a line of its own
    (``FILE  RUN  status: ok -> unstable``), then a table of the other drifts, at most
    ``per_file`` of each file and ``limit`` in all."""
    lines = [f"{d.file}  {d.key}  {d.column}: {d.base} -> {d.new}" for d in drifts if d.status_change]
    cells = [d for d in drifts if not d.status_change]
    shown: list[Drift] = []
    of_file: Counter[str] = Counter()
    left: Counter[str] = Counter()
    for d in cells:
        if len(shown) < limit and of_file[d.file] < per_file:
            shown.append(d)
            of_file[d.file] += 1
        else:
            left[d.file] += 1
    if shown:
        lines.append(_table(shown))
    lines += [f"... and {count} more in {name}" for name, count in left.items()]
    return "\n".join(lines)


def _table(drifts: list[Drift]) -> str:
    rows = [(d.file, d.key, d.column, _fmt(d.base), _fmt(d.new), _diff_text(d)) for d in drifts]
    header = ("file", "row", "column", "base", "new", "|diff|")
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    return "\n".join(lines)


def _diff_text(drift: Drift) -> str:
    """|new - base| of a numeric cell; nothing for a text cell (a note, a missing row)."""
    if isinstance(drift.base, str) or isinstance(drift.new, str):
        return ""
    return _fmt(drift.abs_diff)


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return str(value)

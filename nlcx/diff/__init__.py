"""``nlcx diff BASE NEW``: compare metric tables cell by cell, with per-metric tolerances.

Every table under BASE, a CSV or Parquet file (e.g. a time series written with
``outputs.timeseries_format: parquet``) or a Parquet dataset (a directory ``*.parquet`` of
part files: a sweep's ``metrics.parquet`` and ``sweep.parquet``, one table each), is matched
with the table at the same relative path under NEW, or, where NEW holds that table in the
other form, with that one (``metrics.csv`` with ``metrics.parquet``); ``only``: the tables
whose relative path matches one of the given patterns. A sweep written as CSV and the same
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

How a pair of tables is compared (:mod:`nlcx.diff.stream`, :mod:`nlcx.diff.matching`,
:mod:`nlcx.diff.rows`, :mod:`nlcx.diff.statuses`, :mod:`nlcx.diff.tables`), in memory bounded
whatever their size and in time linear in it:

- Each file of a table (a CSV or Parquet file, each part file of a dataset) is checked
  against the manifest of the nlcx output directory that lists it before it is read
  (:func:`nlcx.manifest.verify_file`): a truncated or altered file is refused in one line; a
  file that no manifest lists is read as it is. Two tables whose files hold the same bytes
  (same sizes, then the bytes compared a megabyte at a time) have no drift and are not parsed.
- The tables are read a chunk of rows at a time, never whole, and compared column by column
  with numpy and pyarrow. Per file, the drifting cells, status changes, missing and extra rows
  are counted exactly, and only the first :data:`KEEP` (10) drifts in row order and the first
  :data:`KEEP_STATUS` (50) status changes are kept to be shown.
- Rows are matched on their key (the text of their key columns, and the occurrence number of
  a repeated key: the k-th row of a key in BASE with its k-th row in NEW). While the two
  tables list the same keys in the same order, rows are compared chunk against chunk; from a
  row whose key differs, rows are matched on 64-bit hashes of their key and occurrence, and
  the rows without a match yet wait for it in a pending set across chunks. When more than
  :data:`PENDING_ROWS` (1 000 000) rows wait at once, or rows that hold more than
  :data:`PENDING_BYTES` (128 MiB: 8 bytes a number, 16 a text; fewer rows of a wide table),
  as when the tables list their rows in different orders, matching stops: the waiting rows and
  all the rows after them are counted as missing and extra rows, and one line of the output
  says so.
- Status changes: while the rows are compared, each run's distinct statuses are gathered as
  64-bit hashes in numpy arrays (one entry per distinct (run, status) pair, in the order they
  first appear). Runs whose statuses differ are status changes; if there are any, the rows are
  compared again without those runs' rows. A table of more than :data:`STATUS_RUNS`
  (1 000 000) distinct (run, status) pairs has its statuses compared row by row, and one line
  of the output says so.
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from nlcx.diff.records import (
    DESCRIPTIVE,
    KEEP,
    KEEP_STATUS,
    PENDING_BYTES,
    PENDING_ROWS,
    ROW_KEYS,
    STATUS_RUNS,
    Drift,
    FileDrift,
    Tolerances,
    is_status_column,
    status_columns,
)
from nlcx.errors import NlcxError
from nlcx.pages.output_tables import is_table

__all__ = [
    "DESCRIPTIVE",
    "KEEP",
    "KEEP_STATUS",
    "PENDING_BYTES",
    "PENDING_ROWS",
    "ROW_KEYS",
    "STATUS_RUNS",
    "SUFFIXES",
    "DiffReport",
    "Drift",
    "FileDrift",
    "Tolerances",
    "config_changes",
    "diff_dirs",
    "file_summaries",
    "is_status_column",
    "parse_tolerances",
    "render",
    "status_columns",
    "summary",
]


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
class DiffReport:
    """The drift of every table compared: ``files`` in path order, ``n_files`` of them."""

    files: list[FileDrift]
    n_files: int

    @property
    def drifted(self) -> list[FileDrift]:
        """The tables with drift."""
        return [f for f in self.files if f.total]

    @property
    def total(self) -> int:
        """Every drift of every table."""
        return sum(f.total for f in self.files)

    @property
    def drifts(self) -> list[Drift]:
        """The drifts kept to be shown, table by table: status changes first."""
        return [d for f in self.files for d in (*f.statuses, *f.first)]


#: The tables compared: CSVs, Parquet files and Parquet datasets (directories).
SUFFIXES = (".csv", ".parquet")


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


def diff_dirs(base: Path, new: Path, tol: Tolerances, only: Sequence[str] = (), keep: int = KEEP) -> DiffReport:
    """The drift between the CSV and Parquet tables under ``base`` and ``new``.

    Parameters
    ----------
    base, new : Path
        Two directories, or two tables (files or Parquet datasets).
    tol : Tolerances
        Per-metric relative and absolute tolerances.
    only : sequence of str
        fnmatch patterns on the relative paths of ``base``'s tables: compare only those.
    keep : int
        Drifts kept to be shown per file (all are counted).

    Returns
    -------
    DiffReport
        One :class:`FileDrift` per table of ``base`` compared.

    Raises
    ------
    nlcx.manifest.IntegrityError
        A file of a table is not the one its output directory's manifest lists.
    nlcx.errors.NlcxError
        ``base`` or ``new`` is missing, ``only`` matches nothing, or a table cannot be read.
    """
    from nlcx.diff.stream import compare_tables
    from nlcx.diff.tables import open_table, same_bytes

    if not base.exists():
        raise NlcxError(f"{base}: no such baseline directory or file")
    if not new.exists():
        raise NlcxError(f"{new}: no such directory or file")
    files = _compared_files(base, only)
    verified: set[tuple[int, int]] = set()
    out = []
    for path, rel in files:
        other = _counterpart(new, rel)
        if other is None:
            out.append(FileDrift(rel, tables=1, first=[Drift(rel, "(file)", "", "present", "missing")]))
            continue
        base_table, new_table = open_table(path, verified), open_table(other, verified)
        if same_bytes(base_table, new_table):
            out.append(FileDrift(rel, identical=True))
            continue
        out.append(compare_tables(rel, base_table, new_table, tol, keep))
    return DiffReport(out, len(files))


def config_changes(base: Path, new: Path) -> list[str] | None:
    """The resolved configs' differences, ``key: old → new`` (a dotted key; ``(absent)`` for a
    key one of them lacks), from the config.yaml of each of two output directories, in key
    order; None unless both hold one. Each config.yaml is checked against its manifest first."""
    from nlcx import safe_yaml
    from nlcx.manifest import verify_file

    files = [base / "config.yaml", new / "config.yaml"]
    if not all(path.is_dir() for path in (base, new)) or not all(f.is_file() for f in files):
        return None
    flat = []
    for file in files:
        verify_file(file)
        data = safe_yaml.load_file(file)
        flat.append(_flattened(data if isinstance(data, dict) else {}))
    old, now = flat
    return [
        f"{key}: {_shown(old.get(key, _ABSENT))} → {_shown(now.get(key, _ABSENT))}"
        for key in sorted(old.keys() | now.keys())
        if key not in old or key not in now or old[key] != now[key] or type(old[key]) is not type(now[key])
    ]


_ABSENT = object()


def _flattened(data: dict[str, object], prefix: str = "") -> dict[str, object]:
    """A nested mapping as dotted keys to the values that are not mappings (an empty mapping
    has none)."""
    out: dict[str, object] = {}
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flattened(value, dotted + "."))
        else:
            out[dotted] = value
    return out


def _shown(value: object) -> str:
    """A config value as YAML writes it inline (``(absent)`` for a missing key)."""
    import json

    if value is _ABSENT:
        return "(absent)"
    if value is None:
        return "null"
    if isinstance(value, str):
        return value
    try:
        return json.dumps(value, ensure_ascii=False)
    except (TypeError, ValueError):
        return repr(value)


def file_summaries(report: DiffReport) -> list[str]:
    """One line per table that drifted: ``FILE: N cell(s) drifted (COLUMNS), largest |diff| X``,
    with its status changes, missing and extra rows, and whether its columns differ."""
    lines = []
    for f in report.drifted:
        parts = []
        if f.tables:
            parts.append("missing in NEW" if f.first and f.first[0].key == "(file)" else "other columns")
        if f.cells:
            largest = "" if math.isnan(f.largest) else f", largest |diff| {_fmt(f.largest)}"
            parts.append(f"{f.cells} cell(s) drifted ({', '.join(f.columns)}){largest}")
        if f.status_changes:
            parts.append(f"{f.status_changes} status change(s)")
        if f.missing_rows:
            parts.append(f"{f.missing_rows} row(s) missing in NEW")
        if f.extra_rows:
            parts.append(f"{f.extra_rows} row(s) extra in NEW")
        lines.append(f"{f.file}: {'; '.join(parts)}")
    return lines


def summary(report: DiffReport) -> str:
    """``drift: N cell(s) in F of M file(s): FILE K, FILE K (S status change(s)), ...``: how many
    drifts each file holds, so that a few moved metrics stand out beside a long time series."""
    per_file = ", ".join(
        f"{f.file} {f.total}" + (f" ({f.status_changes} status change(s))" if f.status_changes else "")
        for f in report.drifted
    )
    return f"drift: {report.total} cell(s) in {len(report.drifted)} of {report.n_files} file(s): {per_file}"


def render(report: DiffReport, limit: int = 50, per_file: int = KEEP, cells: bool = True) -> str:
    """A readable account of what changed: each run's changed status on a line of its own
    (``FILE  RUN  status: ok -> unstable``), then (``cells``) a table of the other drifts, at
    most ``per_file`` of each file and ``limit`` in all, then a line for each limit reached."""
    lines = []
    for f in report.drifted:
        lines += [f"{d.file}  {d.key}  {d.column}: {d.base} -> {d.new}" for d in f.statuses]
        if f.status_changes > len(f.statuses):
            lines.append(f"... and {f.status_changes - len(f.statuses)} more status change(s) in {f.file}")
    shown: list[Drift] = []
    left = []
    for f in report.drifted if cells else ():
        some = f.first[: max(min(per_file, limit - len(shown)), 0)]
        shown += some
        rest = f.total - f.status_changes - len(some)
        if rest:
            left.append(f"... and {rest} more in {f.file}")
    if shown:
        lines.append(_table(shown))
    lines += left
    lines += [note for f in report.files for note in f.notes]
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

"""``nlcx diff BASE NEW``: compare metric CSVs cell by cell, with per-metric tolerances.

Every CSV (and Parquet time series, ``outputs.timeseries_format: parquet``) under BASE is
matched with the file at the same relative path under NEW. Rows
are matched on their text columns (e.g. controller, signal, metric) and every numeric
column is compared: a cell drifts when |new - base| > atol + rtol |base| (NaN equals NaN).
Tolerances are given per metric: in long-form files the ``metric`` column names the metric,
otherwise the column name does, and ``default`` applies to the rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from nlcx.errors import NlcxError


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


#: The files compared: CSVs and Parquet time series.
SUFFIXES = (".csv", ".parquet")


def _read(path: Path) -> pd.DataFrame:
    """A CSV (an empty cell is NaN, any other text is kept) or a Parquet file (null is NaN)."""
    if path.suffix == ".parquet":
        return pd.read_parquet(path)
    return pd.read_csv(path, keep_default_na=False, na_values=[""])


def compare_frames(name: str, base: pd.DataFrame, new: pd.DataFrame, tol: Tolerances) -> list[Drift]:
    """Drifting cells, missing and extra rows of one file."""
    numeric = [c for c in base.columns if pd.api.types.is_numeric_dtype(base[c]) and c != "variant"]
    keys = [c for c in base.columns if c not in numeric]
    if list(new.columns) != list(base.columns):
        return [Drift(name, "(columns)", "", ", ".join(base.columns), ", ".join(new.columns))]
    b = base.copy()
    n = new.copy()
    for frame in (b, n):
        text = frame[keys].map(lambda v: "" if pd.isna(v) else str(v)) if keys else None
        frame["_key"] = text.agg(" | ".join, axis=1) if text is not None else frame.index.map(str)
        frame["_occurrence"] = frame.groupby("_key").cumcount()
    merged = b.merge(n, on=["_key", "_occurrence"], how="outer", suffixes=("_base", "_new"), indicator=True)
    drifts = []
    unmatched = merged[merged["_merge"] != "both"]
    for key, merge in zip(unmatched["_key"], unmatched["_merge"], strict=True):
        side = "missing in NEW" if merge == "left_only" else "extra in NEW"
        drifts.append(Drift(name, key, "(row)", side if merge == "left_only" else "", side))
    both = merged[merged["_merge"] == "both"]
    metric_names = both["metric_base"] if "metric" in keys else None
    for col in numeric:
        bv = pd.to_numeric(both[f"{col}_base"], errors="coerce").to_numpy(dtype=float)
        nv = pd.to_numeric(both[f"{col}_new"], errors="coerce").to_numpy(dtype=float)
        names = metric_names.to_numpy() if metric_names is not None else np.full(len(both), col)
        rt = np.array([tol.of(str(m))[0] for m in names]) if len(both) else np.zeros(0)
        at = np.array([tol.of(str(m))[1] for m in names]) if len(both) else np.zeros(0)
        same_nan = np.isnan(bv) & np.isnan(nv)
        with np.errstate(invalid="ignore"):
            close = np.abs(nv - bv) <= at + rt * np.abs(bv)
        bad = ~(same_nan | close)
        for k in np.nonzero(bad)[0]:
            drifts.append(Drift(name, str(both["_key"].iloc[k]), col, bv[k], nv[k]))
    return drifts


def diff_dirs(base: Path, new: Path, tol: Tolerances) -> tuple[list[Drift], int]:
    """All drifts between the CSV and Parquet files under ``base`` and ``new``; and how many
    files were compared."""
    if not base.exists():
        raise NlcxError(f"{base}: no such baseline directory or file")
    if not new.exists():
        raise NlcxError(f"{new}: no such directory or file")
    files = [base] if base.is_file() else sorted(p for p in base.rglob("*") if p.suffix in SUFFIXES)
    drifts: list[Drift] = []
    for path in files:
        rel = path.name if base.is_file() else str(path.relative_to(base))
        other = new if new.is_file() else new / rel
        if not other.exists():
            drifts.append(Drift(rel, "(file)", "", "present", "missing"))
            continue
        drifts += compare_frames(rel, _read(path), _read(other), tol)
    return drifts, len(files)


def render(drifts: list[Drift], limit: int = 50) -> str:
    """A readable table of what changed."""
    rows = [(d.file, d.key, d.column, _fmt(d.base), _fmt(d.new), _fmt(d.abs_diff)) for d in drifts[:limit]]
    header = ("file", "row", "column", "base", "new", "|diff|")
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    if len(drifts) > limit:
        lines.append(f"... and {len(drifts) - limit} more")
    return "\n".join(lines)


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return str(value)

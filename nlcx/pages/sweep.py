"""What the report of a sweep directory shows: the aggregates people otherwise script.

Per controller, signal and metric over the variants: median, interquartile range, min, max,
and how many variants measured it, were unstable (the run stopped) or failed (the variant
did not run); ``summary.csv`` holds the same table. Charts (:mod:`nlcx.pages.sweep_charts`,
SVG drawn from aggregates, so their cost does not grow with the variants): each metric's
distribution per controller, and each metric against each varied parameter, its median and
interquartile range per bin of the parameter; ``profiles.csv`` holds the numbers they draw.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import yaml

if TYPE_CHECKING:
    import pyarrow as pa

from nlcx import report
from nlcx.pages import charts, sweep_charts
from nlcx.pages.output_tables import PART_FILES, STEMS, read_output_table, table_path

FILES = "report_files"


def summary(metrics: pd.DataFrame, index: pd.DataFrame) -> pd.DataFrame:
    """controller, signal, metric, unit, n (variants that measured it), median, q25, q75, iqr,
    min, max, undefined (ran, but the metric is undefined: e.g. never settled), unstable (the
    run stopped: diverged) and failed (the variant did not run)."""
    failed = int((index.status == "failed").sum()) if "status" in index else 0
    rows = []
    keys = ["controller", "signal", "metric"]
    for (controller, signal, metric), group in metrics.groupby(keys, sort=False, observed=True):
        ran = group[group.status == "ok"].value.astype(float)
        ok = ran[np.isfinite(ran)]
        q25, median, q75 = (float(np.percentile(ok, q)) if len(ok) else np.nan for q in (25, 50, 75))
        rows.append({
            "controller": controller, "signal": signal, "metric": metric,
            "unit": group.unit.iloc[0] if "unit" in group and pd.notna(group.unit.iloc[0]) else "",
            "n": len(ok), "median": median, "q25": q25, "q75": q75, "iqr": q75 - q25,
            "min": float(ok.min()) if len(ok) else np.nan, "max": float(ok.max()) if len(ok) else np.nan,
            "undefined": int(ran.isna().sum()), "unstable": int((group.status != "ok").sum()), "failed": failed,
        })  # fmt: skip
    return pd.DataFrame(rows)


def varied(index: pd.DataFrame) -> list[str]:
    """The varied parameters: the sweep index's ``value:`` columns."""
    return [c for c in index.columns if c.startswith("value:")]


def described(values: pd.Series, shown: int = 12) -> str:
    """A varied parameter's values in words: their range (numbers) or the distinct values
    (text: the first ``shown`` of them, in order of appearance)."""
    present = values.dropna()
    if pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values):
        distinct = present.nunique()
        return f"{distinct} distinct values from {present.min():.4g} to {present.max():.4g}" if distinct else "no value"
    levels = list(present.astype(str).unique())
    more = f", and {len(levels) - shown} more" if len(levels) > shown else ""
    return f"{len(levels)} distinct values: " + ", ".join(levels[:shown]) + more


#: The metrics' columns held as categories: every grouping then factorizes small integer codes.
CATEGORIES = ("controller", "signal", "metric", "unit", "status")


def read_tables(directory: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The sweep's metrics (the columns the page reads; :data:`CATEGORIES` as categories) and
    index, in either form (:func:`~nlcx.pages.output_tables.read_output_table`). A Parquet
    dataset's text columns come as categories straight from their dictionaries: a million-variant
    sweep's tens of millions of rows never become Python strings."""
    path = table_path(directory, "metrics")
    if path is None or path.suffix != ".parquet":
        metrics = read_output_table(directory, "metrics")
        metrics = metrics.astype({column: "category" for column in CATEGORIES if column in metrics})
        return metrics, read_output_table(directory, "sweep")
    import pyarrow as pa
    import pyarrow.parquet as pq

    files = sorted(path.glob(PART_FILES)) if path.is_dir() else [path]
    metrics = pa.concat_tables([_coded(pq.read_table(f, columns=["variant", *CATEGORIES, "value"])) for f in files])
    index_path = table_path(directory, "sweep")
    assert index_path is not None
    index_files = sorted(index_path.glob(PART_FILES)) if index_path.is_dir() else [index_path]
    names = pq.read_schema(index_files[0]).names
    columns = [c for c in names if c in ("variant", "status") or c.startswith("value:")]
    try:
        index = pa.concat_tables([pq.read_table(f, columns=columns) for f in index_files]).to_pandas()
    except pa.ArrowInvalid:  # parts of different column types: read as the CSV would be
        index = read_output_table(directory, "sweep")[columns]
    return metrics.to_pandas(), index


def _coded(table: pa.Table) -> pa.Table:
    """A metrics part with its :data:`CATEGORIES` dictionary-encoded (int32 codes into strings),
    ``variant`` as int64 and ``value`` as float64: parts written apart then join as one table."""
    import pyarrow as pa

    category = pa.dictionary(pa.int32(), pa.string())
    columns = []
    for name, column in zip(table.column_names, table.columns, strict=True):
        if name in CATEGORIES:
            plain = column if pa.types.is_dictionary(column.type) else column.cast(pa.string()).dictionary_encode()
            columns.append(plain.cast(category))
        else:
            columns.append(column.cast(pa.int64() if name == "variant" else pa.float64()))
    return pa.table(columns, names=table.column_names)


def context(directory: Path) -> dict[str, Any]:
    """Everything the sweep page shows; writes summary.csv, profiles.csv and the charts' SVG files beside it."""
    metrics, index = read_tables(directory)
    table = summary(metrics, index)
    report.write_csv(directory / "summary.csv", table)
    files = directory / FILES
    colour = sweep_charts.controller_colours([str(c) for c in metrics.controller.unique()])
    distribution = sweep_charts.distribution_svg(table)
    report.write_text(files / "distributions.svg", str(distribution))
    ok = metrics[(metrics.status == "ok") & metrics.value.notna()]
    ok = ok.assign(value=ok.value.astype(float))
    params = varied(index)
    plots, tables = [], []
    for i, column in enumerate(params):
        profile, labels = sweep_charts.profiles(ok, index, column)
        chart = sweep_charts.profile_svg(profile, labels, colour)
        report.write_text(files / f"parameter_{i}.svg", str(chart))
        tables.append(profile)
        plots.append({
            "parameter": column.removeprefix("value:"),
            "described": described(index[column]),
            "file": f"{FILES}/parameter_{i}.svg",
            "chart": chart,
        })  # fmt: skip
    if tables:
        report.write_csv(directory / "profiles.csv", pd.concat(tables, ignore_index=True))
    config = (directory / "config.yaml").read_text(encoding="utf-8") if (directory / "config.yaml").is_file() else ""
    loaded = yaml.safe_load(config) if config else None
    raw = loaded if isinstance(loaded, dict) else {}
    return {
        "kind": "sweep",
        "title": f"nlcx sweep: {raw.get('name', directory.name)}",
        "caption": str(raw.get("title") or ""),
        "summary": table.to_dict("records"),
        "variants": len(index),
        "status": index.status.value_counts().to_dict() if "status" in index else {},
        "parameters": [c.removeprefix("value:") for c in params],
        "distribution": f"{FILES}/distributions.svg",
        "distribution_chart": distribution,
        "legend": charts.legend(colour.items()),
        "plots": plots,
        "config": config,
        "table_files": table_files(directory),
    }


def table_files(directory: Path) -> dict[str, str]:
    """The file name of each of the sweep's tables, in the form the directory holds it
    (e.g. ``{"metrics": "metrics.parquet", "sweep": "sweep.parquet"}``), for the page's links."""
    names = {stem: table_path(directory, stem) for stem in STEMS}
    return {stem: path.name for stem, path in names.items() if path is not None}

"""What the report of a sweep directory shows: the aggregates people otherwise script.

First the answer: how many variants each controller was unstable in (:func:`robustness`,
from :func:`stability`), and per metric the controllers side by side, each one's median and
interquartile range (:func:`side_by_side`). Then, per controller, signal and metric over the
variants: median, interquartile range, min, max,
and how many variants measured it, were unstable (the run stopped) or failed (the variant
did not run); ``summary.csv`` holds the same table. Charts (:mod:`nlcx.pages.sweep_charts`,
SVG drawn from aggregates, so their cost does not grow with the variants): each metric's
distribution per controller, and each metric against each varied parameter, its median and
interquartile range per bin of the parameter; ``profiles.csv`` holds the numbers they draw.
"""

from __future__ import annotations

from pathlib import Path
from typing import TypedDict

import numpy as np
import pandas as pd

from nlcx import report, safe_yaml
from nlcx.pages import charts, sweep_charts
from nlcx.pages.kinds import ReportPage
from nlcx.pages.output_tables import STEMS, part_files, read_output_table, table_path
from nlcx.pages.render import TEMPLATES

FILES = "report_files"


def summary(metrics: pd.DataFrame, index: pd.DataFrame) -> pd.DataFrame:
    """controller, signal, metric, unit, n (variants that measured it), median, q25, q75, iqr,
    min, max, undefined (ran, but the metric is undefined: e.g. never settled), unstable (the
    run stopped: diverged) and failed (the variant did not run); a row per (controller,
    signal, metric) in the order they first appear (categorical text columns read fastest)."""
    failed = int((index.status == "failed").sum()) if "status" in index else 0
    if metrics.empty or not {"controller", "signal", "metric", "value", "status"} <= set(metrics.columns):
        return pd.DataFrame(columns=SUMMARY_COLUMNS)  # no variant measured anything
    groups, trios = sweep_charts.first_seen([metrics.controller, metrics.signal, metrics.metric])
    value = metrics.value.to_numpy(dtype=float)
    ok_status = (metrics.status == "ok").to_numpy()
    units = metrics.unit if "unit" in metrics else None
    rows = []
    for g, (controller, signal, metric) in enumerate(trios):
        members = np.flatnonzero(groups == g)
        ran = value[members[ok_status[members]]]
        ok = ran[np.isfinite(ran)]
        q25, median, q75 = (float(v) for v in np.percentile(ok, [25, 50, 75])) if len(ok) else (np.nan,) * 3
        unit = units.iloc[members[0]] if units is not None else None
        rows.append({
            "controller": controller, "signal": signal, "metric": metric,
            "unit": unit if unit is not None and pd.notna(unit) else "",
            "n": len(ok), "median": median, "q25": q25, "q75": q75, "iqr": q75 - q25,
            "min": float(ok.min()) if len(ok) else np.nan, "max": float(ok.max()) if len(ok) else np.nan,
            "undefined": int(np.isnan(ran).sum()), "unstable": int((~ok_status[members]).sum()), "failed": failed,
        })  # fmt: skip
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


#: The columns of the summary table (summary.csv), in order.
SUMMARY_COLUMNS = ("controller", "signal", "metric", "unit", "n", "median", "q25", "q75", "iqr", "min", "max",
                   "undefined", "unstable", "failed")  # fmt: skip


#: The columns of the stability table (:func:`stability`), in order.
STABILITY_COLUMNS = ("ok", "unstable", "failed", "variants", "stable_share")


def stability(metrics: pd.DataFrame, index: pd.DataFrame) -> pd.DataFrame:
    """Per controller (the index, in the order the controllers first appear), how many of the
    variants its run was ``ok`` in, ``unstable`` in (the variant ran and this controller's run
    stopped: a row of it is not ok, or the metrics kept have no row of it) and ``failed`` in
    (the variant did not run: its status in the table sweep); ``variants``, their sum; and
    ``stable_share`` = ok / variants (NaN for no variant)."""
    variants = len(index)
    failed = int((index.status == "failed").sum()) if "status" in index else 0
    if metrics.empty or not {"controller", "variant", "status"} <= set(metrics.columns):
        return pd.DataFrame(columns=list(STABILITY_COLUMNS), index=pd.Index([], name="controller"))
    groups, labels = sweep_charts.first_seen([metrics.controller])
    not_ok = (metrics.status != "ok").to_numpy()
    variant = metrics.variant.to_numpy(dtype=np.int64)
    size = int(variant.max()) + 1 if variant.size else 0

    def variants_of(mask: np.ndarray) -> int:
        """How many distinct variants the rows of ``mask`` belong to (marks, not a sort)."""
        marks = np.zeros(size, dtype=bool)
        marks[variant[mask]] = True
        return int(marks.sum())

    rows = []
    for g, (controller,) in enumerate(labels):
        members = groups == g
        ok = variants_of(members) - variants_of(members & not_ok)
        rows.append({"controller": controller, "ok": ok, "unstable": variants - failed - ok, "failed": failed,
                     "variants": variants, "stable_share": ok / variants if variants else np.nan})  # fmt: skip
    return pd.DataFrame(rows).set_index("controller")[list(STABILITY_COLUMNS)]


def robustness(table: pd.DataFrame) -> str:
    """The stability table (:func:`stability`) in one line: ``unstable: conventional 4 of 20,
    proposed 14 of 20`` (and the failed variants, when any)."""
    if table.empty:
        return "unstable: no controller ran"
    line = "unstable: " + ", ".join(f"{c} {int(r.unstable)} of {int(r.variants)}" for c, r in table.iterrows())
    failed = int(table.failed.iloc[0])
    return line + (f"; failed (did not run): {failed} of {int(table.variants.iloc[0])}" if failed else "")


class SweepSummaryRow(TypedDict):
    """One (signal, metric) of :func:`side_by_side`: its statistics by controller."""

    signal: str
    metric: str
    unit: object
    #: controller -> median, q25, q75 and n.
    by: dict[str, dict[str, object]]


def side_by_side(table: pd.DataFrame) -> dict[str, object]:
    """The summary (:func:`summary`) with the controllers side by side: ``controllers`` in
    order, and ``rows``, one per (signal, metric) in order, each with its ``unit`` and, per
    controller, its ``median``, ``q25``, ``q75`` and ``n`` (None where it has none)."""
    controllers = [str(c) for c in dict.fromkeys(table.controller)] if len(table) else []
    rows: dict[tuple[str, str], SweepSummaryRow] = {}
    for r in table.to_dict("records"):
        key = (str(r["signal"]), str(r["metric"]))
        row = rows.setdefault(key, {"signal": key[0], "metric": key[1], "unit": r["unit"], "by": {}})
        row["by"][str(r["controller"])] = {k: r[k] for k in ("median", "q25", "q75", "n")}
    return {"controllers": controllers, "rows": list(rows.values())}


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

    files = part_files(path)
    if not {"variant", *CATEGORIES, "value"} <= set(pq.read_schema(files[0]).names):  # no variant measured
        return pd.DataFrame(columns=["variant", *CATEGORIES, "value"]), read_output_table(directory, "sweep")
    index_path = table_path(directory, "sweep")
    assert index_path is not None
    index_files = part_files(index_path)
    names = pq.read_schema(index_files[0]).names
    columns = [c for c in names if c in ("variant", "status") or c.startswith("value:")]
    try:
        index = pa.concat_tables([pq.read_table(f, columns=columns) for f in index_files]).to_pandas()
    except pa.ArrowInvalid:  # parts of different column types: read as the CSV would be
        index = read_output_table(directory, "sweep")[columns]
    return _metrics_frame(files), index


def _metrics_frame(files: list[Path]) -> pd.DataFrame:
    """The metrics parts' columns the page reads, filled part by part into arrays of the whole
    table's length: the numbers as they are, each text column as codes into the categories seen
    so far. Memory: the frame and one part, never a second copy of the table."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    total = sum(pq.ParquetFile(f).metadata.num_rows for f in files)
    variant, value = np.empty(total, dtype=np.int64), np.empty(total)
    codes = {name: np.empty(total, dtype=np.int16) for name in CATEGORIES}  # a few texts each
    categories: dict[str, dict[str, int]] = {name: {} for name in CATEGORIES}
    start = 0
    for f in files:
        table = pq.read_table(f, columns=["variant", *CATEGORIES, "value"])
        stop = start + table.num_rows
        variant[start:stop] = table.column("variant").to_numpy()
        value[start:stop] = table.column("value").to_numpy(zero_copy_only=False)
        for name in CATEGORIES:
            column = table.column(name)
            encoded = (column if pa.types.is_dictionary(column.type) else column.dictionary_encode()).combine_chunks()
            seen = categories[name]
            lookup = np.array([seen.setdefault(text, len(seen)) for text in encoded.dictionary.to_pylist()] + [-1])
            indices = encoded.indices.fill_null(-1).to_numpy(zero_copy_only=False)
            if len(seen) >= 2**15:
                raise ValueError(f"the sweep's metrics hold more than {2**15 - 1} distinct {name} texts")
            codes[name][start:stop] = lookup[indices]
        start = stop
    frame = {name: pd.Categorical.from_codes(codes.pop(name), pd.Index(list(categories[name]))) for name in CATEGORIES}
    return pd.DataFrame({"variant": variant, **frame, "value": value}, copy=False)


def context(directory: Path) -> dict[str, object]:
    """Everything the sweep page shows; writes summary.csv, profiles.csv and the charts' SVG files beside it.
    ``usable`` is False when no variant measured any metric (every one failed or was unstable):
    the page then says so first."""
    metrics, index = read_tables(directory)
    table = summary(metrics, index)
    stable = stability(metrics, index)
    report.write_csv(directory / "summary.csv", table)
    files = directory / FILES
    usable = bool(table["n"].sum()) if len(table) else False
    colour = sweep_charts.controller_colours([str(c) for c in table.controller.unique()])
    distribution = sweep_charts.distribution_svg(table)
    report.write_text(files / "distributions.svg", str(distribution))
    params = varied(index) if usable else []
    stride = sweep_charts.profile_stride(len(index))
    sampled = metrics if stride == 1 else metrics[metrics.variant.to_numpy() % stride == 0]
    plots, tables = [], []
    for i, column in enumerate(params):
        profile, labels = sweep_charts.profiles(sampled, index, column)
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
    loaded = safe_yaml.load_text(config, str(directory / "config.yaml")) if config else None
    raw = loaded if isinstance(loaded, dict) else {}
    return {
        "kind": "sweep",
        "title": f"nlcx sweep: {raw.get('name', directory.name)}",
        "caption": str(raw.get("title") or ""),
        "summary": table.to_dict("records"),
        "robustness": robustness(stable),
        "stability": {str(c): r for c, r in stable.to_dict("index").items()},
        "side_by_side": side_by_side(table),
        "usable": usable,
        "variants": len(index),
        "profile_stride": stride,
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


def page_context(directory: Path, configs: Path | None, repo: Path | None) -> dict[str, object]:
    """The page's :func:`context` (it reads only the directory's own files)."""
    return context(directory)


#: The report page of a sweep directory (built in: :data:`nlcx.pages.kinds.BUILT_IN`).
PAGE = ReportPage(TEMPLATES, page_context)

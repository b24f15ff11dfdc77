"""What the report of a sweep directory shows: the aggregates people otherwise script.

Per controller, signal and metric over the variants: median, interquartile range, min, max,
and how many variants measured it, were unstable (the run stopped) or failed (the variant
did not run); ``summary.csv`` holds the same table. Plots: each metric's distribution per
controller, and each metric against each varied parameter (with the values it took).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from nlcx import drawing, report

FILES = "report_files"


def summary(metrics: pd.DataFrame, index: pd.DataFrame) -> pd.DataFrame:
    """controller, signal, metric, unit, n (variants that measured it), median, q25, q75, iqr,
    min, max, undefined (ran, but the metric is undefined: e.g. never settled), unstable (the
    run stopped: diverged) and failed (the variant did not run)."""
    failed = int((index.status == "failed").sum()) if "status" in index else 0
    rows = []
    for (controller, signal, metric), group in metrics.groupby(["controller", "signal", "metric"], sort=False):
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
    levels = list(dict.fromkeys(present.astype(str)))
    more = f", and {len(levels) - shown} more" if len(levels) > shown else ""
    return f"{len(levels)} distinct values: " + ", ".join(levels[:shown]) + more


def _grid(n_panels: int) -> tuple[Any, np.ndarray]:
    """A figure of ``n_panels`` small axes, four a row, spaced by fixed margins (tight_layout
    measures every label of every axes, slow for a sweep's ~50 panels); drawn without pyplot
    (:func:`nlcx.drawing.new_figure`)."""
    cols = 4
    rows = max(1, -(-n_panels // cols))
    fig, axes = drawing.new_figure(rows, cols, (3.2 * cols, 2.4 * rows))
    fig.subplots_adjust(left=0.05, right=0.98, bottom=0.6 / (2.4 * rows), top=1 - 0.6 / (2.4 * rows),
                        wspace=0.35, hspace=0.55)  # fmt: skip
    for ax in list(axes.flat)[n_panels:]:
        ax.axis("off")
    return fig, axes


def distribution_figure(metrics: pd.DataFrame, path: Path) -> None:
    """One box plot per (signal, metric), a box per controller."""
    ok = metrics[metrics.status == "ok"]
    keys = list(dict.fromkeys(zip(ok.signal, ok.metric, strict=True)))
    controllers = list(dict.fromkeys(ok.controller))
    fig, axes = _grid(len(keys))
    for ax, (signal, metric) in zip(axes.flat, keys, strict=False):
        data = [
            ok[(ok.signal == signal) & (ok.metric == metric) & (ok.controller == c)].value.astype(float)
            for c in controllers
        ]
        ax.boxplot([d[np.isfinite(d)] for d in data], tick_labels=controllers)
        ax.set_title(f"{signal} {metric}", fontsize=9)
        ax.tick_params(labelsize=7)
    drawing.write_figure(path, fig)


def parameter_figure(metrics: pd.DataFrame, index: pd.DataFrame, column: str, path: Path) -> None:
    """Every (signal, metric) against one varied parameter, a colour per controller."""
    ok = metrics[metrics.status == "ok"].merge(index[["variant", column]], on="variant")
    keys = list(dict.fromkeys(zip(ok.signal, ok.metric, strict=True)))
    numeric = pd.api.types.is_numeric_dtype(index[column])
    fig, axes = _grid(len(keys))
    levels = {v: i for i, v in enumerate(dict.fromkeys(index[column].astype(str)))}
    for ax, (signal, metric) in zip(axes.flat, keys, strict=False):
        for k, (controller, rows_c) in enumerate(
            ok[(ok.signal == signal) & (ok.metric == metric)].groupby("controller")
        ):
            x = rows_c[column] if numeric else rows_c[column].astype(str).map(levels) + (k - 0.5) * 0.2
            ax.scatter(x, rows_c.value.astype(float), s=4, alpha=0.5, label=controller)
        if not numeric:
            ax.set_xticks(list(levels.values()), list(levels), fontsize=7)
        ax.set_title(f"{signal} {metric}", fontsize=9)
        ax.tick_params(labelsize=7)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle(column.removeprefix("value:"), fontsize=10)
    drawing.write_figure(path, fig)


def context(directory: Path) -> dict[str, Any]:
    """Everything the sweep page shows; writes summary.csv and the plots beside it."""
    metrics = pd.read_csv(directory / "metrics.csv")
    index = pd.read_csv(directory / "sweep.csv")
    table = summary(metrics, index)
    report.write_csv(directory / "summary.csv", table)
    files = directory / FILES
    distribution_figure(metrics, files / "distributions.png")
    params = varied(index)
    plots = []
    for i, column in enumerate(params):
        parameter_figure(metrics, index, column, files / f"parameter_{i}.png")
        plots.append({
            "parameter": column.removeprefix("value:"),
            "described": described(index[column]),
            "file": f"{FILES}/parameter_{i}.png",
        })  # fmt: skip
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
        "distribution": f"{FILES}/distributions.png",
        "plots": plots,
        "config": config,
    }

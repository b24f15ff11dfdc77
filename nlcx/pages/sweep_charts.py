"""A sweep page's charts, drawn as SVG from aggregates: their cost does not grow with the points.

Two kinds of panel, one per (signal, metric), laid out four a row in one SVG:

- :func:`distribution_svg`: per controller, a box from the first to the third quartile, the
  median as a tick and a whisker from min to max, read from the sweep's summary table;
- :func:`profile_svg`: one varied parameter against the metric, per controller the median of
  each bin of the parameter (a line) and its interquartile band, from :func:`profiles`.

Every text inside (titles, labels, tooltips) is escaped; the result is
:class:`markupsafe.Markup`, printed as it is by a page and written as a ``.svg`` file for the
Markdown report.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import pandas as pd
from markupsafe import Markup, escape

#: Bins of a numeric parameter with more distinct values than this; fewer are shown each.
BINS = 20
#: The profiles of a sweep with more variants than this are drawn from every k-th variant, so
#: that at most this many are read (:func:`profile_stride`); the summary always holds them all.
PROFILE_VARIANTS = 100_000


def profile_stride(n_variants: int) -> int:
    """k such that every k-th variant (index a multiple of k) gives at most :data:`PROFILE_VARIANTS`."""
    return max(1, -(-n_variants // PROFILE_VARIANTS))


COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")
WIDTH, HEIGHT, COLUMNS = 240, 150, 4
LEFT, RIGHT, TOP, BOTTOM = 60, 8, 20, 26


def _num(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else "–"


def _scale(lo: float, hi: float, a: float, b: float) -> Callable[[float], float]:
    """The affine map of [lo, hi] onto [a, b] (the middle of [a, b] when lo == hi)."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return lambda _v: (a + b) / 2
    return lambda v: a + (v - lo) / (hi - lo) * (b - a)


def _grid(panels: Sequence[str], label: str) -> Markup:
    """``panels`` (each an SVG ``<g>`` drawn in a WIDTH × HEIGHT box) in one SVG, COLUMNS a row."""
    rows = max(1, -(-len(panels) // COLUMNS))
    width, height = COLUMNS * WIDTH, rows * HEIGHT
    parts = [
        f'<svg class="sweep-chart" role="img" aria-label="{escape(label)}" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" xmlns="http://www.w3.org/2000/svg" font-family="sans-serif">'
    ]
    for i, panel in enumerate(panels):
        parts.append(f'<g transform="translate({(i % COLUMNS) * WIDTH},{(i // COLUMNS) * HEIGHT})">{panel}</g>')
    parts.append("</svg>")
    return Markup("".join(parts))


def _frame(title: str, x_labels: tuple[str, str], y_labels: tuple[str, str]) -> str:
    """A panel's title, plot box and the end labels of its axes."""
    x0, x1, y0, y1 = LEFT, WIDTH - RIGHT, TOP, HEIGHT - BOTTOM
    return (
        f'<text x="{WIDTH / 2}" y="13" font-size="10" text-anchor="middle">{escape(title)}</text>'
        f'<rect x="{x0}" y="{y0}" width="{x1 - x0}" height="{y1 - y0}" fill="none" stroke="#ccc"/>'
        f'<text x="{x0}" y="{y1 + 11}" font-size="8">{escape(x_labels[0])}</text>'
        f'<text x="{x1}" y="{y1 + 11}" font-size="8" text-anchor="end">{escape(x_labels[1])}</text>'
        f'<text x="{x0 - 3}" y="{y1}" font-size="8" text-anchor="end">{escape(y_labels[0])}</text>'
        f'<text x="{x0 - 3}" y="{y0 + 7}" font-size="8" text-anchor="end">{escape(y_labels[1])}</text>'
    )


def _box_panel(title: str, rows: pd.DataFrame, colour: dict[str, str]) -> str:
    """Quartile boxes, median ticks and min–max whiskers, one row per controller."""
    lo, hi = float(np.nanmin(rows["min"])), float(np.nanmax(rows["max"]))
    x = _scale(lo, hi, LEFT + 4, WIDTH - RIGHT - 4)
    step = (HEIGHT - BOTTOM - TOP) / max(len(rows), 1)
    parts = [_frame(title, (_num(lo), _num(hi)), ("", ""))]
    for k, r in enumerate(rows.to_dict("records")):
        if not r["n"]:
            continue
        y = TOP + (k + 0.5) * step
        name = str(r["controller"])
        low, mid, high, least, most = (float(r[q]) for q in ("q25", "median", "q75", "min", "max"))
        tip = escape(f"{name}: median {_num(mid)}, IQR {_num(low)} to {_num(high)}, "
                     f"min {_num(least)}, max {_num(most)}, n {r['n']}")  # fmt: skip
        c = colour[name]
        parts.append(
            f"<g><title>{tip}</title>"
            f'<line x1="{x(least):.1f}" x2="{x(most):.1f}" y1="{y:.1f}" y2="{y:.1f}" stroke="{c}"/>'
            f'<rect x="{x(low):.1f}" y="{y - step / 4:.1f}" width="{max(x(high) - x(low), 1):.1f}" '
            f'height="{step / 2:.1f}" fill="{c}" fill-opacity="0.35" stroke="{c}"/>'
            f'<line x1="{x(mid):.1f}" x2="{x(mid):.1f}" y1="{y - step / 4:.1f}" y2="{y + step / 4:.1f}" '
            f'stroke="{c}" stroke-width="2"/>'
            f'<text x="{LEFT - 3}" y="{y + 3:.1f}" font-size="8" text-anchor="end">{escape(name)}</text></g>'
        )
    return "".join(parts)


def controller_colours(controllers: Sequence[str]) -> dict[str, str]:
    """One colour per controller, in the order given."""
    return {c: COLOURS[i % len(COLOURS)] for i, c in enumerate(controllers)}


def distribution_svg(summary: pd.DataFrame) -> Markup:
    """Per (signal, metric) of the summary table, a box per controller (its quartiles, median,
    min and max over the variants that measured it)."""
    colour = controller_colours([str(c) for c in summary.controller.unique()])
    panels = [
        _box_panel(f"{signal} {metric}", rows, colour)
        for (signal, metric), rows in summary.groupby(["signal", "metric"], sort=False, observed=True)
        if rows["n"].sum()
    ]
    return _grid(panels, "distributions per controller")


def bins_of(values: pd.Series) -> tuple[pd.Series, list[str]]:
    """Each variant's bin of a varied parameter, and the bins' labels in order.

    A numeric parameter with at most :data:`BINS` distinct values keeps each value; one with
    more is cut into :data:`BINS` bins of equal width over its range, labelled by their
    centres. Any other parameter keeps each value, in order of first appearance.
    """
    present = values.dropna()
    numeric = pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values)
    if numeric and present.nunique() > BINS:
        edges = np.linspace(float(present.min()), float(present.max()), BINS + 1)
        codes = np.clip(np.searchsorted(edges, values.to_numpy(dtype=float), side="right") - 1, 0, BINS - 1)
        centres = (edges[:-1] + edges[1:]) / 2
        return pd.Series(codes, index=values.index).where(values.notna()), [f"{c:.4g}" for c in centres]
    levels = sorted(present.unique()) if numeric else list(present.astype(str).unique())
    keys = values if numeric else values.astype(str)
    position = {v: i for i, v in enumerate(levels)}
    return keys.map(position), [f"{v:.4g}" if numeric else str(v) for v in levels]


def first_rows(codes: np.ndarray, present: np.ndarray, window: int = 4096) -> np.ndarray:
    """The first row of each code of ``present`` (each must occur in ``codes``): windows of
    doubling length scanned from the top until every code has been seen. In a metrics table every
    (controller, signal, metric) shows among the first variants' rows, so this reads a few
    thousand rows, where a scan per code reads the whole table for each."""
    first = dict.fromkeys(present.tolist(), -1)
    missing = set(first)
    start = 0
    while missing:
        if start >= codes.size:
            raise ValueError(f"codes {sorted(missing)} do not occur")
        part = codes[start : start + window]
        for code in np.flatnonzero(np.bincount(part)).tolist():
            if code in missing:
                first[code] = start + int(np.argmax(part == code))
                missing.discard(code)
        start, window = start + window, 2 * window
    return np.array(list(first.values()), dtype=np.int64)


def first_seen(
    columns: Sequence[pd.Series], rows: np.ndarray | None = None
) -> tuple[np.ndarray, list[tuple[str, ...]]]:
    """Each row's group, the groups being the distinct tuples of ``columns`` (as categories), in the
    order they first appear (among ``rows``, a mask, when given; other rows get -1); and the
    groups' tuples. The tuples are combined into one small integer code per row, counted with
    ``bincount``, and each code's first row found by :func:`first_rows`: a few passes over the rows, no sort."""
    columns = [c if isinstance(c.dtype, pd.CategoricalDtype) else c.astype("category") for c in columns]
    sizes = [len(column.cat.categories) + 1 for column in columns]
    combined = np.zeros(len(columns[0]), dtype=np.int32 if np.prod(sizes, dtype=float) < 2**31 else np.int64)
    for column, size in zip(columns, sizes, strict=True):  # in place: one array the size of the rows
        combined *= size
        combined += column.cat.codes.to_numpy()
        combined += 1
    if rows is not None:
        combined[~rows] = 0  # no tuple has code 0 (every code above is shifted by one)
    counts = np.bincount(combined) if combined.size else np.zeros(1, dtype=np.int64)
    present = np.flatnonzero(counts[1:]) + 1
    first = first_rows(combined, present)
    by_appearance = np.argsort(first, kind="stable")
    rank = np.full(counts.size, -1, dtype=combined.dtype)
    rank[present[by_appearance]] = np.arange(present.size)
    labels = [tuple(str(column.iloc[first[k]]) for column in columns) for k in by_appearance]
    return rank[combined], labels


def profiles(metrics: pd.DataFrame, index: pd.DataFrame, column: str) -> tuple[pd.DataFrame, list[str]]:
    """The metrics against one varied parameter: per (signal, metric, controller) and bin of
    the parameter (:func:`bins_of`), the number of variants that measured the metric, its
    median and its quartiles (pandas' linear interpolation), in the order metrics.csv lists
    them (among the rows of runs that finished, with a value); and the bins' labels. The
    groups are integer codes, so the cost is a few passes over the rows. ``metrics`` may hold
    the rows of some variants only (:func:`profile_stride`); the bins span every variant of ``index``."""
    codes, labels = bins_of(index[column])
    variants = index.variant.to_numpy(dtype=np.int64)
    bin_of_variant = np.full(int(variants.max()) + 1 if variants.size else 0, np.nan)
    bin_of_variant[variants] = codes.to_numpy(dtype=float)
    ok = (metrics.status == "ok").to_numpy() & metrics.value.notna().to_numpy()
    row_bins = np.full(len(metrics), np.nan)
    row_bins[ok] = bin_of_variant[metrics.variant.to_numpy(dtype=np.int64)[ok]]
    ok &= ~np.isnan(row_bins)
    groups, trios = first_seen([metrics.signal, metrics.metric, metrics.controller], ok)
    n_bins = max(len(labels), 1)
    key = groups[ok] * n_bins + row_bins[ok].astype(np.int64)
    grouped = pd.Series(metrics.value.to_numpy(dtype=float)[ok]).groupby(key, sort=True)
    table = grouped.quantile([0.25, 0.5, 0.75]).unstack()
    table.columns = ["q25", "median", "q75"]
    table["n"] = grouped.size()
    keys = table.index.to_numpy(dtype=np.int64)
    trio = [trios[k] for k in keys // n_bins]
    table = table.reset_index(drop=True)
    table.insert(0, "bin", keys % n_bins)
    for position, name in enumerate(("signal", "metric", "controller")):
        table.insert(position, name, [t[position] for t in trio])
    table["at"] = [labels[b] for b in table["bin"]]
    table.insert(0, "parameter", column.removeprefix("value:"))
    return table, labels


def _profile_panel(title: str, rows: pd.DataFrame, n_bins: int, labels: list[str], colour: dict[str, str]) -> str:
    """Per controller, the median by bin (a line with points) and its interquartile band."""
    lo, hi = float(rows["q25"].min()), float(rows["q75"].max())
    x = _scale(0, max(n_bins - 1, 0), LEFT + 6, WIDTH - RIGHT - 6)
    y = _scale(lo, hi, HEIGHT - BOTTOM - 3, TOP + 3)
    parts = [_frame(title, (labels[0], labels[-1]), (_num(lo), _num(hi)))]
    for key, line in rows.groupby("controller", sort=False, observed=True):
        controller = str(key)
        c = colour[controller]
        bins, q25, median, q75, n = (line[k].tolist() for k in ("bin", "q25", "median", "q75", "n"))
        upper = " ".join(f"{x(b):.1f},{y(v):.1f}" for b, v in zip(bins, q75, strict=True))
        lower = " ".join(f"{x(b):.1f},{y(v):.1f}" for b, v in zip(bins[::-1], q25[::-1], strict=True))
        middle = " ".join(f"{x(b):.1f},{y(v):.1f}" for b, v in zip(bins, median, strict=True))
        parts.append(f'<polygon points="{upper} {lower}" fill="{c}" fill-opacity="0.18" stroke="none"/>')
        parts.append(f'<polyline points="{middle}" fill="none" stroke="{c}" stroke-width="1.5"/>')
        for b, low, mid, high, count in zip(bins, q25, median, q75, n, strict=True):
            tip = escape(f"{controller} at {labels[b]}: median {_num(mid)}, IQR {_num(low)} to {_num(high)}, n {count}")
            parts.append(f'<circle cx="{x(b):.1f}" cy="{y(mid):.1f}" r="2" fill="{c}"><title>{tip}</title></circle>')
    return "".join(parts)


def profile_svg(table: pd.DataFrame, labels: list[str], colour: dict[str, str]) -> Markup:
    """One panel per (signal, metric) of a parameter's :func:`profiles` table."""
    panels = [
        _profile_panel(f"{signal} {metric}", rows, len(labels), labels, colour)
        for (signal, metric), rows in table.groupby(["signal", "metric"], sort=False, observed=True)
    ]
    return _grid(panels, f"metrics against {table.parameter.iloc[0]}" if len(table) else "no metric")

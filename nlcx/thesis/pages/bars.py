"""The bars of a reproduction's tables, drawn straight into the page as SVG (no image files, no
script): per (signal, metric) of a thesis table, four bars: thesis conventional, thesis
proposed, nlcx conventional, nlcx proposed, each group scaled to its own largest value (metrics
of different units side by side); the exact values are in each bar's tooltip. The charts are
:class:`markupsafe.Markup` (a page prints them as they are), so every text inside them
(labels, tooltips) is escaped here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from markupsafe import Markup, escape

from nlcx.thesis.pages.tables import Cell

SERIES = (
    ("thesis", "conventional", "#9ecae1"),
    ("thesis", "proposed", "#3182bd"),
    ("nlcx", "conventional", "#fdae6b"),
    ("nlcx", "proposed", "#e6550d"),
)
BAR, GAP, HEIGHT, TOP, BOTTOM = 9, 14, 90, 8, 34


@dataclass
class Group:
    """One (signal, metric) of a table: its four values, by (source, controller)."""

    label: str
    values: dict[tuple[str, str], float]


def groups_of(cells: list[Cell]) -> list[Group]:
    """(signal, metric) groups of a table with conventional and proposed cells."""
    groups: dict[str, Group] = {}
    for cell in cells:
        if cell.controller not in ("conventional", "proposed"):
            continue
        key = cell.label.replace(f" · {cell.controller}", "").replace(f"{cell.controller} · ", "")
        group = groups.setdefault(key, Group(key, {}))
        group.values[("thesis", cell.controller)] = cell.thesis
        group.values[("nlcx", cell.controller)] = cell.nlcx
    return [g for g in groups.values() if len(g.values) == 4]


def grouped_bars(cells: list[Cell]) -> Markup:
    """The SVG of a table's grouped bars (empty when it has no conventional/proposed pairs)."""
    groups = groups_of(cells)
    if not groups:
        return Markup("")
    width = len(groups) * (4 * BAR + GAP) + GAP
    parts = [
        f'<svg class="bars" role="img" width="{width}" height="{TOP + HEIGHT + BOTTOM}" '
        f'viewBox="0 0 {width} {TOP + HEIGHT + BOTTOM}" xmlns="http://www.w3.org/2000/svg">'
    ]
    for i, group in enumerate(groups):
        x0 = GAP + i * (4 * BAR + GAP)
        finite = [abs(v) for v in group.values.values() if math.isfinite(v)]
        scale = max(finite) if finite and max(finite) > 0 else 1.0
        for k, (source, controller, colour) in enumerate(SERIES):
            value = group.values[(source, controller)]
            h = HEIGHT * abs(value) / scale if math.isfinite(value) else 0.0
            tip = escape(f"{group.label}: {source} {controller} = {value:.4g}")
            parts.append(
                f'<rect x="{x0 + k * BAR}" y="{TOP + HEIGHT - h:.1f}" width="{BAR - 1}" height="{h:.1f}" '
                f'fill="{colour}"><title>{tip}</title></rect>'
            )
        parts.append(
            f'<text x="{x0 + 2 * BAR}" y="{TOP + HEIGHT + 12}" font-size="9" text-anchor="middle">'
            f"{escape(group.label)}</text>"
        )
    parts.append("</svg>")
    return Markup("".join(parts))


def legend_keys() -> list[tuple[str, str]]:
    """The four series as (label, colour), for :func:`nlcx.pages.charts.legend`."""
    return [(f"{source} {controller}", colour) for source, controller, colour in SERIES]

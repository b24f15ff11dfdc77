"""What the report of a reproduction directory (``nlcx reproduce``) shows.

Summary (the thesis, the run's provenance and profile, verdicts), every table beside the
thesis with Δ and tolerance, a gallery of every thesis figure, the claims and the
documented deviations. Numbers come from the directory's own files: tables/*.csv,
claims.csv, figures/, manifest.json.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from nlcx.pages import charts
from nlcx.pages.tables import TableComparison, compare
from nlcx.pages.tolerances import Tolerances
from nlcx.pages.tolerances import load as load_tolerances
from nlcx.thesis import catalog

CITATION = (
    '"Conventional and Intelligent Control of Nonlinear Systems", PhD thesis, Thapar University '
    "(the text, tables and figure captions nlcx reproduces)"
)
VERDICTS = ("yes", "partly", "no")
#: The documents the deviations section links to (relative to the repository root).
DOCS = {
    "docs/assumptions.md": "every unprinted parameter and the value nlcx chose",
    "docs/errata.md": "where the printed equations disagree with their derivation",
    "docs/calibration.md": "the conventional gains fitted to the printed tables",
    "docs/fidelity.md": "which loop did the thesis simulate (the identification study)",
    "docs/metrics.md": "how every metric is measured",
}


@dataclass
class GalleryItem:
    figure: str
    chapter: int
    #: The experiment's plant (x, xy, xz, xyz pendulum or the CSTR): the gallery's groups.
    plant: str
    caption: str
    file: str
    generated: bool


def gallery(directory: Path, root: Path) -> list[GalleryItem]:
    """Every result figure of the thesis with its caption and whether nlcx drew it."""
    return [
        GalleryItem(
            spec.figure,
            spec.chapter,
            spec.plant,
            spec.title,
            f"figures/{spec.filename}",
            (directory / "figures" / spec.filename).is_file(),
        )
        for spec in catalog.figures(root)
    ]


def claims(directory: Path) -> list[dict[str, Any]]:
    path = directory / "claims.csv"
    return pd.read_csv(path).fillna("").to_dict("records") if path.is_file() else []


def docs_links(directory: Path, repo: Path | None) -> list[dict[str, str]]:
    """The deviation documents, linked relative to the page (only those that exist)."""
    if repo is None:
        return []
    return [
        {"name": name, "what": what, "href": Path(os.path.relpath(repo / name, directory)).as_posix()}
        for name, what in DOCS.items()
        if (repo / name).is_file()
    ]


def sections(path: Path) -> list[dict[str, str]]:
    """The ``## `` sections of a Markdown document: heading and first paragraph (plain text)."""
    if not path.is_file():
        return []
    out: list[dict[str, str]] = []
    for block in path.read_text(encoding="utf-8").split("\n## ")[1:]:
        heading, _, body = block.partition("\n")
        paragraphs = [p.strip() for p in body.split("\n\n") if p.strip() and not p.lstrip().startswith(("|", "```"))]
        first = " ".join(paragraphs[0].split()) if paragraphs else ""
        out.append({"heading": heading.strip(), "summary": first})
    return out


def deviations(repo: Path | None) -> dict[str, list[dict[str, str]]]:
    """What the deviations section lists: every documented assumption (unprinted parameters
    and choices), the errata of the printed equations, the calibration, and what was difficult
    (the identification study's conclusion)."""
    if repo is None:
        return {"assumptions": [], "errata": [], "calibration": [], "difficult": []}
    fidelity = sections(repo / "docs" / "fidelity.md")
    return {
        "assumptions": sections(repo / "docs" / "assumptions.md"),
        "errata": sections(repo / "docs" / "errata.md"),
        "calibration": [s for s in sections(repo / "docs" / "calibration.md") if s["heading"].startswith("What")],
        "difficult": [s for s in fidelity if s["heading"].startswith(("Conclusion", "What the studies say"))],
    }


def context(directory: Path, configs: Path, repo: Path | None) -> dict[str, Any]:
    """Everything the reproduction page shows."""
    tolerances: Tolerances = load_tolerances(configs / "tolerances.yaml")
    tables: list[TableComparison] = compare(directory, tolerances)
    claim_rows = claims(directory)
    figures = gallery(directory, configs)
    manifest = json.loads((directory / "manifest.json").read_text()) if (directory / "manifest.json").is_file() else {}
    return {
        "kind": "reproduction",
        "title": "nlcx reproduction of the thesis",
        "citation": CITATION,
        "manifest": manifest,
        "tolerances": tolerances,
        "tables": tables,
        "bars": {t.name: charts.grouped_bars(t.cells) for t in tables},
        "legend": charts.legend(),
        "table_verdicts": {v: sum(t.verdict == v for t in tables) for v in ("reproduced", "partly", "not", "n/a")},
        "claims": claim_rows,
        "claim_counts": {v: sum(c["reproduced"] == v for c in claim_rows) for v in VERDICTS},
        "figures": figures,
        "chapters": sorted({f.chapter for f in figures}),
        "figure_counts": {
            "generated": sum(f.generated for f in figures),
            "missing": sum(not f.generated for f in figures),
        },
        "docs": docs_links(directory, repo),
        "deviations": deviations(repo),
    }


def summary_frame(ctx: dict[str, Any]) -> pd.DataFrame:
    """report_summary.csv: one row per table (cells, within tolerance, verdict), for `nlcx diff`."""
    return pd.DataFrame(
        [
            {"table": t.name, "cells": len(t.cells), "within_tolerance": t.within, "verdict": t.verdict}
            for t in ctx["tables"]
        ]
    )

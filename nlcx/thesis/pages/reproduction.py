"""What the report of a reproduction directory (``nlcx reproduce``) shows.

Summary (the thesis, the run's provenance and profile, verdicts), every table beside the
thesis with Δ and tolerance, a gallery of every thesis figure, the claims and the
documented deviations. Numbers come from the directory's own files: tables/*.csv,
claims.csv, figures/, manifest.json.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict, cast

import pandas as pd
from markdown_it import MarkdownIt
from markupsafe import Markup

from nlcx import report
from nlcx.pages import charts
from nlcx.pages.kinds import ReportPage
from nlcx.thesis import catalog
from nlcx.thesis.pages import bars
from nlcx.thesis.pages.tables import TableComparison, compare
from nlcx.thesis.pages.tolerances import ReproductionTolerances
from nlcx.thesis.pages.tolerances import load as load_tolerances

if TYPE_CHECKING:
    from markdown_it.token import Token

    from nlcx.thesis.catalog import FigureSpec

CITATION = (
    '"Conventional and Intelligent Control of Nonlinear Systems", PhD thesis, Thapar University '
    "(the text, tables and figure captions nlcx reproduces)"
)
VERDICTS = ("yes", "partly", "no")
#: The documents the deviations section links to (relative to the repository root).
DOCS = {
    "docs/replication.md": "the replication report: what replicates, chapter by chapter, and what does not",
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


def asked(spec: FigureSpec, manifest: Mapping[str, object]) -> bool:
    """Whether the reproduction asked for a figure: its key among ``--only``'s and its chapter
    among ``--chapter``'s, as the manifest records them (every figure where it records none)."""
    # lists, as ``nlcx reproduce`` records them
    only = cast("list[str]", manifest.get("only") or [])
    chapters = cast("list[int]", manifest.get("chapters") or [])
    return (not only or spec.key in only) and (not chapters or spec.chapter in chapters)


def gallery(directory: Path, root: Path, manifest: Mapping[str, object] | None = None) -> list[GalleryItem]:
    """Every result figure of the thesis that the reproduction asked for (:func:`asked`, from
    its ``manifest``), with its caption and whether nlcx drew it."""
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
        if asked(spec, manifest or {})
    ]


def claims(directory: Path) -> list[dict[str, object]]:
    path = directory / "claims.csv"
    return pd.read_csv(path).fillna("").to_dict("records") if path.is_file() else []


class DocumentSection(TypedDict):
    """A ``## `` section of a Markdown document (:func:`sections`)."""

    heading: str
    #: The document, relative to the page.
    href: str
    html: Markup


def docs_links(directory: Path, repo: Path | None) -> list[dict[str, str]]:
    """The deviation documents, linked relative to the page (only those that exist)."""
    if repo is None:
        return []
    return [
        {"name": name, "what": what, "href": Path(os.path.relpath(repo / name, directory)).as_posix()}
        for name, what in DOCS.items()
        if (repo / name).is_file()
    ]


def _relative_links(tokens: Sequence[Token], document: Path, directory: Path) -> None:
    """Point the relative links of a document's tokens (e.g. ``metrics.md``) from the page
    in ``directory`` to the file beside the document; anchors and absolute links unchanged."""
    for token in tokens:
        if token.children:
            _relative_links(token.children, document, directory)
        href = token.attrGet("href") if token.type == "link_open" else None
        if href and isinstance(href, str) and not href.startswith("#") and ":" not in href:  # a link's is text
            target, _, fragment = href.partition("#")
            relative = Path(os.path.relpath(document.parent / target, directory)).as_posix()
            token.attrSet("href", relative + (f"#{fragment}" if fragment else ""))


def sections(path: Path, directory: Path) -> list[DocumentSection]:
    """The ``## `` sections of a Markdown document: heading, a link to the document and the
    body as HTML (markdown-it-py, CommonMark with tables; raw HTML escaped and javascript:,
    vbscript:, file: and data: links left as text, so the page prints it as it is), its
    relative links pointing from the page in ``directory`` to the document's neighbours."""
    if not path.is_file():
        return []
    md = MarkdownIt("commonmark", {"html": False}).enable("table")
    href = Path(os.path.relpath(path, directory)).as_posix()
    out: list[DocumentSection] = []
    for block in path.read_text(encoding="utf-8").split("\n## ")[1:]:
        heading, _, body = block.partition("\n")
        tokens = md.parse(body)
        _relative_links(tokens, path, directory)
        html = Markup(md.renderer.render(tokens, md.options, {}))
        out.append({"heading": heading.strip(), "href": href, "html": html})
    return out


def deviations(directory: Path, repo: Path | None) -> dict[str, list[DocumentSection]]:
    """What the deviations section shows: every documented assumption (unprinted parameters
    and choices), the errata of the printed equations, the calibration's findings, and what
    was difficult (the identification study's findings and conclusion)."""
    if repo is None:
        return {"assumptions": [], "errata": [], "calibration": [], "difficult": []}
    docs = repo / "docs"
    fidelity = sections(docs / "fidelity.md", directory)
    return {
        "assumptions": sections(docs / "assumptions.md", directory),
        "errata": sections(docs / "errata.md", directory),
        "calibration": [s for s in sections(docs / "calibration.md", directory) if s["heading"].startswith("What")],
        "difficult": [s for s in fidelity if s["heading"].startswith(("Conclusion", "What the studies say"))],
    }


def context(directory: Path, configs: Path, repo: Path | None) -> ReproductionPage:
    """Everything the reproduction page shows."""
    tolerances: ReproductionTolerances = load_tolerances(configs / "tolerances.yaml")
    tables: list[TableComparison] = compare(directory, tolerances)
    claim_rows = claims(directory)
    manifest = json.loads((directory / "manifest.json").read_text()) if (directory / "manifest.json").is_file() else {}
    figures = gallery(directory, configs, manifest)
    return {
        "kind": "reproduction",
        "title": "nlcx reproduction of the thesis",
        "citation": CITATION,
        "manifest": manifest,
        "tolerances": tolerances,
        "tables": tables,
        "bars": {t.name: bars.grouped_bars(t.cells) for t in tables},
        "legend": charts.legend(bars.legend_keys()),
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
        "deviations": deviations(directory, repo),
    }


class ReproductionPage(TypedDict):
    """Everything the reproduction page shows (:func:`context`)."""

    kind: str
    title: str
    citation: str
    #: The directory's manifest.json (empty without one).
    manifest: dict[str, object]
    tolerances: ReproductionTolerances
    tables: list[TableComparison]
    bars: dict[str, Markup]
    legend: Markup
    table_verdicts: dict[str, int]
    claims: list[dict[str, object]]
    claim_counts: dict[str, int]
    figures: list[GalleryItem]
    chapters: list[int]
    figure_counts: dict[str, int]
    docs: list[dict[str, str]]
    deviations: dict[str, list[DocumentSection]]


def summary_frame(ctx: ReproductionPage) -> pd.DataFrame:
    """report_summary.csv: one row per table (cells, within tolerance, verdict), for `nlcx diff`."""
    return pd.DataFrame(
        [
            {"table": t.name, "cells": len(t.cells), "within_tolerance": t.within, "verdict": t.verdict}
            for t in ctx["tables"]
        ]
    )


def page_context(directory: Path, configs: Path | None, repo: Path | None) -> ReproductionPage:
    """The page's :func:`context`, the thesis's configs (tolerances.yaml, the figures' catalogue)
    read from ``configs`` (default: configs/thesis of the checkout, else of the working
    directory); report_summary.csv written beside it (:func:`summary_frame`)."""
    ctx = context(directory, configs or (repo or Path.cwd()) / "configs" / "thesis", repo)
    report.write_csv(directory / "report_summary.csv", summary_frame(ctx))
    return ctx


#: The report page of a reproduction directory (the entry point ``reproduction`` of nlcx.pages).
PAGE = ReportPage(Path(__file__).parent / "templates", page_context)

"""The record of what Wang (2011) states: each statement carries a page of the paper, a value and a short
paraphrase; the pages read and not read cover the paper; no profile claims the paper's loop without its gains."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path
from typing import Any

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
RECORD = files("nlcx.thesis") / "data" / "sources" / "wang2011.yaml"  # package data, as nlcx.thesis.catalog reads it
PROFILES = ROOT / "configs" / "thesis" / "profiles"
PAGE = ROOT / "docs" / "sources.md"
#: Simulation Modelling Practice and Theory 19 (2011) 440-449.
FIRST_PAGE, LAST_PAGE = 440, 449
REQUIRED = {"what", "value", "unit", "page", "section", "quote_short"}
ALLOWED = REQUIRED | {"note"}


@pytest.fixture(scope="module")
def record() -> dict[str, Any]:
    return yaml.safe_load(RECORD.read_text(encoding="utf-8"))


def test_the_citation_gives_the_journal_pages(record: dict[str, Any]) -> None:
    first, last = (int(page) for page in record["citation"]["pages"].split("-"))
    assert (first, last) == (FIRST_PAGE, LAST_PAGE)
    assert record["citation"]["volume"] == 19 and record["citation"]["year"] == 2011


def test_every_statement_has_a_page_of_the_paper_and_a_value(record: dict[str, Any]) -> None:
    read = {entry["page"] for entry in record["pages_read"]}
    assert record["statements"]
    for statement in record["statements"]:
        assert REQUIRED <= set(statement) <= ALLOWED, statement
        page = statement["page"]
        assert isinstance(page, int) and FIRST_PAGE <= page <= LAST_PAGE, statement
        assert page in read, f"{statement['what']}: page {page} is not among the pages read"
        assert statement["value"] not in (None, ""), statement
        assert statement["what"] and statement["section"] and statement["unit"]
        assert len(statement["quote_short"].split()) <= 20, statement["quote_short"]


def test_the_pages_read_and_not_read_cover_the_paper_once(record: dict[str, Any]) -> None:
    read = [entry["page"] for entry in record["pages_read"]]
    assert sorted(read + record["pages_not_read"]) == list(range(FIRST_PAGE, LAST_PAGE + 1))


def test_the_docs_page_shows_every_statement_with_its_page(record: dict[str, Any]) -> None:
    rows = [line for line in PAGE.read_text(encoding="utf-8").splitlines() if line.startswith("| ")]
    for statement in record["statements"]:
        row = [r for r in rows if r.startswith(f"| {statement['what']} |")]
        assert row, f"docs/sources.md has no row for {statement['what']!r}"
        assert f"| {statement['page']} |" in row[0]


def test_no_profile_claims_the_papers_loop_without_its_printed_gains(record: dict[str, Any]) -> None:
    gains = [s for s in record["statements"] if "gain" in s["what"].lower()]
    assert not gains
    assert any("PID gains" in item for item in record["not_read"])
    assert not (PROFILES / "wang2011.yaml").exists()

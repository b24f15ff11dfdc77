"""One source for each thesis number, and a package structure that keeps it so.

The AGS gain ranges (Tables 2.2, 3.1, 3.6, 4.1) and rates k (section 2.3) live in
nlcx/thesis/data/ags_*.csv; scripts/make_thesis_configs.py writes configs/thesis/ags/ from
them, and ``nlcx reproduce`` sets the configs run beside them. These tests fail when a
config is edited by hand, when a run departs from a printed number, when nlcx/thesis grows
an import cycle or a function longer than 80 lines.
"""

from __future__ import annotations

import ast
import copy
import dataclasses
import importlib.util
import math
import re
import sys
from graphlib import CycleError, TopologicalSorter
from pathlib import Path
from types import ModuleType
from typing import Any

import pandas as pd
import pytest

from nlcx import config
from nlcx.thesis import ags, catalog, claims
from nlcx.thesis.tables import ags_table

ROOT = Path(__file__).resolve().parent.parent
THESIS = ROOT / "configs" / "thesis"
PACKAGE = ROOT / "nlcx" / "thesis"
#: What a claim's source may cite: numbered tables and figures (and sections beside them),
#: numbered sections, a pendulum's theorem, the conclusion.
CITATION = re.compile(
    r"(Table|Table of Fig\.|Fig\.|Figs\.) \d+\.\d+([-, ]+\d+\.\d+)*( and section \d+(\.\d+)+)?"
    r"|\d+(\.\d+)+(, \d+(\.\d+)+)*"
    r"|Theorem and V̇ figure of the (x|xy|xz|xyz) pendulum|Conclusion of the chapter"
)


def _load_generator() -> ModuleType:
    name = "make_thesis_configs"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
        assert spec and spec.loader
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    return sys.modules[name]


def _thesis_modules() -> dict[str, Path]:
    """Every module of nlcx.thesis and its subpackages (nlcx.thesis.claims), by dotted name."""
    modules = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    modules.pop("nlcx.thesis")
    return modules


def _thesis_imports(name: str, path: Path) -> set[str]:
    """The nlcx.thesis modules one module imports, at the top or inside functions."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from .x import y, from . import y
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            found |= {base} | {f"{base}.{alias.name}" for alias in node.names}
    return (found & set(_thesis_modules())) - {name}


def _departures(table: pd.DataFrame) -> pd.DataFrame:
    """Rows of an AGS table where the config run differs from the printed number."""
    printed = table.dropna(subset=["thesis"])
    return printed[printed.nlcx.astype(float) != printed.thesis.astype(float)]


def _response_configs() -> list[tuple[str, Path]]:
    """(AGS table of the pendulum, config) of every stabilisation and tracking figure of chapters 2-4."""
    table_of = {plant: table for table, (kind, plant) in catalog.PARAMETER_TABLES.items() if kind == "ags"}
    return [
        (table_of[f.plant], f.configs[0])
        for f in catalog.figures(THESIS)
        if f.kind == "response" and f.plant in table_of
    ]


def test_no_import_cycle_among_thesis_modules() -> None:
    graph = {name: _thesis_imports(name, path) for name, path in _thesis_modules().items()}
    # the walk sees imports, those of a subpackage's modules too
    assert graph["nlcx.thesis.claims"] >= {"nlcx.thesis.cstr", "nlcx.thesis.claims.table"}
    assert graph["nlcx.thesis.claims.checks"] >= {"nlcx.thesis.tables"}
    try:
        tuple(TopologicalSorter(graph).static_order())
    except CycleError as exc:
        pytest.fail(f"import cycle in nlcx/thesis: {exc.args[1]}")


def test_no_thesis_function_longer_than_80_lines() -> None:
    long = [
        f"{path.name}:{node.name} {node.end_lineno - node.lineno + 1}"
        for path in PACKAGE.rglob("*.py")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.end_lineno - node.lineno + 1 > 80
    ]
    assert not long


def test_ags_blocks_are_generated_from_the_thesis_data() -> None:
    """configs/thesis/ags/*.yaml are exactly what the generator writes from data/ags_*.csv."""
    generated = _load_generator().ags_configs()
    assert set(generated) == set((THESIS / "ags").glob("*.yaml"))
    for path, text in generated.items():
        assert path.read_text(encoding="utf-8") == text, f"{path.name}: rerun scripts/make_thesis_configs.py"


def test_figure_configs_are_generated_from_the_figure_list() -> None:
    generated = _load_generator().figure_configs()
    assert set(generated) == {p for c in (2, 3, 4) for p in (THESIS / f"ch{c}").glob("fig_*.yaml")}
    for path, text in generated.items():
        assert path.read_text(encoding="utf-8") == text, f"{path.name}: rerun scripts/make_thesis_configs.py"


@pytest.mark.parametrize("table, path", _response_configs(), ids=lambda v: getattr(v, "stem", v))
def test_configs_run_the_printed_ranges_and_rates(table: str, path: Path) -> None:
    """Every stabilisation and tracking config runs the ranges and rates the reproduction
    reports as printed; only the z loop's rates are not printed, and they are the position
    loops' (docs/assumptions.md A11)."""
    resolved = config.load(path).resolved()
    reported = ags_table(table, [resolved])
    assert len(reported) == 9 * len(resolved["controllers"]["proposed"]["loops"])
    assert (reported.loop != "").all()
    assert _departures(reported).empty, _departures(reported).to_string()
    unprinted = reported[reported.thesis.isna()]
    assert set(unprinted.signal) <= {"z"} and set(unprinted.parameter) <= {"rate_kp", "rate_ki", "rate_kd"}
    for row in unprinted.itertuples():
        assert row.nlcx == ags.printed_rate("x", row.parameter.removeprefix("rate_"))


def test_ags_table_reports_a_config_that_departs_from_the_thesis() -> None:
    """The check above can fail: a hand-tuned range or rate shows as a departure."""
    resolved = config.load(THESIS / "ch2" / "fig_2_04.yaml").resolved()
    tuned: dict[str, Any] = copy.deepcopy(resolved)
    tuned["controllers"]["proposed"]["loops"]["theta"]["schedule"]["kp"]["max"] = 35
    tuned["controllers"]["proposed"]["loops"]["x"]["schedule"]["rate"]["kd"] = 0.2
    departures = _departures(ags_table("2.2", [tuned]))
    assert list(zip(departures.signal, departures.parameter, strict=True)) == [("theta", "kp_max"), ("x", "rate_kd")]
    assert _departures(ags_table("2.2", [resolved])).empty


def test_z_rate_is_not_printed_and_runs_as_a_position_loop() -> None:
    """Section 2.3 prints rates for AGS PID 1 and 2 only (A11)."""
    for gain in ags.GAINS:
        assert math.isnan(ags.printed_rate("z", gain))
        assert ags.run_rates("z")[gain] == ags.printed_rate("x", gain) == ags.printed_rate("y", gain)
        assert ags.run_rates("phi")[gain] == ags.printed_rate("theta", gain)


def _citation_problems(claim: claims.Claim) -> list[str]:
    """What keeps a claim from citing the thesis: an empty or unnumbered source, a template
    left unfilled, no section number of its chapter, no checks."""
    problems = []
    if not CITATION.fullmatch(claim.source):
        problems.append(f"source {claim.source!r} names no numbered table, figure, theorem or the conclusion")
    if "{" in claim.source + claim.text:
        problems.append("an unfilled template")
    if not all(re.fullmatch(rf"{claim.chapter}(\.\d+)+", s) for s in claim.section.split(", ")):
        problems.append(f"section {claim.section!r} is no section of chapter {claim.chapter}")
    if not claim.checks:
        problems.append("no checks")
    return problems


@pytest.mark.parametrize("plant", ["x", "xy", "xz", "xyz", "cstr"])
def test_claims_have_unique_ids_and_cite_numbered_sources(plant: str) -> None:
    declared = claims.claims_for(plant)
    assert declared and len({c.id for c in declared}) == len(declared)
    for claim in declared:
        assert not _citation_problems(claim), claim.id


@pytest.mark.parametrize("source", ["", " ", "Table", "see above", "Fig. {0}", "5.", "section 5.4"])
def test_a_claim_citing_no_numbered_source_is_caught(source: str) -> None:
    """The check above fails on a planted claim with an empty or unnumbered source."""
    planted = dataclasses.replace(claims.claims_for("x")[0], source=source)
    assert _citation_problems(planted)[0].startswith(f"source {source!r} names no numbered")

"""The consistency study: which printed columns any loop of the families examined gives."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from nlcx.cli import app
from nlcx.thesis import hypotheses
from nlcx.thesis.consistency.analysis import group_hits, hits, twins, unreachable_sets
from nlcx.thesis.consistency.loops import ColumnRuns, used_box
from nlcx.thesis.consistency.spec import (
    STUDY_FAMILIES,
    also_printed,
    column_cells,
    load_spec,
    printed_interval,
    with_intervals,
)
from nlcx.thesis.fitting import DEFINITIONS, FLOORS, measure_cells
from nlcx.thesis.pages.tolerances import ReproductionTolerances

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "configs" / "thesis"
runner = CliRunner()
SPEC = yaml.safe_load((ROOT / "configs" / "identify" / "consistency.yaml").read_text())
BOX = SPEC["free"]
#: The relative tolerance of M_p, t_r and t_s in configs/thesis/tolerances.yaml.
REL = {m: yaml.safe_load((THESIS / "tolerances.yaml").read_text())["cells"]["by_metric"][m]["rel"] for m in FLOORS}


def test_a_column_is_one_controllers_printed_cells_and_its_repeats_are_found() -> None:
    cells = column_cells("2.3").set_index("cell").value.to_dict()
    assert cells == {"x.Mp": 0.5, "theta.Mp": 0.3, "x.tr": 2.07, "x.ts": 7.26, "theta.ts": 5.58}
    proposed = column_cells("3.7", "proposed").set_index("cell")
    assert proposed.value.to_dict() == {"x.Mp": 0.31, "z.Mp": 0.0, "theta.Mp": 0.14, "x.tr": 2.6, "z.tr": 1.87,
                                        "x.ts": 7.84, "z.ts": 2.95, "theta.ts": 5.82}  # fmt: skip
    assert proposed.text["z.Mp"] == "0" and proposed.text["x.tr"] == "2.6"  # as printed, not as a float
    assert also_printed("2.3") == ["2.5"]
    assert also_printed("3.7") == ["3.9"]
    assert also_printed("4.2") == []  # 4.4 prints x.ts 8.32, not 8.33
    assert also_printed("2.3", "proposed") == []  # 2.5's proposed column is the error AGS's


def test_a_column_frees_only_the_gains_its_experiment_reads() -> None:
    x = used_box(ColumnRuns(THESIS, "2.3").runs, "2.3", BOX)
    xz = used_box(ColumnRuns(THESIS, "3.7").runs, "3.7", BOX)
    assert sorted(x) == sorted(k for k in BOX if not k.startswith("vars.conventional.z."))
    assert sorted(xz) == sorted(BOX)
    assert used_box(ColumnRuns(THESIS, "3.7", "proposed").runs, "3.7", BOX) == {}  # the printed AGS gains


def test_a_printed_cell_covers_its_rounding_widened_by_its_relative_tolerance() -> None:
    """By hand: v printed with d decimals covers v -/+ (0.5 10^-d + rel |v|)."""
    assert printed_interval("0.05", 0.2) == pytest.approx((0.035, 0.065))  # 0.005 + 0.01
    assert printed_interval("5.79", 0.2) == pytest.approx((4.627, 6.953))  # 0.005 + 1.158
    assert printed_interval("12", 0.2) == pytest.approx((9.1, 14.9))  # 0.5 + 2.4
    assert printed_interval("0", 0.2) == pytest.approx((-0.5, 0.5))  # no decimals; rel |0| = 0
    assert printed_interval("0", 0.2, zero_decimals=2) == pytest.approx((-0.005, 0.005))
    assert printed_interval("5.79", 0.0) == pytest.approx((5.785, 5.795))  # the rounding alone
    assert printed_interval("0.40", 0.0) == pytest.approx((0.395, 0.405))  # a printed trailing zero counts
    assert printed_interval("0.4", 0.0) == pytest.approx((0.35, 0.45))


def test_each_cell_is_widened_by_its_metrics_relative_tolerance() -> None:
    rules = ReproductionTolerances.model_validate({
        "table": {"reproduced": 0.9, "partly": 0.5},
        "cells": {"default": {"rel": 0.5, "abs": 9.0, "reason": "-"},
                  "by_metric": {"Mp": {"rel": 0.1, "abs": 9.0, "reason": "-"}, "tr": {"rel": 0.0, "reason": "-"}}},
    })  # fmt: skip
    cells = with_intervals(column_cells("2.3"), rules, None).set_index("cell")
    expected = {  # printed -/+ (rounding + rel |printed|); ts has no entry: the default's rel; abs never counts
        "x.Mp": (0.5 - 0.1, 0.5 + 0.1), "theta.Mp": (0.3 - 0.08, 0.3 + 0.08), "x.tr": (2.065, 2.075),
        "x.ts": (7.26 - 3.635, 7.26 + 3.635), "theta.ts": (5.58 - 2.795, 5.58 + 2.795),
    }  # fmt: skip
    for cell, (lower, upper) in expected.items():
        assert (cells.lower[cell], cells.upper[cell]) == pytest.approx((lower, upper)), cell
    declared = with_intervals(column_cells("2.3"), ReproductionTolerances.model_validate(yaml.safe_load(
        (THESIS / "tolerances.yaml").read_text())), None).set_index("cell")  # fmt: skip
    assert declared.upper["x.tr"] == pytest.approx(2.07 + 0.005 + REL["tr"] * 2.07)


def test_a_loop_hits_the_cells_whose_printed_interval_holds_its_value() -> None:
    cells = pd.DataFrame({"cell": ["x.Mp", "x.tr", "z.Mp"], "lower": [0.45, 2.065, -0.005],
                          "upper": [0.55, 2.075, 0.005]})  # fmt: skip
    nan = np.nan
    loops = pd.DataFrame({
        "hypothesis": ["a", "b", "c", "d", "e"],
        "z.Mp": [0.0, 0.004, -0.006, 0.0051, 0.005],
        "x.Mp": [0.5, 0.549, 0.551, nan, 0.45],
        "x.tr": [2.07, 2.0751, 2.0649, 2.066, 2.075],
    })  # fmt: skip
    assert hits(loops, cells).tolist() == [
        [True, True, True],
        [True, False, True],
        [False, False, False],
        [False, True, False],  # an unmeasured value hits nothing
        [True, True, True],  # the interval's ends belong to it
    ]


def test_a_hypothesis_is_examined_where_each_of_its_options_changes_the_column() -> None:
    """The magnitude ordering reads the AGS's negative-gain ranges: it changes the proposed
    x loop, not the conventional one, so on the conventional column it and its combinations go."""
    family = hypotheses.family(["ordering", "saturation"], 2)
    conventional = [h.name for h in ColumnRuns(THESIS, "2.3").examined(family)]
    proposed = [h.name for h in ColumnRuns(THESIS, "2.3", "proposed").examined(family)]
    assert proposed == [h.name for h in family] and len(family) == 8
    assert conventional == ["literal", "saturation=plain", "saturation=clamping", "saturation=back_calculation"]


def test_a_column_runs_only_the_conventional_controller_and_measures_its_cells() -> None:
    column = ColumnRuns(THESIS, "2.3")
    gains = {k: (lo + hi) / 2 for k, (lo, hi) in BOX.items() if not k.startswith("vars.conventional.z.")}
    experiment = column.runs.experiment("2.3", hypotheses.Hypothesis(), gains)
    assert [c.label for c in experiment.controllers] == ["conventional"]
    ours = column.measure(hypotheses.Hypothesis(), [gains, gains])
    assert ours.shape == (2, 5) and np.array_equal(ours[0], ours[1], equal_nan=True)


def test_runs_measured_again_under_another_definition_equal_runs_simulated_under_it() -> None:
    """engine.remeasure: the same numbers as simulating again with the definition set."""
    column = ColumnRuns(THESIS, "2.3")
    gains = [{k: lo + f * (hi - lo) for k, (lo, hi) in BOX.items() if not k.startswith("vars.conventional.z.")}
             for f in (0.3, 0.5, 0.7)]  # fmt: skip
    each = column.measure_each(hypotheses.Hypothesis(), gains, list(DEFINITIONS))
    for definition, metrics in DEFINITIONS.items():
        direct = measure_cells(column.runs, hypotheses.Hypothesis(), gains, column.cells, metrics).T
        assert np.array_equal(each[definition], direct, equal_nan=True), definition
    assert not np.array_equal(each[next(iter(DEFINITIONS))], each[list(DEFINITIONS)[-1]], equal_nan=True)


def test_minimal_unreachable_sets() -> None:
    """Loops hit {0, 1}, {1, 2}, {0, 2}: every pair is reached, the triple is not; cell 3 is
    never hit, so it is a minimal set on its own and no set containing it is listed."""
    hit = np.array([[1, 1, 0, 0], [0, 1, 1, 0], [1, 0, 1, 0]], dtype=bool)
    assert unreachable_sets(hit, 3) == [(3,), (0, 1, 2)]
    assert unreachable_sets(hit, 2) == [(3,)]
    assert unreachable_sets(np.ones((1, 3), dtype=bool), 3) == []


def test_mirror_twins_count_as_one_cell_hit_when_both_are() -> None:
    cells = column_cells("3.2")
    labels = [" = ".join(cells.cell.iloc[m] for m in g) for g in twins(cells)]
    assert sorted(labels) == sorted(["x.Mp = y.Mp", "theta.Mp = phi.Mp", "x.tr = y.tr", "x.ts = y.ts",
                                     "theta.ts = phi.ts"])  # fmt: skip
    hit = np.array([[True, False, True], [True, True, True]])
    miss = np.array([[0.0, 0.3, 0.05], [0.01, 0.02, np.nan]])
    merged_hit, merged_miss = group_hits(hit, miss, [[0, 1], [2]])
    assert merged_hit.tolist() == [[False, True], [True, True]]
    assert merged_miss.tolist() == [[0.3, 0.05], [0.02, np.inf]]


def test_the_study_end_to_end_its_counts_recomputed_from_the_loops(tmp_path: Path) -> None:
    spec = {
        "name": "tiny",
        "kind": "consistency",
        "tables": ["2.3"],
        "controllers": ["conventional", "proposed"],
        "families": ["saturation"],
        "max_options": 1,
        "alone": ["lag"],
        "free": {k: v for k, v in BOX.items() if not k.startswith("vars.conventional.z.")},
        "warm_start": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 1},
        "optimiser": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 1},
        "cloud": {"n": 6, "seed": 3},
        "definitions": [next(iter(DEFINITIONS))],
    }
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    result = runner.invoke(app, ["identify", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    columns = pd.read_csv(out / "columns.csv", dtype={"table": str}).set_index("controller")
    cells = pd.read_csv(out / "cells.csv", dtype={"table": str, "text": str})
    loops = {c: _loops(out, f"2_3_{c}") for c in ("conventional", "proposed")}
    hyps = ["literal", "lag=first_order", "saturation=plain", "saturation=clamping", "saturation=back_calculation"]
    assert sorted(set(loops["conventional"].hypothesis)) == sorted(hyps)  # lag alone, never with a saturation
    fits = loops["conventional"][loops["conventional"].source == "fit"]
    assert columns.loops["conventional"] == len(loops["conventional"]) == len(fits) + 6 and len(fits) == 5 * 4
    proposed = loops["proposed"]
    assert columns.loops["proposed"] == len(proposed)
    assert (proposed[proposed.source == "fit"].hypothesis == "literal").sum() == 1  # nothing free: one loop
    assert (proposed[proposed.source == "random"].hypothesis == "literal").sum() <= 1
    freed = {h: sorted(json.loads(v)) for h, v in zip(proposed.hypothesis, proposed["values"], strict=True)}
    assert freed == {"literal": [], "lag=first_order": ["tau"], **{h: ["F_max"] for h in hyps[2:]}}  # no gains
    for row in cells.itertuples():
        loop = loops[row.controller]
        assert float(row.text) == row.printed
        half = 0.5 * 10.0 ** -len(row.text.partition(".")[2]) + REL[row.cell.split(".")[1]] * abs(row.printed)
        assert (row.lower, row.upper) == pytest.approx((row.printed - half, row.printed + half))
        inside = (loop[row.cell] >= row.lower) & (loop[row.cell] <= row.upper)
        assert row.loops_hitting == int(inside.sum())
    assert columns.best_fit_loss["conventional"] == min(
        yaml.safe_load((out / "fits" / "2_3_conventional" / f"{h}.json").read_text())["loss"] for h in hyps
    )
    assert set(columns.families) == {"lag saturation"}
    subsets = pd.read_csv(out / "subsets.csv", dtype={"table": str})
    assert len(subsets) > 0 and set(subsets.families) == {"lag saturation"}
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["families"], summary["max_options"], summary["alone"]) == (["saturation"], 1, ["lag"])
    assert [(c["controller"], c["families"], c["hypotheses"]) for c in summary["columns"]] == [
        ("conventional", ["lag", "saturation"], 5), ("proposed", ["lag", "saturation"], 5)
    ]  # fmt: skip
    again = runner.invoke(app, ["identify", str(path), "--out", str(out)])
    assert again.exit_code == 0 and "[1/" not in again.output  # resumed: nothing refitted


def _loops(out: Path, column: str) -> pd.DataFrame:
    """Every loop a column's fits and cloud evaluated, read from the study's files."""
    fits = [pd.read_csv(p) for p in sorted((out / "fits" / column).glob("*.loops.csv"))]
    return pd.concat([*fits, pd.read_csv(next((out / "loops" / column).glob("random_*.csv")))], ignore_index=True)


def test_a_bad_spec_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"name": "bad", "kind": "consistency", "tables": ["9.9"], "free": BOX}))
    result = runner.invoke(app, ["identify", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1, result.output
    assert "9.9" in result.output


@pytest.mark.parametrize(
    ("change", "named"),
    [({"families": ["lag"], "alone": ["lag"]}, "lag"), ({"families": ["ordering"]}, "ordering")],
)
def test_a_family_named_twice_or_outside_the_study_is_one_line(
    tmp_path: Path, change: dict[str, list[str]], named: str
) -> None:
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"name": "bad", "kind": "consistency", "tables": ["2.3"], "free": BOX, **change}))
    result = runner.invoke(app, ["identify", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1, result.output
    assert named in result.output


def test_the_study_examines_both_columns_and_the_scenario_families_alone() -> None:
    spec = load_spec(ROOT / "configs" / "identify" / "consistency.yaml")
    assert spec.controllers == ["conventional", "proposed"]
    assert set(spec.families) | set(spec.alone) <= set(STUDY_FAMILIES) and spec.alone
    family = spec.family()
    combined = hypotheses.family(spec.families, spec.max_options)
    assert family[: len(combined)] == combined  # the loop families' combinations as before
    assert all(len(h.options) == 1 for h in family[len(combined) :])  # then each scenario value alone
    assert {h.options[0][0] for h in family[len(combined) :]} == set(spec.alone)


def test_the_z_loop_and_the_disturbance_are_examined_only_where_the_experiment_has_them() -> None:
    family = hypotheses.family(["z_loop", "disturbance_phase"], 1)
    assert [h.name for h in ColumnRuns(THESIS, "2.3").examined(family)] == ["literal"]  # x, nominal
    assert [h.name for h in ColumnRuns(THESIS, "3.8", "proposed").examined(family)] == [h.name for h in family]
    assert len(family) == 1 + 3 + 3

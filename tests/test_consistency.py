"""The consistency study: which printed conventional columns any loop of the family gives."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from typer.testing import CliRunner

from nlcx.cli import app
from nlcx.thesis import hypotheses
from nlcx.thesis.consistency import (
    ColumnRuns,
    also_printed,
    column_cells,
    group_hits,
    twins,
    unreachable_sets,
    used_box,
)
from nlcx.thesis.identify import DEFINITIONS, FLOORS, measure_cells

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "configs" / "thesis"
runner = CliRunner()
BOX = yaml.safe_load((ROOT / "configs" / "identify" / "consistency.yaml").read_text())["free"]


def test_a_column_is_the_printed_conventional_cells_and_its_repeats_are_found() -> None:
    cells = column_cells("2.3").set_index("cell").value.to_dict()
    assert cells == {"x.Mp": 0.5, "theta.Mp": 0.3, "x.tr": 2.07, "x.ts": 7.26, "theta.ts": 5.58}
    assert also_printed("2.3") == ["2.5"]
    assert also_printed("3.7") == ["3.9"]
    assert also_printed("4.2") == []  # 4.4 prints x.ts 8.32, not 8.33


def test_a_column_frees_only_the_gains_its_experiment_reads() -> None:
    x = used_box(ColumnRuns(THESIS, "2.3").runs, "2.3", BOX)
    xz = used_box(ColumnRuns(THESIS, "3.7").runs, "3.7", BOX)
    assert sorted(x) == sorted(k for k in BOX if not k.startswith("vars.conventional.z."))
    assert sorted(xz) == sorted(BOX)


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
        "families": ["saturation"],
        "max_options": 1,
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
    columns = pd.read_csv(out / "columns.csv", dtype={"table": str})
    cells = pd.read_csv(out / "cells.csv", dtype={"table": str})
    loops = pd.concat([pd.read_csv(p) for p in sorted((out / "fits" / "2_3").glob("*.loops.csv"))])
    loops = pd.concat([loops, pd.read_csv(next((out / "loops" / "2_3").glob("random_*.csv")))])
    assert columns.loops.iloc[0] == len(loops) == 4 + 3 * 4 + 6  # literal fit, three saturations, the cloud
    assert len(cells) > 0 and set(cells.table) == {"2.3"}
    for row in cells.itertuples():
        scale = max(abs(row.printed), FLOORS[row.cell.split(".")[1]])
        assert row.loops_hitting == int(np.sum(np.abs(loops[row.cell] - row.printed) <= 0.1 * scale))
    assert columns.best_fit_loss.iloc[0] == min(
        yaml.safe_load((out / "fits" / "2_3" / f"{h}.json").read_text())["loss"]
        for h in ("literal", "saturation=plain", "saturation=clamping", "saturation=back_calculation")
    )
    again = runner.invoke(app, ["identify", str(path), "--out", str(out)])
    assert again.exit_code == 0 and "[1/" not in again.output  # resumed: nothing refitted


def test_a_bad_spec_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"name": "bad", "kind": "consistency", "tables": ["9.9"], "free": BOX}))
    result = runner.invoke(app, ["identify", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1, result.output
    assert "9.9" in result.output

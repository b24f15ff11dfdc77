"""The targeted consistency search, the final round's loop options and hypotheses by name."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from nlcx.cli import app
from nlcx.thesis import hypotheses, profiles
from nlcx.thesis.consistency.loops import ColumnRuns
from nlcx.thesis.consistency.spec import column_cells, load_spec, with_intervals
from nlcx.thesis.consistency.targeted import SetJudge, load_targeted
from nlcx.thesis.fitting import FLOORS, TableRuns, spec_provenance
from nlcx.thesis.pages import tolerances

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "configs" / "thesis"
runner = CliRunner()
BOX = yaml.safe_load((ROOT / "configs" / "identify" / "consistency.yaml").read_text())["free"]
GAINS = {k: (lo + hi) / 2 for k, (lo, hi) in BOX.items()}
R1 = "theta_settling=absolute+z_loop=no_feedforward_printed+integrator_limit=position"


def test_a_hypothesis_is_parsed_by_name_in_the_catalogues_order_and_combined() -> None:
    parsed = hypotheses.parse("integrator_limit=position+theta_settling=absolute+z_loop=no_feedforward_printed")
    assert parsed.name == R1  # the catalogue's order, whatever the order written
    assert hypotheses.parse("literal") == hypotheses.Hypothesis()
    assert hypotheses.parse(R1).name == R1
    both = hypotheses.combine(parsed, hypotheses.parse("integrator_limit=all+derivative=measurement"))
    assert (
        both.name == "derivative=measurement+theta_settling=absolute+z_loop=no_feedforward_printed+integrator_limit=all"
    )
    for bad in ("nonsense=1", "derivative=sideways", "derivative=measurement+derivative=filtered"):
        with pytest.raises(ValueError, match="is not one option of a family"):
            hypotheses.parse(bad)


def _controllers(table: str, hyp: str, **values: float) -> dict:
    runs = TableRuns(THESIS, [table])
    return runs.experiment(table, hypotheses.parse(hyp), {**GAINS, **values}).raw["controllers"]


def test_own_gains_scale_the_conventional_angle_and_position_loops_of_the_pendulums_with_z_only() -> None:
    factors = {f"c_{g}_{k}": f for (g, k), f in zip(
        [(g, k) for g in ("angle", "position") for k in ("kp", "ki", "kd")], (0.5, 2.0, 3.0, 0.25, 4.0, 1.5),
        strict=True)}  # fmt: skip
    shared, own = _controllers("3.7", "literal"), _controllers("3.7", "conventional_gains=own_with_z", **factors)
    for loop, group in (("theta", "angle"), ("x", "position")):
        for gain in ("kp", "ki", "kd"):
            expected = shared["conventional"]["loops"][loop]["schedule"][gain] * factors[f"c_{group}_{gain}"]
            assert own["conventional"]["loops"][loop]["schedule"][gain] == pytest.approx(expected, rel=1e-15)
    assert own["conventional"]["loops"]["z"] == shared["conventional"]["loops"]["z"]
    assert own["proposed"] == shared["proposed"]  # the AGS ranges are printed
    x_only = _controllers("2.3", "conventional_gains=own_with_z", **factors)
    assert x_only == _controllers("2.3", "literal")  # the x pendulum keeps the shared gains


def test_the_z_schedule_options_exchange_its_printed_ranges_and_free_its_rate() -> None:
    printed = _controllers("3.7", "literal")["proposed"]["loops"]
    swapped = _controllers("3.7", "z_schedule=swapped_rate_free", k_z=0.7)["proposed"]["loops"]
    for gain in ("kp", "ki", "kd"):
        assert swapped["z"]["schedule"][gain] == {"min": printed["z"]["schedule"][gain]["max"],
                                                  "max": printed["z"]["schedule"][gain]["min"]}  # fmt: skip
    assert swapped["z"]["schedule"]["rate"] == {"kp": 0.7, "ki": 0.7, "kd": 0.7}
    assert (swapped["theta"], swapped["x"]) == (printed["theta"], printed["x"])
    assert _controllers("2.3", "z_schedule=swapped") == _controllers("2.3", "literal")  # no z loop: unchanged


def test_the_rise_time_option_changes_the_measurement_only() -> None:
    runs = TableRuns(THESIS, ["2.3"])
    plain = runs.experiment("2.3", hypotheses.Hypothesis(), GAINS)
    measured = runs.experiment("2.3", hypotheses.parse("rise_time=0_100"), GAINS)
    assert measured.raw["metrics"]["rise_limits"] == [0.0, 1.0]
    assert {k: v for k, v in measured.raw.items() if k != "metrics"} == {
        k: v for k, v in plain.raw.items() if k != "metrics"
    }


def test_the_final_rounds_rule_is_the_profile_rule_against_the_current_selection() -> None:
    current = {"validation_median_rel_error": 0.30, "validation_direction_agreement": 0.60}
    lower = {"validation_median_rel_error": 0.26, "validation_direction_agreement": 0.60}
    assert profiles.final_round_selects(lower, current)
    assert not profiles.final_round_selects(
        {"validation_median_rel_error": 0.271, "validation_direction_agreement": 0.70}, current
    )  # 9.7 % lower: not enough
    assert not profiles.final_round_selects(
        {"validation_median_rel_error": 0.10, "validation_direction_agreement": 0.59}, current
    )  # direction agreement lowered


def test_the_final_rounds_spec_names_every_hypothesis_it_fits() -> None:
    from nlcx.thesis.identify import load_spec as load_identify
    from nlcx.thesis.identify import select

    spec = load_identify(ROOT / "configs" / "identify" / "final_round.yaml")
    chosen = select(spec, hypotheses.family(spec.families, spec.max_options))
    assert spec.only is not None and sorted(h.name for h in chosen) == sorted(spec.only) and len(chosen) == 18
    assert R1 in spec.only and "literal" in spec.only


def test_a_study_records_the_commit_of_its_spec(tmp_path: Path) -> None:
    spec = tmp_path / "spec.yaml"
    spec.write_text("name: x\n")
    assert spec_provenance(spec)["spec_commit"] is None  # not in a git checkout
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "spec.yaml"], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "spec"], check=True)
    head = subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    record = spec_provenance(spec)
    assert (record["spec_commit"], record["spec_committed"]) == (head, True)
    spec.write_text("name: y\n")
    assert spec_provenance(spec)["spec_committed"] is False


def test_a_set_is_judged_by_its_largest_relative_miss_and_its_printed_intervals() -> None:
    rules = tolerances.load(THESIS / "tolerances.yaml")
    cells = with_intervals(column_cells("2.3"), rules, 2)
    members = [0, 2]
    judge = SetJudge(cells, members, ((0,), (2,)))
    values = np.tile(cells.value.to_numpy(float), (3, 1))
    values[1, 2] = cells.upper.iloc[2] * 1.001  # just outside one cell of the set
    values[2, 0] = np.nan  # undefined
    miss, hit = judge.judge(values)
    scale = np.maximum(cells.value.abs(), cells.metric.map(FLOORS)).to_numpy()
    assert miss[0] == 0.0 and list(hit) == [True, False, False]
    assert miss[1] == pytest.approx(abs(values[1, 2] - cells.value.iloc[2]) / scale[2])
    assert miss[2] == np.inf


def _tiny_study(tmp_path: Path) -> Path:
    spec = {
        "name": "tiny", "kind": "consistency", "tables": ["2.3"], "controllers": ["conventional", "proposed"],
        "families": ["saturation"], "max_options": 1, "alone": ["lag"],
        "free": {k: v for k, v in BOX.items() if not k.startswith("vars.conventional.z.")},
        "warm_start": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 1},
        "optimiser": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 1},
        "cloud": {"n": 6, "seed": 3}, "zero_decimals": 2,
    }  # fmt: skip
    path = tmp_path / "consistency.yaml"
    path.write_text(yaml.safe_dump(spec))
    result = runner.invoke(app, ["identify", str(path), "--out", str(tmp_path / "study")])
    assert result.exit_code == 0, result.output
    return path


def _targeted(tmp_path: Path, **change: object) -> Path:
    spec = {
        "name": "tiny_targeted", "kind": "targeted", "consistency": "consistency.yaml",
        "study": str(tmp_path / "study"), "sets": {"least_miss": 0.0, "cap": 3},
        "hypotheses": ["literal", "derivative=measurement+step_time=one_second_from_step"], "nearest": 1,
        "combine_with": "saturation=plain", "proposed": ["form=ideal"],
        "budget": {"loops": 30, "per_parameter": 3, "popsize": 6, "sigma": 0.25, "seed": 1}, **change,
    }  # fmt: skip
    path = tmp_path / "targeted.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


@pytest.mark.slow
def test_the_targeted_search_end_to_end_its_verdicts_recomputed(tmp_path: Path) -> None:
    _tiny_study(tmp_path)
    path = _targeted(tmp_path)
    out = tmp_path / "targeted"
    result = runner.invoke(app, ["identify", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    table = pd.read_csv(out / "targeted.csv", dtype={"table": str})
    subsets = pd.read_csv(tmp_path / "study" / "subsets.csv", dtype={"table": str})
    assert len(table) == min(3, len(subsets)) and list(table.consistency_miss) == sorted(table.consistency_miss)
    spec, consistency = load_targeted(path), load_spec(tmp_path / "consistency.yaml")
    rules = tolerances.load(THESIS / "tolerances.yaml")
    for row in table.itertuples():
        loops = pd.read_csv(next((out / "sets").glob(f"2_3_{row.controller}_{_slug(row.cells)}.loops.csv")))
        objective = loops[[c for c in loops if c.startswith("miss_")]].min(axis=1)
        assert np.allclose(loops.objective, objective) and row.smallest_miss == loops.objective.min()
        assert row.loops == len(loops) and row.loops_to_best == int(loops.objective.argmin()) + 1
        hit = loops[[c for c in loops if c.startswith("hit_")]].any(axis=1)
        assert (row.verdict == "reachable") == bool(hit.any())
        if not hit.any():
            assert (row.verdict == "unreachable") == (row.smallest_miss >= spec.margin * spec.tolerance)
        for _, group in loops.groupby("hypothesis"):
            free = len(json.loads(group["values"].iloc[0]))
            assert len(group) <= (min(spec.budget.loops, spec.budget.per_parameter * (free + 1)) if free else 1)
        # the best loop, run again from its values alone, misses the set by what the search recorded
        cells = with_intervals(column_cells("2.3", row.controller), rules, consistency.zero_decimals)
        members = [i for i, c in enumerate(cells.cell) if c in row.cells.split(" & ")]
        runs = ColumnRuns(THESIS, "2.3", row.controller)
        again = runs.measure_each(hypotheses.parse(row.hypothesis), [json.loads(row.values)], consistency.definitions)
        judge = SetJudge(cells, members, tuple((m,) for m in members))
        assert min(judge.judge(v)[0][0] for v in again.values()) == pytest.approx(row.smallest_miss, rel=1e-12)
    study = json.loads((out / "study.json").read_text())
    assert study["hypotheses"] == len(table) and study["spec_sha256"]
    again = runner.invoke(app, ["identify", str(path), "--out", str(out)])
    assert again.exit_code == 0 and "[1/" not in again.output  # resumed: nothing searched again
    parallel = tmp_path / "parallel"
    assert runner.invoke(app, ["identify", str(path), "--out", str(parallel), "--jobs", "2"]).exit_code == 0
    assert (parallel / "targeted.csv").read_bytes() == (out / "targeted.csv").read_bytes()  # any number of workers


def _slug(text: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")


def test_a_bad_targeted_spec_is_one_line(tmp_path: Path) -> None:
    path = _targeted(tmp_path, hypotheses=["derivative=sideways"])
    result = runner.invoke(app, ["identify", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code != 0
    line = result.output.strip()
    assert "\n" not in line and "derivative=sideways" in line and "Traceback" not in line

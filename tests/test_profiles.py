"""Reproduction profiles: literal is the loop as printed (the defaults); a profile reaches every pendulum experiment."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from nlcx import config, engine
from nlcx.cli import app
from nlcx.errors import ConfigError
from nlcx.thesis import profiles

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "configs" / "thesis"
runner = CliRunner()
CLAMPED = {
    "name": "clamped",
    "hypothesis": {"saturation": "clamping", "ordering": "magnitude"},
    "values": {"vars.conventional.angle.kp": 60.0, "F_max": 8.0},
}


def test_literal_runs_every_config_exactly_as_committed() -> None:
    literal = profiles.load("literal", THESIS)
    assert literal.literal
    for path in (THESIS / "ch2" / "fig_2_04.yaml", THESIS / "ch5" / "fig_5_02.yaml"):
        ours = profiles.experiment(path, [], literal)
        assert ours.resolved() == config.load(path).resolved()


def test_a_profile_sets_its_values_and_options_on_the_pendulums_only() -> None:
    profile = profiles.Profile(**CLAMPED)
    exp = profiles.experiment(THESIS / "ch3" / "fig_3_27.yaml", [], profile)  # x-z pendulum
    conventional = exp.resolved()["controllers"]["conventional"]
    assert conventional["loops"]["theta"]["schedule"]["kp"] == 60.0
    assert conventional["saturation"] == {"limits": {"F_x": 8.0, "F_z": 8.0}, "anti_windup": "clamping", "kb": 1.0}
    proposed = exp.resolved()["controllers"]["proposed"]
    assert proposed["loops"]["x"]["schedule"]["kp"] == {"min": -2.4, "max": -3.0}
    cstr = THESIS / "ch5" / "fig_5_02.yaml"
    assert profiles.experiment(cstr, [], profile).resolved() == config.load(cstr).resolved()


def test_reproduce_under_a_profile_changes_the_tables(tmp_path: Path) -> None:
    path = tmp_path / "clamped.yaml"
    path.write_text(yaml.safe_dump(CLAMPED))
    out = {}
    for name, profile in (("literal", "literal"), ("clamped", str(path))):
        out[name] = tmp_path / name
        args = ["reproduce", "--only", "table-2.3", "--jobs", "1", "--out", str(out[name]), "--profile", profile]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        assert f"profile {name}:" in result.output
    literal = pd.read_csv(out["literal"] / "tables" / "table_2_3.csv")
    clamped = pd.read_csv(out["clamped"] / "tables" / "table_2_3.csv")
    assert list(literal.thesis) == list(clamped.thesis)
    assert not literal.nlcx.equals(clamped.nlcx)
    (run,) = [r for r in engine.run_experiment(
        profiles.experiment(THESIS / "ch2" / "fig_2_04.yaml", [], profiles.Profile(**CLAMPED))
    ).runs if r.label == "conventional"]  # fmt: skip
    assert abs(run.u).max() <= 8.0


def test_an_unknown_profile_or_option_is_a_one_line_error() -> None:
    with pytest.raises(ConfigError, match="no such profile; allowed: literal"):
        profiles.load("nonesuch", THESIS)
    result = runner.invoke(app, ["reproduce", "--only", "table-2.3", "--profile", "nonesuch"])
    assert result.exit_code == 2 and result.output.strip().startswith("config error: --profile = 'nonesuch'")
    with pytest.raises(ValueError, match="unknown option saturation=sometimes"):
        profiles.Profile(name="x", hypothesis={"saturation": "sometimes"})


def _row(error: float, direction: float) -> dict[str, float]:
    return {"validation_median_rel_error": error, "validation_direction_agreement": direction}


def test_the_rule_selects_only_a_tenth_lower_validation_error_at_no_loss_of_direction() -> None:
    literal = _row(0.50, 0.60)
    assert profiles.rule_selects(_row(0.449, 0.60), literal)  # 10.2 % lower, same direction
    assert not profiles.rule_selects(_row(0.46, 0.90), literal)  # 8 % lower
    assert not profiles.rule_selects(_row(0.20, 0.59), literal)  # far lower, direction lost
    assert profiles.rule_selects(_row(0.30, 0.61), literal)


def test_reproduce_without_profile_runs_the_profile_the_rule_chose(tmp_path: Path) -> None:
    """The default follows ``default:`` of selected.yaml; the manifest names what ran."""
    import json
    import shutil

    configs = tmp_path / "thesis"
    shutil.copytree(THESIS, configs)
    selected = configs / "profiles" / "selected.yaml"
    spec = yaml.safe_load(selected.read_text())
    for chosen, expected in ((True, "selected"), (False, "literal")):
        selected.write_text(yaml.safe_dump({**spec, "default": chosen}))
        assert profiles.default_name(configs) == expected
        out = tmp_path / expected
        args = ["reproduce", "--only", "table-2.1", "--jobs", "1", "--out", str(out), "--configs", str(configs)]
        result = runner.invoke(app, [*args, "--no-report"])
        assert result.exit_code == 0, result.output
        assert f"profile {expected}:" in result.output
        assert json.loads((out / "manifest.json").read_text())["profile"] == expected
    selected.unlink()
    assert profiles.default_name(configs) == "literal"


def test_the_committed_selected_profile_records_the_rules_verdict() -> None:
    """``default`` of the committed selected.yaml is a bool the study wrote, never absent."""
    spec = yaml.safe_load((THESIS / "profiles" / "selected.yaml").read_text())
    assert isinstance(spec.get("default"), bool)
    assert profiles.default_name(THESIS) == ("selected" if spec["default"] else "literal")

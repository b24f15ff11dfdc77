"""Overrides in Hydra's grammar: ``key=value``, ``+key=value``, ``++key=value``, ``~key`` and ``~key=value``."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from nlcx.cli import app
from nlcx.config import OVERRIDE_FORMS, apply_overrides, load, parse_override, read_config
from nlcx.errors import MISSING, ConfigError

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
runner = CliRunner()


@pytest.fixture
def raw() -> dict[str, object]:
    return {"simulation": {"t_end": 20.0, "bounds": {}}, "uncertainty": {"noise": {"std": 0.1}}, "seed": 0}


def _error(raw: dict[str, object], overrides: list[str]) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        apply_overrides(raw, overrides)
    assert len(str(info.value).splitlines()) == 1
    return info.value


def test_parse_override_reads_the_action_key_and_yaml_value() -> None:
    assert parse_override("a.b=[1, 2]").action == "set"
    add = parse_override("+a.b={c: 1e-3, d: 1.0e-3}")
    assert (add.action, add.key) == ("add", ("a", "b"))
    assert add.value == yaml.safe_load("{c: 1e-3, d: 1.0e-3}") == {"c": "1e-3", "d": 0.001}  # PyYAML's numbers
    assert parse_override("++seed=3").action == "force"
    delete = parse_override("~uncertainty.noise")
    assert (delete.action, delete.key, delete.value) == ("delete", ("uncertainty", "noise"), MISSING)
    assert parse_override("~seed=0").value == 0
    assert parse_override("~title=").value is None  # an empty value is null, as for key=


@pytest.mark.parametrize("text", ["+seed", "++seed", "seed", "+++seed=1", "+~seed=1", "~", "~=1", "a..b=1", "=1", "+"])
def test_malformed_overrides_are_one_line_errors(text: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_override(text)
    assert str(info.value) == f"config error: <config> = {text!r}: {OVERRIDE_FORMS}"


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("a=\x07", "unacceptable character #x0007: special characters are not allowed"),
        ("a=[1, 2", "expected ',' or ']', but got '<stream end>'"),
    ],
)
def test_a_value_that_is_not_yaml_is_a_one_line_error_naming_the_problem(text: str, problem: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_override(text)
    message = str(info.value)
    assert "\n" not in message
    assert message == f"config error: a = {text[2:]!r}: not valid YAML: {problem}"


def test_set_adds_or_replaces_a_key(raw: dict[str, object]) -> None:
    before = copy.deepcopy(raw)
    out = apply_overrides(raw, ["simulation.t_end=5", "simulation.bounds.x=0.5", "outputs.figure=false"])
    assert out["simulation"] == {"t_end": 5, "bounds": {"x": 0.5}}
    assert out["outputs"] == {"figure": False}
    assert raw == before


def test_add_on_an_existing_key_is_an_error(raw: dict[str, object]) -> None:
    error = _error(raw, ["+simulation.t_end=5"])
    assert (error.path, error.value) == ("simulation.t_end", 20.0)
    assert "already set" in error.allowed and "++key=value" in error.allowed
    assert _error(raw, ["+uncertainty.noise={std: 1}"]).path == "uncertainty.noise"  # a whole section too
    assert _error(raw, ["+simulation.bounds.x=1", "+simulation.bounds.x=2"]).value == 1  # added by the first


def test_add_creates_a_new_nested_key(raw: dict[str, object]) -> None:
    before = copy.deepcopy(raw)
    out = apply_overrides(raw, ["+simulation.bounds.x=5", "+reference.x.kind=step", "+vars.k=[1, 2]"])
    assert out["simulation"] == {"t_end": 20.0, "bounds": {"x": 5}}
    assert out["reference"] == {"x": {"kind": "step"}}
    assert out["vars"] == {"k": [1, 2]}
    assert raw == before


def test_add_below_a_value_that_is_not_a_mapping_is_an_error(raw: dict[str, object]) -> None:
    error = _error(raw, ["+seed.x=1"])
    assert (error.path, error.value) == ("seed", 0)
    assert "not a mapping" in error.allowed


def test_force_sets_an_existing_key_or_adds_a_new_one(raw: dict[str, object]) -> None:
    out = apply_overrides(raw, ["++simulation.t_end=7.5", "++simulation.dt=0.01", "++metrics.ss_window=2"])
    assert out["simulation"] == {"t_end": 7.5, "bounds": {}, "dt": 0.01}
    assert out["metrics"] == {"ss_window": 2}


def test_delete_removes_the_key_and_keeps_the_rest(raw: dict[str, object]) -> None:
    before = copy.deepcopy(raw)
    out = apply_overrides(raw, ["~uncertainty.noise", "~simulation.bounds"])
    assert out == {"simulation": {"t_end": 20.0}, "uncertainty": {}, "seed": 0}
    assert raw == before
    assert apply_overrides(raw, ["~seed"]).keys() == {"simulation", "uncertainty"}


def test_delete_of_a_missing_key_is_an_error(raw: dict[str, object]) -> None:
    for text, path in [("~uncertainty.friction", "uncertainty.friction"), ("~outputs.figure", "outputs.figure")]:
        error = _error(raw, [text])
        assert (error.path, error.value) == (path, MISSING)
        assert "cannot delete" in error.allowed
    error = _error(raw, ["~seed.x"])  # below a number: not there either
    assert error.path == "seed.x"
    assert _error(raw, ["~seed", "~seed"]).path == "seed"  # deleted by the first


def test_delete_with_a_value_deletes_only_that_value(raw: dict[str, object]) -> None:
    assert "noise" not in apply_overrides(raw, ["~uncertainty.noise={std: 0.1}"])["uncertainty"]
    assert "t_end" not in apply_overrides(raw, ["~simulation.t_end=20.0"])["simulation"]
    error = _error(raw, ["~simulation.t_end=30"])
    assert (error.path, error.value) == ("simulation.t_end", 20.0)
    assert "only where its value is 30" in error.allowed
    flags = {"outputs": {"figure": True, "n": 1}}
    assert _error(flags, ["~outputs.n=true"]).path == "outputs.n"  # 1 is not true, though 1 == True in Python
    assert apply_overrides(flags, ["~outputs.figure=true"]) == {"outputs": {"n": 1}}


def test_overrides_apply_in_order(raw: dict[str, object]) -> None:
    out = apply_overrides(raw, ["~seed", "+seed=4", "seed=5", "~seed=5", "++seed=6"])
    assert out["seed"] == 6


def test_the_command_line_takes_hydra_overrides() -> None:
    """The examples of the README: a bound added to a config without one, a section deleted."""
    config = CONFIGS / "x_error_ags.yaml"
    assert "bounds" not in read_config(config).get("simulation", {})
    assert load(config, ["+simulation.bounds.x=5"]).section.simulation.bounds == {"x": 5.0}
    result = runner.invoke(app, ["validate", str(config), "+simulation.bounds.x=5"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["validate", str(config), "+simulation.t_end=5"])
    assert result.exit_code == 2
    assert result.stderr.strip().startswith("config error: simulation.t_end = 20.0: already set")

    disturbed = CONFIGS / "thesis" / "ch2" / "fig_2_18.yaml"
    assert [u.label for u in load(disturbed).uncertainties] == ["disturbance"]
    assert load(disturbed, ["~uncertainty.disturbance"]).uncertainties == ()
    result = runner.invoke(app, ["validate", str(disturbed), "~uncertainty.disturbance"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["validate", str(config), "~uncertainty.disturbance"])
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        "config error: uncertainty.disturbance = (missing): not in the config, so ~key cannot delete it"
    )

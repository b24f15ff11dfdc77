"""Bad configs give one line naming the key path, the bad value and what is allowed."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from nlcx import config as cfg
from nlcx.cli import app
from nlcx.config import apply_overrides, load

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "x_time_ags.yaml"
runner = CliRunner()


def validate(args: list[str]):
    return runner.invoke(app, ["validate", *args])


CASES = [
    # (overrides, key path, bad value shown, words of what is allowed)
    (
        ["plant.name=x_pendulm"],
        "plant.name",
        "'x_pendulm'",
        "unknown plant; allowed: cstr, transfer_function, x_pendulum, xy_pendulum, xyz_pendulum, xz_pendulum "
        "(did you mean 'x_pendulum'?)",
    ),
    (
        ["simulation.t_edn=5"],
        "simulation.t_edn",
        "5",
        "unknown key; allowed keys: bounds, device, dt, integrator, t_end (did you mean 't_end'?)",
    ),
    (["simulation.dt=abc"], "simulation.dt", "'abc'", "must be a valid number"),
    (["simulation.dt=-0.001"], "simulation.dt", "-0.001", "must be greater than 0"),
    (
        ["simulation.integrator=rk5"],
        "simulation.integrator",
        "'rk5'",
        "allowed values: 'rk4', 'heun' or 'euler'",
    ),
    (["plant.params.mass=2"], "plant.params.mass", "2", "unknown key; allowed keys: M, equations, g, l, m"),
    (["plant.params.M=0"], "plant.params.M", "0", "must be greater than 0"),
    (
        ["controllers.proposed.loops.x.schedule.kind=time_agss"],
        "controllers.proposed.loops.x.schedule.kind",
        "'time_agss'",
        "unknown gain schedule; allowed: anfis, constant, error_ags, fuzzy, time_ags (did you mean 'time_ags'?)",
    ),
    (
        ["controllers.proposed.loops.x.schedule.rate.kp=-1"],
        "controllers.proposed.loops.x.schedule.rate.kp",
        "-1",
        "must be greater than or equal to 0",
    ),
    (
        ["controllers.conventional.loops.y={schedule: {kind: constant}}"],
        "controllers.conventional.loops.y",
        "'y'",
        "not an output of x_pendulum; allowed: x, theta",
    ),
    (
        ["controllers.proposed.kind=lqg"],
        "controllers.proposed.kind",
        "'lqg'",
        "unknown controller; allowed: lqr, open_loop, pid",
    ),
    (
        ["reference.x.kind=ramp"],
        "reference.x.kind",
        "'ramp'",
        "unknown reference; allowed: constant, filtered_step, sine, step",
    ),
    (
        ["uncertainty.wind={}"],
        "uncertainty.wind.kind",
        "'wind'",
        "unknown uncertainty; allowed: actuator_lag, actuator_saturation, disturbance, friction, noise",
    ),
    (
        ["simulation.dt=0.003"],
        "simulation.t_end",
        "20.0",
        "must be a whole number (>= 1) of steps dt = 0.003",
    ),
    (["seed=-1"], "seed", "-1", "must be greater than or equal to 0"),
    (["simulation.t_end"], "", "'simulation.t_end'", "an override must look like section.key=value"),
    (["+simulation.dt"], "", "'+simulation.dt'", "an override must look like section.key=value"),
    (
        ["+simulation.dt=0.01"],
        "simulation.dt",
        "0.001",
        "already set; +key=value adds a new key only (key=value or ++key=value sets it)",
    ),
    (["~uncertainty.wind"], "uncertainty.wind", "(missing)", "not in the config, so ~key cannot delete it"),
    (["~seed=3"], "seed", "0", "~seed=3 deletes it only where its value is 3"),
    (["~plant.name"], "plant.name", "(missing)", "required key is missing"),
    (
        ["controllers.conventional.loops.x.schedule=${vars.gains}"],
        "controllers.conventional.loops.x.schedule",
        "'${vars.gains}'",
        "refers to vars.gains, a key that does not exist",
    ),
]


@pytest.mark.parametrize(("overrides", "path", "value", "allowed"), CASES)
def test_bad_config_one_line(overrides: list[str], path: str, value: str, allowed: str) -> None:
    result = validate([str(CONFIG), *overrides])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"config error: {path or '<config>'} = {value}: {allowed}")
    assert "Traceback" not in result.output


def test_wrong_number_of_loops(tmp_path: Path) -> None:
    raw = yaml.safe_load(CONFIG.read_text())
    del raw["controllers"]["conventional"]["loops"]["x"]
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(raw))
    result = validate([str(bad)])
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        "config error: controllers.conventional.loops = ['theta']: x_pendulum needs exactly one loop "
        "per output (2: x, theta); got 1 loop(s) on theta"
    )


def test_missing_section_and_bad_files(tmp_path: Path) -> None:
    raw = yaml.safe_load(CONFIG.read_text())
    del raw["plant"]
    (tmp_path / "noplant.yaml").write_text(yaml.safe_dump(raw))
    result = validate([str(tmp_path / "noplant.yaml")])
    assert result.stderr.strip() == "config error: plant = (missing): required key is missing"
    (tmp_path / "broken.yaml").write_text("name: x\nplant: [unclosed\n")
    result = validate([str(tmp_path / "broken.yaml")])
    assert result.exit_code == 2 and result.stderr.startswith("config error: <config> = ")
    assert "not valid YAML (line 3, column 1)" in result.stderr
    result = validate([str(tmp_path / "absent.yaml")])
    assert result.exit_code == 2 and "config file not found" in result.stderr


def test_overrides_set_nested_values_as_yaml() -> None:
    raw = {"a": {"b": 1}}
    out = apply_overrides(raw, ["a.c.d=[1, 2]", "a.b=x", "e=2.5"])
    assert out == {"a": {"b": "x", "c": {"d": [1, 2]}}, "e": 2.5}
    assert raw == {"a": {"b": 1}}


def test_valid_config_and_defaults_in_one_place() -> None:
    exp = load(CONFIG, ["simulation.t_end=5"])
    resolved = exp.resolved()
    assert resolved["simulation"]["t_end"] == 5
    assert resolved["plant"]["params"] == {"M": 1.0, "m": 0.1, "l": 0.3, "g": 9.8, "equations": "derived"}
    assert resolved["controllers"]["proposed"]["derivative"] == {
        "method": "backward",
        "N": 100.0,
        "on": "error",
    }
    assert resolved["metrics"]["settling_band"] == 0.02
    result = validate([str(CONFIG)])
    assert result.exit_code == 0 and "valid" in result.output


SECTIONS = [cfg.PlantSection, cfg.SimulationSection, cfg.MetricsSection, cfg.OutputsSection, cfg.ExperimentSection]


@pytest.mark.parametrize("model", SECTIONS, ids=lambda m: m.__name__)
def test_every_section_field_is_described_in_the_json_schema(model: type[cfg.Section]) -> None:
    """The configuration reference is generated from the schema: every key has a description,
    every time a unit, and the section its docstring."""
    schema = model.model_json_schema()
    assert model.__doc__ is not None
    assert schema["description"].startswith(model.__doc__.strip().splitlines()[0])
    assert set(schema["properties"]) == set(model.model_fields)
    for key, prop in schema["properties"].items():
        assert len(prop.get("description", "")) > 10, (model.__name__, key)
    times = {"t_end", "dt", "ss_window"} & set(schema["properties"])
    assert all(schema["properties"][key]["unit"] == "s" for key in times)

"""The commands that describe nlcx itself: ``--version``, ``list KIND NAME``, ``schema``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator
from typer.testing import CliRunner

import nlcx
from nlcx import config
from nlcx.cli import app
from nlcx.controllers.pid import LoopConfig, PIDConfig
from nlcx.plants.x_pendulum import XPendulum
from nlcx.schema import experiment_schema

ROOT = Path(__file__).resolve().parent.parent
runner = CliRunner()


@pytest.mark.parametrize("flag", ["--version", "-V"])
def test_version(flag: str) -> None:
    result = runner.invoke(app, [flag])
    assert result.exit_code == 0, result.output
    assert result.stdout == f"nlcx {nlcx.__version__}\n"
    assert re.fullmatch(r"nlcx \d+\.\d+\.\d+\S*\n", result.stdout)
    eager = runner.invoke(app, [flag, "list"])  # printed before any command runs, and nothing else
    assert eager.exit_code == 0 and eager.stdout == result.stdout


def _rows(output: str, title: str) -> list[list[str]]:
    """The rows (cells split where two spaces or more part them) of the block that follows
    the line starting with ``title``, its header row left out."""
    lines = output.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(title))
    block = []
    for line in lines[start + 2 :]:
        if not line.startswith("  "):
            break
        block.append(re.split(r"\s{2,}", line.strip()))
    return block


def test_list_a_plant_shows_its_signals_and_parameters() -> None:
    result = runner.invoke(app, ["list", "plants", "x_pendulum"])
    assert result.exit_code == 0, result.output
    assert runner.invoke(app, ["list", "plant", "x_pendulum"]).stdout == result.stdout  # the singular too
    states = _rows(result.stdout, "states:")
    assert [row[:2] for row in states] == [["x", "m"], ["x_dot", "m/s"], ["theta", "rad"], ["theta_dot", "rad/s"]]
    assert [(s.name, s.unit) for s in XPendulum.states] == [tuple(row[:2]) for row in states]
    assert [row[:2] for row in _rows(result.stdout, "inputs:")] == [["F_x", "N"]]
    assert [row[0] for row in _rows(result.stdout, "outputs:")] == ["x", "theta"]
    params = {row[0]: row for row in _rows(result.stdout, "parameters (plant.params)")}
    assert list(params)[:4] == ["M", "m", "l", "g"]
    defaults = {"M": "1.0", "m": "0.1", "l": "0.3", "g": "9.8"}  # Table 2.1
    units = {"M": "kg", "m": "kg", "l": "m", "g": "m/s^2"}
    for name in defaults:
        assert params[name][:4] == [name, "float > 0", units[name], defaults[name]]
        assert float(params[name][3]) == XPendulum.Params.model_fields[name].default
    assert params["equations"][1] == "'derived' | 'printed'" and params["equations"][2] == '"derived"'


def test_list_a_controller_shows_its_configuration() -> None:
    result = runner.invoke(app, ["list", "controller", "pid"])
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith("controller pid: ")
    fields = {row[0]: row for row in _rows(result.stdout, "configuration (controllers.<label>), PIDConfig")}
    assert list(fields) == list(PIDConfig.model_fields)
    assert fields["loops"][1:3] == ["dict[str, LoopConfig] min length 1", "required"]
    assert fields["integral"][1:3] == ["'outside' | 'inside'", '"outside"']
    assert fields["sample_time"][1:4] == ["float >= 0", "s", "0.0"]
    assert fields["loops"][-1] == PIDConfig.model_fields["loops"].description
    loop = {row[0]: row for row in _rows(result.stdout, "LoopConfig:")}  # the models nested in it follow
    assert list(loop) == list(LoopConfig.model_fields) and loop["sign"][1:3] == ["-1 | 1", "1"]


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (
            ["list", "plants", "x_pendulm"],
            "list error: NAME = x_pendulm: unknown plant; allowed: cstr, transfer_function, x_pendulum, xy_pendulum, "
            "xyz_pendulum, xz_pendulum (did you mean 'x_pendulum'?); one of your own: name its file in the config's "
            "imports: [my_plants.py] (or --plugins FILE), or install a package that declares it under the "
            "entry-point group nlcx.plants",
        ),
        (
            ["list", "controler"],
            "list error: KIND = controler: unknown kind (did you mean 'controller'?); allowed: plants, controllers, "
            "schedules, uncertainties, references, tuners",
        ),
    ],
)
def test_list_an_unknown_name_is_one_line(args: list[str], line: str) -> None:
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert result.stderr.splitlines() == [line] and result.stdout == ""


def test_schema_to_stdout_and_to_a_file(tmp_path: Path) -> None:
    printed = runner.invoke(app, ["schema"])
    assert printed.exit_code == 0, printed.output
    schema = json.loads(printed.stdout)
    assert schema == experiment_schema()
    out = tmp_path / "editor" / "nlcx.schema.json"
    written = runner.invoke(app, ["schema", "--out", str(out)])
    assert written.exit_code == 0 and written.stdout == f"wrote {out}\n"
    assert out.read_text(encoding="utf-8") == printed.stdout
    assert not list(out.parent.glob(".*.tmp"))
    validator = Draft202012Validator(schema)
    experiment = config.interpolate(config.read_config(ROOT / "configs" / "x_error_ags.yaml"))
    assert validator.is_valid(experiment) and not validator.is_valid({**experiment, "colour": "red"})

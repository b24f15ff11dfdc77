"""The command line end to end on the real configs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from conftest import reproduce_only
from typer.testing import CliRunner

from nlcx.cli import app

ROOT = Path(__file__).resolve().parent.parent
runner = CliRunner()
PENDULUM_COLUMNS = ["t", "controller", "x", "x_dot", "theta", "theta_dot", "F_x", "x_ref", "theta_ref"]


@pytest.mark.parametrize("name", ["x_time_ags", "x_error_ags"])
def test_run_writes_the_run_directory(name: str, tmp_path: Path) -> None:
    out = tmp_path / name
    result = runner.invoke(
        app, ["run", str(ROOT / "configs" / f"{name}.yaml"), "outputs.gains_figure=true", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} == {
        ".nlcx-output",
        "config.yaml",
        "metrics.csv",
        "timeseries.csv",
        "figure.png",
        "gains.png",
        "manifest.json",
        "report.html",
        "report.md",
    }
    metrics = pd.read_csv(out / "metrics.csv")
    assert list(metrics.columns) == ["controller", "signal", "metric", "value", "unit", "status", "note"]
    assert set(metrics.controller) == {"conventional", "proposed"}
    for metric in (
        "rise_time",
        "settling_time",
        "overshoot",
        "undershoot",
        "steady_state_error",
        "ise",
        "iae",
        "itae",
    ):
        assert ((metrics.signal == "x") & (metrics.metric == metric)).sum() == 2
    assert ((metrics.signal == "theta") & (metrics.metric == "peak_deviation")).sum() == 2
    assert ((metrics.signal == "F_x") & (metrics.metric == "control_effort")).sum() == 2
    ts = pd.read_csv(out / "timeseries.csv")
    assert list(ts.columns[: len(PENDULUM_COLUMNS)]) == PENDULUM_COLUMNS
    assert {"theta.kp", "theta.ki", "theta.kd", "x.kp", "x.ki", "x.kd"} <= set(ts.columns)
    assert len(ts) == 2 * 20001 and ts.t.max() == pytest.approx(20.0)
    manifest = json.loads((out / "manifest.json").read_text())
    assert {r["status"] for r in manifest["runs"]} == {"ok"}
    assert manifest["seed"]["entropy"] == 0 and "numpy" in manifest["versions"]
    assert manifest["seed"]["uncertainty_spawn_keys"] == []  # no uncertainty
    assert set(manifest["timings_s"]) >= {"simulate", "write", "wall"}
    assert "commit" in manifest["git"]
    assert manifest["nlcx_output"] == "run" and manifest["overrides"] == ["outputs.gains_figure=true"]
    assert manifest["argv"] == sys.argv  # the CLI runner's process
    assert (out / "figure.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob(".*.tmp"))


def test_manifest_lists_each_uncertaintys_spawned_seed(tmp_path: Path) -> None:
    """Figure 3.6's run has a disturbance and noise: the manifest lists the seed sequence's
    two children, in config order, as prepare spawned them (the noise draws from the second)."""
    out = tmp_path / "f"
    cfg = ROOT / "configs" / "thesis" / "ch3" / "fig_3_06.yaml"
    result = runner.invoke(app, ["run", str(cfg), "simulation.t_end=0.5", "--out", str(out), "--no-report"])
    assert result.exit_code == 0, result.output
    seed = json.loads((out / "manifest.json").read_text())["seed"]
    assert seed["uncertainty_spawn_keys"] == [[0], [1]]


def test_resolved_config_reproduces_the_run(tmp_path: Path) -> None:
    first, second = tmp_path / "first", tmp_path / "second"
    assert runner.invoke(app, ["run", str(ROOT / "configs" / "x_error_ags.yaml"), "--out", str(first)]).exit_code == 0
    assert runner.invoke(app, ["run", str(first / "config.yaml"), "--out", str(second)]).exit_code == 0
    for name in ("metrics.csv", "timeseries.csv"):
        assert (first / name).read_bytes() == (second / name).read_bytes()


def test_overrides_and_quiet(tmp_path: Path) -> None:
    out = tmp_path / "short"
    result = runner.invoke(
        app,
        [
            "run",
            str(ROOT / "configs" / "x_time_ags.yaml"),
            "simulation.t_end=5",
            "outputs.figure=false",
            "--out",
            str(out),
            "-q",
        ],
    )
    assert result.exit_code == 0 and result.output.strip() == str(out)
    ts = pd.read_csv(out / "timeseries.csv")
    assert ts.t.max() == pytest.approx(5.0)
    assert not (out / "figure.png").exists()
    assert yaml.safe_load((out / "config.yaml").read_text())["simulation"]["t_end"] == 5


def test_unstable_run_is_reported_and_exit_is_zero(tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        [
            "run",
            str(ROOT / "configs" / "x_time_ags.yaml"),
            "controllers.conventional.loops.theta.sign=1",
            "--out",
            str(tmp_path / "u"),
        ],
    )
    assert result.exit_code == 0
    assert "conventional   unstable: diverged at t =" in result.output
    manifest = json.loads((tmp_path / "u" / "manifest.json").read_text())
    assert manifest["runs"][0]["status"] == "unstable" and manifest["runs"][0]["t_fail"] > 0


def test_list_shows_every_registry() -> None:
    result = runner.invoke(app, ["list"])
    assert result.exit_code == 0
    for name in (
        "plants:",
        "x_pendulum",
        "transfer_function",
        "controllers:",
        "pid",
        "open_loop",
        "schedules:",
        "constant",
        "time_ags",
        "error_ags",
        "uncertainties:",
        "disturbance",
        "references:",
        "step",
        "sine",
    ):
        assert name in result.output


def test_third_party_plant_through_an_entry_point(tmp_path: Path) -> None:
    """A package that only declares an nlcx.plants entry point is listed and runs."""
    (tmp_path / "toyplant.py").write_text(
        textwrap.dedent('''
        import numpy as np
        from numba import njit
        from pydantic import Field
        from nlcx.kernel.abi import RHS_SIG
        from nlcx.plants.base import PlantModel, PlantParams, Signal

        class Params(PlantParams):
            w: float = Field(2.0, gt=0)

        @njit(RHS_SIG, cache=False)
        def rhs(t, x, u, p, dx, nb):
            for b in range(nb):  # column b: one variant
                dx[0, b] = x[1, b]
                dx[1, b] = -p[0, b] * p[0, b] * x[0, b] + u[0, b]

        class Oscillator(PlantModel):
            """Toy harmonic oscillator from a third-party package."""
            Params = Params
            states = (Signal("q", "m"), Signal("q_dot", "m/s"))
            inputs = (Signal("f", "N"),)
            outputs = ("q",)
            rhs = staticmethod(rhs)

            def parameter_vector(self, params):
                return np.array([params.w])
    ''')
    )
    dist = tmp_path / "toyplant-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toyplant\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[nlcx.plants]\noscillator = toyplant:Oscillator\n")
    cfg = tmp_path / "toy.yaml"
    cfg.write_text(
        yaml.safe_dump(
            {
                "name": "toy",
                "plant": {"name": "oscillator"},
                "controllers": {
                    "pd": {
                        "kind": "pid",
                        "loops": {"q": {"schedule": {"kind": "constant", "kp": 10, "kd": 3}}},
                    }
                },
                "reference": {"q": {"kind": "step"}},
                "simulation": {"t_end": 5.0, "dt": 0.001},
            }
        )
    )
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    nlcx = [sys.executable, "-m", "nlcx.cli"]
    listed = subprocess.run([*nlcx, "list", "plants"], capture_output=True, text=True, env=env, check=True)
    assert "oscillator" in listed.stdout and "third-party" in listed.stdout
    ran = subprocess.run(
        [*nlcx, "run", str(cfg), "--out", str(tmp_path / "out")], capture_output=True, text=True, env=env
    )
    assert ran.returncode == 0, ran.stderr
    metrics = pd.read_csv(tmp_path / "out" / "metrics.csv")
    ess = metrics[(metrics.signal == "q") & (metrics.metric == "steady_state_error")].value.item()
    assert abs(ess - (1 - 10 / 14)) < 1e-3  # P-D on w^2 = 4: y_ss = kp / (w^2 + kp)


def test_console_script_one_line_error() -> None:
    proc = subprocess.run(
        [
            str(Path(sys.executable).parent / "nlcx"),
            "run",
            str(ROOT / "configs" / "x_time_ags.yaml"),
            "simulation.dt=-1",
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == ["config error: simulation.dt = -1: must be greater than 0"]


def test_the_thesis_commands_are_listed_by_their_own_help_and_parse_their_own_options() -> None:
    """Each thesis command is listed by the first line of its own help, and its command line is
    parsed by the command built from its function: its options, its one-line refusals."""
    import inspect

    import typer

    from nlcx.cli.lazy import THESIS_COMMANDS, LazyCommand

    group = typer.main.get_command(app)
    for name, (_, listed) in THESIS_COMMANDS.items():
        command = group.commands[name]  # type: ignore[attr-defined]
        assert isinstance(command, LazyCommand) and command.help == listed
        own = " ".join(inspect.cleandoc(command.loaded.help or "").split("\n\n")[0].split())
        assert own.startswith(listed), (name, own)
        assert command.loaded.params and not command.params, "the options are the loaded command's"
    result = runner.invoke(app, ["calibrate", "spec.yaml", "--jobs", "0"])
    assert result.exit_code == 2 and "--jobs" in result.output.splitlines()[0]
    result = runner.invoke(app, ["baselines", "--no-such-option"])
    assert result.exit_code == 2 and "No such option: --no-such-option" in result.output


def test_a_run_and_its_report_leave_the_thesis_unimported(tmp_path: Path) -> None:
    """``nlcx run`` (its report page included) imports nothing of the thesis, a study on top of
    the library."""
    code = (
        "import atexit, sys\n"
        "atexit.register(lambda: print('THESIS', sorted(m for m in sys.modules if m.startswith('nlcx.thesis'))))\n"
        "from nlcx.cli import main\n"
        f"sys.argv = ['nlcx', 'run', {str(ROOT / 'configs' / 'x_error_ags.yaml')!r}, 'simulation.t_end=1', "
        f"'--out', {str(tmp_path / 'run')!r}, '--quiet']\n"
        "main()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "run" / "report.html").is_file()
    assert proc.stdout.splitlines()[-1] == "THESIS []"


def test_reproduce_only_some_figures_and_tables(tmp_path: Path) -> None:
    out = tmp_path / "thesis"
    result = reproduce_only("fig-2.4,fig-2.3,table-2.3,table-2.1,table-2.2", out)
    assert result.exit_code == 0, result.output
    assert {p.name for p in (out / "figures").iterdir()} == {"fig_2_4.png", "fig_2_3.png"}
    assert {p.name for p in (out / "tables").iterdir()} == {"table_2_3.csv", "table_2_1.csv", "table_2_2.csv"}
    table = pd.read_csv(out / "tables" / "table_2_3.csv")
    assert list(table.columns[:6]) == ["signal", "metric", "controller", "thesis", "nlcx", "delta"]
    assert len(table) == 14  # every printed cell of Table 2.3
    row = table[(table.signal == "x") & (table.metric == "Mp") & (table.controller == "proposed")].iloc[0]
    assert row.improvement_thesis_pct == pytest.approx((0.5 - 0.33) / 0.33 * 100)
    params = pd.read_csv(out / "tables" / "table_2_2.csv")
    printed = params[(params.schedule == "time_ags") & (params.parameter.str.endswith(("min", "max")))]
    assert np.allclose(printed.nlcx, printed.thesis)  # the ranges run are Table 2.2's
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["nlcx_output"] == "reproduction" and manifest["overrides"] == [] and manifest["argv"] == sys.argv
    assert manifest["only"] == ["fig-2.4", "fig-2.3", "table-2.3", "table-2.1", "table-2.2"]
    page = (out / "report.md").read_text()
    assert "- Figures: generated 2, missing 0" in page  # the two figures asked for, not the thesis's all
    assert {"started", "duration_s", "host", "platform", "versions", "git", "profile", "wall_s"} <= set(manifest)
    written = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    bad = runner.invoke(app, ["reproduce", "--only", "fig-9.9", "--out", str(out)])
    assert bad.exit_code == 2 and "unknown fig-9.9" in bad.stderr
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == written, "a failed rerun changes nothing"
    assert {p.name for p in tmp_path.iterdir()} == {"thesis", ".thesis.nlcx-lock"}


def test_calibration_is_reproducible_serial_or_parallel(tmp_path: Path) -> None:
    spec = str(ROOT / "configs" / "thesis" / "calibration" / "x_conventional.yaml")
    small = ["optimiser.pop_size=6", "optimiser.generations=2"]
    outs = []
    for name, jobs in (("serial", "1"), ("parallel", "2"), ("again", "1")):
        result = runner.invoke(app, ["calibrate", spec, *small, "--jobs", jobs, "--out", str(tmp_path / name)])
        assert result.exit_code == 0, result.output
        outs.append((tmp_path / name / "tuning.csv").read_bytes())
    assert outs[0] == outs[1] == outs[2]
    fit = pd.read_csv(tmp_path / "serial" / "fit.csv")
    assert set(fit.signal) == {"x", "theta"} and {"thesis", "nlcx", "residual"} <= set(fit.columns)

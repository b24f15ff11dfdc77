"""Validation gaps and the open-loop step analysis, end to end through `nlcx run`."""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np
import pandas as pd
import pytest
import yaml
from test_step_info import MATLAB_DEN, MATLAB_NUM, MATLAB_PUBLISHED, PC_KEYS
from typer.testing import CliRunner

from nlcx import config, engine, preflight
from nlcx.cli import app
from nlcx.errors import ConfigError

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
NUM, DEN = list(MATLAB_NUM), list(MATLAB_DEN)  # python-control's step_info test system


def open_loop_config(tmp_path: Path, **changes: object) -> Path:
    raw = {
        "name": "tf_open_loop",
        "plant": {"name": "transfer_function", "params": {"num": NUM, "den": DEN}},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {"u": {"kind": "step", "final": 1.0, "time": 1.0}},
        "simulation": {"dt": 0.01, "t_end": 121.0},  # settled: y(end) = 2.5 to 1e-9
        **changes,
    }
    path = tmp_path / "open_loop.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def one_line_error(path: Path, *overrides: str) -> str:
    result = runner.invoke(app, ["run", str(path), "--out", str(path.parent / "out"), *overrides])
    assert result.exit_code == 2, result.output
    assert not isinstance(result.exception, MemoryError | KeyError | AttributeError)
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.output
    return lines[0]


def test_open_loop_step_on_an_input_gives_each_outputs_step_info(tmp_path: Path) -> None:
    """metrics.csv of `nlcx run` equals python-control's step_info on the exact step response
    sampled on the same grid (times within one sample, python-control reports the sample at or
    after a crossing), and python-control's published numbers for this system."""
    out = tmp_path / "run"
    result = runner.invoke(app, ["run", str(open_loop_config(tmp_path)), "--out", str(out), "-q"])
    assert result.exit_code == 0, result.output
    metrics = pd.read_csv(out / "metrics.csv")
    ours = metrics[metrics.signal == "y"].set_index("metric").value
    t = np.arange(0.0, 120.0 + 1e-9, 0.01)
    exact = np.squeeze(control.step_response(control.tf(NUM, DEN), t).outputs)
    ref = control.step_info(exact, t)
    for key in ("rise_time", "settling_time", "overshoot", "undershoot", "peak", "peak_time", "steady_state_value"):
        pc = PC_KEYS[key]
        tol = 0.01 + 1e-6 if key in ("rise_time", "settling_time") else 1e-6 * max(1.0, abs(ref[pc]))
        assert abs(ours[key] - ref[pc]) <= tol, (key, ours[key], ref[pc])
    for key, value in MATLAB_PUBLISHED.items():  # within 0.5 %: MATLAB's samples are others
        assert abs(ours[key] - value) <= 5e-3 * abs(value), (key, ours[key], value)
    assert ours["undershoot"] == 0.0
    units = metrics[metrics.signal == "y"].set_index("metric").unit
    assert units["rise_time"] == "s" and units["overshoot"] == "%"
    # the input itself gets its effort metrics, as in every run
    assert {"control_effort", "peak_input"} <= set(metrics[metrics.signal == "u"].metric)


def test_open_loop_without_an_input_step_has_no_step_info(tmp_path: Path) -> None:
    path = open_loop_config(tmp_path, reference={"u": {"kind": "constant", "value": 1.0}})
    out = tmp_path / "run"
    assert runner.invoke(app, ["run", str(path), "--out", str(out), "-q"]).exit_code == 0
    assert "y" not in set(pd.read_csv(out / "metrics.csv").signal)


def test_a_reference_on_an_output_drives_nothing_in_open_loop(tmp_path: Path) -> None:
    path = open_loop_config(tmp_path, reference={"y": {"kind": "step"}})
    line = one_line_error(path)
    assert line.startswith("config error: reference.y = 'step': no controller reads a reference on output y")
    assert "open (open_loop): u" in line


def test_a_reference_on_an_input_no_pid_reads_is_an_error(tmp_path: Path) -> None:
    path = open_loop_config(
        tmp_path,
        controllers={"p": {"kind": "pid", "loops": {"y": {"schedule": {"kind": "constant", "kp": 1.0}}}}},
        reference={"y": {"kind": "step"}, "u": {"kind": "step"}},
    )
    line = one_line_error(path)
    assert line.startswith("config error: reference.u = 'step': no controller reads a reference on input u")


def test_an_input_and_an_output_with_one_name_is_an_error(tmp_path: Path) -> None:
    path = open_loop_config(tmp_path)
    line = one_line_error(path, "plant.params.output_name=u")
    assert line.startswith("config error: plant.params.")
    assert "has an input and an output named 'u'" in line


def test_a_run_too_big_for_memory_stops_before_allocating(tmp_path: Path) -> None:
    line = one_line_error(ROOT / "configs" / "x_error_ags.yaml", "simulation.t_end=1e7")
    assert line.startswith("config error: simulation.t_end = 10000000.0: the run's arrays need about ")
    assert "GiB" in line and "shorten simulation.t_end or raise simulation.dt" in line


def test_a_sweep_too_big_for_memory_stops_before_any_variant(tmp_path: Path) -> None:
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    raw["simulation"]["t_end"] = 2e5
    raw["sweep"] = {"grid": {"plant.params.M": [1.0, 1.1]}, "batch_size": 2}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(raw))
    out = tmp_path / "sweep"
    result = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 2, result.output
    last = result.output.strip().splitlines()[-1]  # after the (empty) progress bar
    assert last.startswith("config error: simulation.t_end = 200000.0: the run's arrays need")
    assert not (out / "parts").exists()


def test_the_memory_estimate_counts_the_arrays_the_kernel_allocates() -> None:
    """run_bytes agrees with the bytes of the arrays a run actually holds (x, u, r, logs, grid)."""
    exp = config.load(ROOT / "configs" / "x_error_ags.yaml", ["simulation.t_end=2.0"])
    result = engine.run_experiment(exp)
    p = result.prepared
    held = p.grid.t.nbytes + p.grid.stage_times.nbytes
    held += sum(r.x.nbytes + r.u.nbytes + r.r.nbytes + r.log.nbytes + r.friction.nbytes for r in result.runs)
    channels = [len(c.reference_signals) + len(c.log_names) for c in p.controllers]
    n_stages = p.grid.stage_times.shape[1]
    estimate = preflight.run_bytes(p.grid.t.size, n_stages, p.plant, channels)
    assert estimate >= held and estimate <= held * 1.05
    with pytest.raises(ConfigError, match="more than 80% of the 1 MiB of memory available"):
        preflight.check_memory(10 * 2**20, "simulation.t_end", 2.0, "advice", limit=2**20)
    preflight.check_memory(2**19, "simulation.t_end", 2.0, "advice", limit=2**20)

"""``nlcx metrics FILE.csv``: step_info on the columns of a CSV, end to end."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import control
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from nlcx.cli import app
from nlcx.metrics import STEP_INFO_METRICS, STEP_INFO_UNITS, step_info

ROOT = Path(__file__).resolve().parent.parent
runner = CliRunner()


def _response(num: list[float], den: list[float], t: np.ndarray) -> np.ndarray:
    return np.squeeze(control.step_response(control.tf(num, den), t).outputs)


@pytest.fixture(scope="module")
def rig_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """MATLAB's stepinfo example (python-control's test system) and the non-minimum-phase
    (1 - s)/(s^2 + s + 1) with a negative gain, on 0.01 s samples, plus a constant and a text column."""
    t = np.linspace(0.0, 60.0, 6001)
    frame = pd.DataFrame(
        {
            "time": t,
            "y": _response([1, 5, 5], [1, 1.65, 5, 6.5, 2], t),
            "y_nmp": _response([1, -1], [1, 1, 1], t),
            "u": np.ones_like(t),
            "note": ["rig"] * t.size,
        }
    )
    path = tmp_path_factory.mktemp("rig") / "data.csv"
    frame.to_csv(path, index=False)
    return path


def _read(path: Path) -> tuple[np.ndarray, pd.DataFrame]:
    frame = pd.read_csv(path)
    return frame["time"].to_numpy(), frame


def _written(path: Path, signal: str) -> dict[str, float]:
    table = pd.read_csv(path)
    rows = table[table.signal == signal]
    assert list(rows.metric) == list(STEP_INFO_METRICS)
    assert list(rows.unit) == [STEP_INFO_UNITS[k] for k in STEP_INFO_METRICS]
    return dict(zip(rows.metric, rows.value, strict=True))


def test_measures_a_known_step_response(rig_csv: Path, tmp_path: Path) -> None:
    out = tmp_path / "results" / "metrics.csv"
    result = runner.invoke(app, ["metrics", str(rig_csv), "--time", "time", "--signal", "y", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert list(pd.read_csv(out).columns) == ["signal", "metric", "value", "unit"]
    written = _written(out, "y")
    t, frame = _read(rig_csv)
    y = frame["y"].to_numpy()
    assert written == step_info(t, y)  # the same numbers, to the last bit
    # ... and python-control's on the same samples: crossings within one sample, the rest equal.
    ref = control.step_info(y, t)
    dt = t[1] - t[0]
    assert abs(written["rise_time"] - ref["RiseTime"]) < dt
    assert ref["SettlingTime"] - dt <= written["settling_time"] <= ref["SettlingTime"]
    assert written["overshoot"] == pytest.approx(ref["Overshoot"], rel=1e-12)
    assert written["peak"] == ref["Peak"] and written["peak_time"] == ref["PeakTime"]
    assert written["steady_state_value"] == ref["SteadyStateValue"] == y[-1]
    assert written["settling_min"] == ref["SettlingMin"] and written["settling_max"] == ref["SettlingMax"]
    # The printed table: one line per metric with 4 significant digits.
    lines = {line.split()[0]: line.split()[1:] for line in result.stdout.splitlines()[2:] if line.startswith("  ")}
    assert lines["rise_time"] == ["s", f"{written['rise_time']:.4g}"]
    assert lines["overshoot"] == ["%", f"{written['overshoot']:.4g}"]
    assert f"wrote {out}" in result.stdout
    assert not list(out.parent.glob(".*.tmp"))


def test_several_signals_with_a_reference(rig_csv: Path, tmp_path: Path) -> None:
    """--signal repeated: every column measured (in one batch) against --reference."""
    out = tmp_path / "metrics.csv"
    out.write_text("stale\n")  # replaced as a whole
    args = ["metrics", str(rig_csv), "--time", "time", "--signal", "y", "--signal", "u", "--signal", "y"]
    result = runner.invoke(app, [*args, "--reference", "2.5", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert list(dict.fromkeys(pd.read_csv(out).signal)) == ["y", "u"]  # a repeated column once
    t, frame = _read(rig_csv)
    for name in ("y", "u"):
        expected = step_info(t, frame[name].to_numpy(), reference=2.5)
        assert _written(out, name) == pytest.approx(expected, rel=0, abs=0, nan_ok=True)
    # MATLAB's published stepinfo values for the system, to the grid's resolution.
    y = _written(out, "y")
    assert abs(y["rise_time"] - 3.8456) < 0.01 and abs(y["settling_time"] - 27.9762) < 0.01
    assert abs(y["overshoot"] - 7.4915) < 0.03 and y["peak"] == pytest.approx(2.6873, rel=1e-3)
    assert y["steady_state_value"] == 2.5
    u = _written(out, "u")  # a constant 1 against 2.5 never rises to 90 %
    assert np.isnan(u["rise_time"]) and u["undershoot"] == 0.0 and u["peak"] == 1.0


def test_negative_gain_and_t_step(rig_csv: Path, tmp_path: Path) -> None:
    """A step at t = 5 s in data that sits at 10 before it: the measurement starts there."""
    t, frame = _read(rig_csv)
    shifted = pd.DataFrame({"s": np.concatenate([t[:500], 5.0 + t]), "v": 10.0 + np.r_[np.zeros(500), frame.y_nmp]})
    path = tmp_path / "shifted.csv"
    shifted.to_csv(path, index=False)
    out = tmp_path / "m.csv"
    result = runner.invoke(
        app, ["metrics", str(path), "--time", "s", "--signal", "v", "--t-step", "5", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    written = _written(out, "v")
    ts, back = pd.read_csv(path)["s"].to_numpy(), pd.read_csv(path)["v"].to_numpy()
    assert written == step_info(ts, back, t_step=5.0)
    base = step_info(t, frame.y_nmp.to_numpy())  # the same response from t = 0 at 0
    for key in ("rise_time", "settling_time", "overshoot", "undershoot"):
        assert written[key] == pytest.approx(base[key], abs=1e-6), key
    assert written["undershoot"] > 25.0 and written["steady_state_value"] == pytest.approx(9.0, abs=1e-3)


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


BAD_CASES = [
    # (id, CSV text or None for no file, extra arguments, key, value shown (FILE: its name), words of the message)
    ("missing_file", None, ["--signal", "y"], "FILE", "missing.csv", "no such file"),
    ("missing_column", "t,y,u\n0,0,1\n1,1,1\n2,1,1\n", ["--signal", "yy"], "--signal", "yy", "allowed: y, u"),
    ("missing_time", "time,y\n0,0\n1,1\n2,1\n", ["--signal", "y"], "--time", "t", "allowed: time, y"),
    ("no_signal", "t,note\n0,a\n1,b\n2,c\n", [], "--signal", "(missing)", "no column of numbers besides t"),
    ("non_numeric", "t,y,u\n0,0,a\n1,1,b\n2,1,c\n", ["--signal", "u"], "--signal", "u", "not numeric"),
    ("empty_value", "t,y\n0,0\n1,\n2,1\n", ["--signal", "y"], "--signal", "y", "data row 2"),
    ("time_not_increasing", "t,y\n0,0\n1,1\n1,1\n3,1\n", ["--signal", "y"], "--time", "t", "strictly increasing"),
    ("time_not_numeric", "t,y\n0,0\nx,1\n3,1\n", ["--signal", "y"], "--time", "t", "not numeric"),
    ("two_samples", "t,y\n0,0\n1,1\n", ["--signal", "y"], "FILE", "bad.csv", "at least 3 samples"),
    ("t_step_outside", "t,y\n0,0\n1,1\n2,1\n3,1\n", ["--signal", "y", "--t-step", "2"], "--t-step", "2", "<= 1"),
    ("t_step_before", "t,y\n0,0\n1,1\n2,1\n3,1\n", ["--signal", "y", "--t-step", "-1"], "--t-step", "-1", "0 <="),
    ("reference_nan", "t,y\n0,0\n1,1\n2,1\n", ["--signal", "y", "--reference", "nan"], "--reference", "nan", "finite"),
    ("not_csv", "", ["--signal", "y"], "FILE", "bad.csv", "not readable as CSV"),
    ("reference_column", "t,y,y_rf\n0,0,1\n1,1,1\n2,1,1\n", ["--reference", "y_ref"], "--reference", "y_ref",
     "did you mean 'y_rf'?"),
    ("reference_text", "t,y,r\n0,0,1\n1,1,a\n2,1,1\n", ["--reference", "r"], "--reference", "r", "data row 2"),
    ("band", "t,y\n0,0\n1,1\n2,1\n", ["--settling-band", "1.5"], "--settling-band", "1.5", "0 < band < 1"),
    ("rise_limits", "t,y\n0,0\n1,1\n2,1\n", ["--rise-limits", "0.9", "0.1"], "--rise-limits", "0.9 0.1",
     "LOW < HIGH"),
    ("ss_window", "t,y\n0,0\n1,1\n2,1\n", ["--ss-window", "0"], "--ss-window", "0", "a time > 0 s"),
    ("controller_short", "t,controller,y\n0,a,0\n1,a,1\n2,a,1\n0,b,0\n1,b,1\n", [], "FILE", "bad.csv",
     "2 sample(s) of controller b"),
    ("controller_back", "t,controller,y\n0,a,0\n1,a,1\n2,a,1\n0,b,0\n2,b,1\n1,b,1\n", [], "--time", "t",
     "controller b, data row 6: 1 after 2"),
]  # fmt: skip


@pytest.mark.parametrize(
    ("text", "args", "key", "value", "words"), [c[1:] for c in BAD_CASES], ids=[c[0] for c in BAD_CASES]
)
def test_bad_input_is_one_line_naming_the_key(
    tmp_path: Path, text: str | None, args: list[str], key: str, value: str, words: str
) -> None:
    path = tmp_path / "missing.csv" if text is None else _write(tmp_path / "bad.csv", text)
    out = tmp_path / "metrics.csv"
    result = runner.invoke(app, ["metrics", str(path), *args, "--out", str(out)])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, lines
    shown = str(tmp_path / value) if key == "FILE" else value
    assert lines[0].startswith(f"metrics error: {key} = {shown}: "), lines[0]
    assert words in lines[0] and "; allowed: " in lines[0]
    assert not out.exists() and result.stdout == ""


def test_console_entry_end_to_end(rig_csv: Path, tmp_path: Path) -> None:
    """``python -m nlcx.cli`` (what the ``nlcx`` script runs) in a fresh process."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    nlcx = [sys.executable, "-m", "nlcx.cli", "metrics", str(rig_csv), "--time", "time"]
    out = tmp_path / "m.csv"
    ok = subprocess.run([*nlcx, "--signal", "y_nmp", "--out", str(out)], capture_output=True, text=True, env=env)
    assert ok.returncode == 0, ok.stderr
    t, frame = _read(rig_csv)
    assert _written(out, "y_nmp") == step_info(t, frame.y_nmp.to_numpy())
    bad = subprocess.run([*nlcx, "--signal", "yy"], capture_output=True, text=True, env=env)
    assert bad.returncode == 2
    assert bad.stderr.splitlines() == [
        "metrics error: --signal = yy: not a column of data.csv (did you mean 'y'?); allowed: y, y_nmp, u, note"
    ]


# ----------------------------------------------------------------------------- nlcx's own time series

STEP_KEYS = ("rise_time", "settling_time", "overshoot", "undershoot", "peak", "peak_time")
REGULATION_KEYS = ("peak_deviation", "peak_time", "settling_time", "steady_state_error")


@pytest.fixture(scope="module", params=["csv", "parquet"])
def own_run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``nlcx run configs/x_error_ags.yaml``: two controllers stacked in one time series, x
    stepping to 1 (x_ref), theta regulated to 0 (theta_ref); as CSV and as Parquet."""
    out = tmp_path_factory.mktemp(f"run_{request.param}")
    args = ["run", str(ROOT / "configs" / "x_error_ags.yaml"), f"outputs.timeseries_format={request.param}"]
    result = runner.invoke(app, [*args, "outputs.figure=false", "--no-report", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out / f"timeseries.{request.param}"


def _long(path: Path) -> pd.DataFrame:
    return pd.read_csv(path, keep_default_na=False, na_values=[""])


def test_own_time_series_are_measured_per_controller_as_the_run_measured_them(own_run: Path, tmp_path: Path) -> None:
    """Every controller's x step metrics and theta regulation metrics equal those nlcx run wrote
    (its defaults are the command's: 2 % band, 10-90 % rise, 1 s window)."""
    out = tmp_path / "m.csv"
    result = runner.invoke(app, ["metrics", str(own_run), "--out", str(out)])
    assert result.exit_code == 0, result.output
    ours = _long(out)
    assert list(ours.columns) == ["controller", "signal", "metric", "value", "unit", "note"]
    theirs = _long(own_run.parent / "metrics.csv")
    assert list(dict.fromkeys(ours.controller)) == ["conventional", "proposed"]
    assert set(ours.signal) == {"x", "theta"}  # the signals with a reference column, not F_x or the logs
    for controller in ("conventional", "proposed"):
        mine = ours[ours.controller == controller].set_index(["signal", "metric"]).value
        run = theirs[theirs.controller == controller].set_index(["signal", "metric"]).value
        for key in STEP_KEYS:
            assert mine["x", key] == pytest.approx(run["x", key], rel=1e-9, abs=0), (controller, key)
        assert mine["x", "steady_state_value"] == 1.0  # x_ref's final value: the config's step to 1
        assert sorted(mine["theta"].index) == sorted(REGULATION_KEYS)  # no step metrics for theta
        for key in REGULATION_KEYS:
            assert mine["theta", key] == pytest.approx(run["theta", key], rel=1e-9, abs=0), (controller, key)
    theta = ours[ours.signal == "theta"]
    assert (theta.note == "regulated: theta_ref is constant 0").all()
    notes = [line for line in result.stdout.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "regulated" in notes[0] and "theta (theta_ref is constant 0)" in notes[0]
    assert "x (" not in notes[0]


def test_peak_deviation_is_the_largest_angle_of_each_controller(own_run: Path, tmp_path: Path) -> None:
    """Independently: max |theta| over each controller's rows of the time series."""
    out = tmp_path / "m.csv"
    result = runner.invoke(app, ["metrics", str(own_run), "--signal", "theta", "--out", str(out)])
    assert result.exit_code == 0, result.output
    series = pd.read_parquet(own_run) if own_run.suffix == ".parquet" else pd.read_csv(own_run)
    ours = _long(out)
    for controller, rows in series.groupby("controller"):
        peak = ours[(ours.controller == controller) & (ours.metric == "peak_deviation")].value.item()
        k = int(np.argmax(np.abs(rows.theta.to_numpy())))
        assert peak == abs(rows.theta.iloc[k])
        at = ours[(ours.controller == controller) & (ours.metric == "peak_time")].value.item()
        assert at == rows.t.iloc[k] - rows.t.iloc[0]
    # the printed table: one per controller, theta's peak deviation in it
    assert result.stdout.count("controller conventional:") == 1 and result.stdout.count("controller proposed:") == 1
    assert "overshoot" not in result.stdout


def _first_order(t: np.ndarray, t_step: float, tau: float) -> np.ndarray:
    return np.where(t >= t_step, -np.expm1(-(t - t_step) / tau), 0.0)


def test_a_reference_column_that_steps_gives_the_step_time(tmp_path: Path) -> None:
    """y = 1 - exp(-(t - 2)/tau) after a step of y_ref at t = 2 s: 10-90 % rise time tau ln 9 and
    2 % settling time tau ln 50 (analytic), measured from the step the reference column shows."""
    t = np.round(np.arange(0, 12.0001, 1e-3), 9)
    tau = 0.5
    frame = pd.DataFrame({"t": t, "y": _first_order(t, 2.0, tau), "y_ref": np.where(t >= 2.0, 1.0, 0.0)})
    path = tmp_path / "step.csv"
    frame.to_csv(path, index=False)
    out = tmp_path / "m.csv"
    result = runner.invoke(app, ["metrics", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "step at 2 s; final value: y_ref = 1" in result.stdout
    values = _long(out).set_index("metric").value
    assert values["rise_time"] == pytest.approx(tau * np.log(9), abs=1e-5)
    assert values["settling_time"] == pytest.approx(tau * np.log(50), abs=1e-5)
    assert values["overshoot"] == 0.0 and values["steady_state_value"] == 1.0
    explicit = runner.invoke(app, ["metrics", str(path), "--t-step", "0", "--signal", "y"])
    assert "step at 0 s" in explicit.stdout  # --t-step overrides what the column shows


def test_a_varying_reference_is_tracked(tmp_path: Path) -> None:
    """A sine reference: error integrals of y_ref - y (trapezoidal, computed here), no step metrics."""
    t = np.linspace(0.0, 10.0, 2001)
    ref = 0.3 * np.sin(0.5 * t)
    y = 0.3 * np.sin(0.5 * t - 0.1)
    path = tmp_path / "track.csv"
    pd.DataFrame({"t": t, "y": y, "y_ref": ref}).to_csv(path, index=False)
    out = tmp_path / "m.csv"
    result = runner.invoke(app, ["metrics", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    values = _long(out).set_index("metric").value
    y_read = pd.read_csv(path)
    e = (y_read.y_ref - y_read.y).to_numpy()
    assert values["ise"] == pytest.approx(np.sum(np.diff(t) * (e[1:] ** 2 + e[:-1] ** 2) / 2), rel=1e-12)
    assert values["max_abs_error"] == np.max(np.abs(e))
    assert "rise_time" not in values and "note: measured as tracking: y (y_ref varies" in result.stdout


def test_plain_csv_measures_every_column_of_numbers(rig_csv: Path, tmp_path: Path) -> None:
    """No --signal and no reference column: every column of numbers but time, each against its
    last sample, written as for any plain CSV (signal, metric, value, unit)."""
    out = tmp_path / "m.csv"
    result = runner.invoke(app, ["metrics", str(rig_csv), "--time", "time", "--out", str(out)])
    assert result.exit_code == 0, result.output
    table = pd.read_csv(out)
    assert list(table.columns) == ["signal", "metric", "value", "unit"]
    assert list(dict.fromkeys(table.signal)) == ["y", "y_nmp", "u"]  # not the text column
    t, frame = _read(rig_csv)
    for name in ("y", "y_nmp"):
        assert _written(out, name) == step_info(t, frame[name].to_numpy())
    assert "note:" not in result.stdout


def test_reference_from_a_column(rig_csv: Path, tmp_path: Path) -> None:
    """--reference COLUMN: the column's (constant) value as the target, the same numbers as
    --reference VALUE; a column that is constant 0 measures the signal as regulated."""
    t, frame = _read(rig_csv)
    path = tmp_path / "with_target.csv"
    frame.assign(target=2.5, zero=0.0).to_csv(path, index=False)
    by_number, by_column = tmp_path / "n.csv", tmp_path / "c.csv"
    args = ["metrics", str(path), "--time", "time", "--signal", "y"]
    assert runner.invoke(app, [*args, "--reference", "2.5", "--out", str(by_number)]).exit_code == 0
    assert runner.invoke(app, [*args, "--reference", "target", "--out", str(by_column)]).exit_code == 0
    assert _written(by_column, "y") == _written(by_number, "y") == step_info(t, frame.y.to_numpy(), reference=2.5)
    regulated = runner.invoke(app, [*args, "--reference", "zero", "--out", str(tmp_path / "z.csv")])
    assert regulated.exit_code == 0, regulated.output
    values = _long(tmp_path / "z.csv").set_index("metric").value
    assert values["peak_deviation"] == np.max(np.abs(frame.y.to_numpy()))
    assert "overshoot" not in values and "y (zero is constant 0)" in regulated.stdout

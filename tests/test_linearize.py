"""nlcx.linearize and ``nlcx linearize``: the plant's linear model, the frozen gains, the
closed-loop poles and the margins, each checked against a computation made here by hand
(the x pendulum's equations 2.8-2.11 linearised on paper, eqs. 2.17-2.22, the characteristic
polynomial of a PID on a transfer function, python-control's ``margin`` on a loop transfer
built here from those pieces)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import control as ct
import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

import nlcx
from nlcx.analysis import linearize_along
from nlcx.analysis.frozen import FrozenPoint, parse_at
from nlcx.cli import app
from nlcx.config import read_config
from nlcx.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
X_ERROR = ROOT / "configs" / "x_error_ags.yaml"
X_TIME = ROOT / "configs" / "x_time_ags.yaml"
CSTR_TF = ROOT / "configs" / "thesis" / "ch5" / "plant.yaml"
runner = CliRunner()


def _yaml(path: Path) -> dict[str, Any]:
    return yaml.safe_load(path.read_text())


def x_pendulum_by_hand(M: float, m: float, l: float, g: float) -> tuple[np.ndarray, np.ndarray]:
    """A and B of eqs. 2.8-2.11 about the upright rest (x3 = theta = 0, x4 = 0, F_x = 0).

    With s = sin x3 ~ x3, cos x3 ~ 1 and the x4^2 terms of second order:
    eq. 2.9:  x2' = (-m g x3 + F_x) / M
    eq. 2.11: x4' = (-F_x + (M + m) g x3) / (M l)"""
    A = np.array([
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, -m * g / M, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, (M + m) * g / (M * l), 0.0],
    ])  # fmt: skip
    B = np.array([[0.0], [1.0 / M], [0.0], [-1.0 / (M * l)]])
    return A, B


def error_ags_by_hand(schedule: dict[str, Any], e: float) -> tuple[float, float, float]:
    """Eqs. 2.20-2.22 on s = |e| (the configs' ``error: abs``)."""
    s = abs(e)
    kp, ki, kd, rate = schedule["kp"], schedule["ki"], schedule["kd"], schedule["rate"]
    return (
        kp["max"] - (kp["max"] - kp["min"]) * math.exp(-rate["kp"] * s),
        ki["min"] - (ki["min"] - ki["max"]) * math.exp(-rate["ki"] * s),
        kd["max"] - (kd["max"] - kd["min"]) * math.exp(-rate["kd"] * s),
    )


def time_ags_by_hand(schedule: dict[str, Any], t: float) -> tuple[float, float, float]:
    """Eqs. 2.17-2.19."""
    kp, ki, kd, rate = schedule["kp"], schedule["ki"], schedule["kd"], schedule["rate"]
    return (
        kp["min"] + (kp["max"] - kp["min"]) * math.exp(-rate["kp"] * t),
        ki["max"] - (ki["max"] - ki["min"]) * math.exp(-rate["ki"] * t),
        kd["min"] + (kd["max"] - kd["min"]) * math.exp(-rate["kd"] * t),
    )


def _gains(lin: Any, loop: str) -> tuple[float, float, float]:
    row = lin.gains.set_index("loop").loc[loop]
    return float(row.kp), float(row.ki), float(row.kd)


# --------------------------------------------------------------------------- (1) the plant


def test_the_x_pendulum_linearised_equals_eqs_2_8_to_2_11_linearised_by_hand() -> None:
    params = _yaml(X_ERROR)["plant"]["params"]
    A, B = x_pendulum_by_hand(params["M"], params["m"], params["l"], params["g"])
    lin = nlcx.linearize(X_ERROR, "proposed")
    assert lin.plant.state_labels == ["x", "x_dot", "theta", "theta_dot"]
    assert (lin.plant.input_labels, lin.plant.output_labels) == (["F_x"], ["x", "theta"])
    np.testing.assert_allclose(lin.plant.A, A, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(lin.plant.B, B, rtol=1e-7, atol=1e-7)
    np.testing.assert_array_equal(lin.plant.C, [[1, 0, 0, 0], [0, 0, 1, 0]])
    np.testing.assert_array_equal(lin.plant.D, [[0], [0]])


# --------------------------------------------------------------------------- (5) frozen gains


@pytest.mark.parametrize("e", [0.0, 0.5, -0.8])
def test_error_ags_frozen_at_e_gives_the_gains_of_eqs_2_20_to_2_22(e: float) -> None:
    loops = _yaml(X_ERROR)["controllers"]["proposed"]["loops"]
    lin = nlcx.linearize(X_ERROR, "proposed", at=f"e={e}")
    assert lin.at == FrozenPoint(t=0.0, e=e)
    for name in ("theta", "x"):
        np.testing.assert_allclose(_gains(lin, name), error_ags_by_hand(loops[name]["schedule"], e), rtol=1e-12)


def test_time_ags_frozen_at_t_gives_the_gains_of_eqs_2_17_to_2_19() -> None:
    loops = _yaml(X_TIME)["controllers"]["proposed"]["loops"]
    lin = nlcx.linearize(X_TIME, "proposed", at={"t": 3.0})
    for name in ("theta", "x"):
        np.testing.assert_allclose(_gains(lin, name), time_ags_by_hand(loops[name]["schedule"], 3.0), rtol=1e-12)


def test_the_frozen_gains_are_those_the_simulation_logs_at_that_error() -> None:
    """The PID logs k_p at every sample: where x's error passes 0.5 (theta's error is then
    small but not 0, so only the x loop is compared), the logged gains are the frozen ones."""
    frame = nlcx.run(X_ERROR).trajectory("proposed")
    error = (frame.x_ref - frame.x).to_numpy()
    k = int(np.argmin(np.abs(error - 0.5)))
    lin = nlcx.linearize(X_ERROR, "proposed", at={"e": float(error[k])})
    logged = frame.loc[k, ["x.kp", "x.ki", "x.kd"]].to_numpy(dtype=float)
    np.testing.assert_allclose(_gains(lin, "x"), logged, rtol=1e-12)


# --------------------------------------------------------------------------- (2) the margins


def _loop_transfers_by_hand(e: float) -> dict[str, ct.TransferFunction]:
    """L(s) of the x pendulum under the proposed PID frozen at e, broken at F_x: the theta
    loop (x closed), the x loop (theta closed), and both together, built from the hand
    linearisation, eqs. 2.20-2.22 and the backward difference's N = 2/dt."""
    raw = _yaml(X_ERROR)
    params, loops = raw["plant"]["params"], raw["controllers"]["proposed"]["loops"]
    A, B = x_pendulum_by_hand(params["M"], params["m"], params["l"], params["g"])
    N = 2.0 / raw["simulation"]["dt"]
    s = ct.tf("s")
    plants, pids = {}, {}
    for name, row in (("x", 0), ("theta", 2)):
        C = np.zeros((1, 4))
        C[0, row] = 1.0
        plants[name] = ct.tf(ct.ss(A, B, C, 0))
        kp, ki, kd = error_ags_by_hand(loops[name]["schedule"], e)
        pids[name] = loops[name]["sign"] * (kp + ki / s + kd * N * s / (s + N))
    return {
        "theta": pids["theta"] * plants["theta"] / (1 + pids["x"] * plants["x"]),
        "x": pids["x"] * plants["x"] / (1 + pids["theta"] * plants["theta"]),
        "F_x": pids["theta"] * plants["theta"] + pids["x"] * plants["x"],
    }


def test_the_margins_are_python_controls_on_the_loop_transfer_built_by_hand() -> None:
    lin = nlcx.linearize(X_ERROR, "proposed", at="e=0.5")
    table = lin.margins.set_index("name")
    assert list(lin.margins.opening) == ["loop", "loop", "input"]
    for name, transfer in _loop_transfers_by_hand(0.5).items():
        with np.errstate(invalid="ignore"):  # python-control compares NaN crossings with 0
            gm, pm, wpc, wgc = ct.margin(transfer)
        row = table.loc[name]
        got = (row.gain_margin, row.phase_margin, row.gain_margin_frequency, row.phase_margin_frequency)
        np.testing.assert_allclose(got, (gm, pm, wpc, wgc), rtol=1e-6)
        w = np.array([0.3, 2.0, 9.0])
        np.testing.assert_allclose(lin.loop_transfers[name](1j * w), transfer(1j * w), rtol=1e-7)


def test_the_loop_broken_where_the_theta_loop_enters_has_the_open_loop_poles_of_the_pendulum() -> None:
    """Broken at the theta loop, the x loop closed around the pendulum: python-control's count
    of the loop transfer's right half-plane poles is reported for the Nyquist criterion."""
    lin = nlcx.linearize(X_ERROR, "proposed", at="e=0.5")
    transfer = _loop_transfers_by_hand(0.5)["theta"]
    unstable = int(np.sum(ct.poles(ct.minreal(transfer, verbose=False)).real > 1e-6))
    assert lin.margins.set_index("name").loc["theta", "rhp_poles"] == unstable


# --------------------------------------------------------------------------- (3) the poles


def _cstr_with(pid: dict[str, Any]) -> dict[str, Any]:
    raw = read_config(CSTR_TF)
    return {**raw, "name": "cstr_tf_pid", "controllers": {"pid": {"kind": "pid", **pid}}}


@pytest.mark.parametrize(
    ("derivative", "form"),
    [({"method": "filtered", "N": 40.0}, "parallel"), ({"method": "backward"}, "parallel"),
     ({"method": "filtered", "N": 40.0}, "ideal"), ({"method": "filtered", "N": 40.0}, "series")],
)  # fmt: skip
def test_closed_loop_poles_on_a_transfer_function_are_the_roots_of_its_characteristic_polynomial(
    derivative: dict[str, Any], form: str
) -> None:
    """G(s) = num/den under k_p + k_i/s + k_d N s/(s + N): the poles are the roots of
    den s (s + N) + num (k_p s (s + N) + k_i (s + N) + k_d N s^2), with the form's parameters
    turned into parallel gains by hand and N = 2/dt for the backward difference."""
    kp, ki, kd = 2.0, 3.0, 0.4
    raw = _cstr_with({"derivative": derivative, "form": form, "loops": {"C_B": {"schedule": {
        "kind": "constant", "kp": kp, "ki": ki, "kd": kd}}}})  # fmt: skip
    lin = nlcx.linearize(raw)
    parallel = {
        "parallel": (kp, ki, kd),
        "ideal": (kp, kp * ki, kp * kd),  # k_p (1 + k_i/s + k_d s)
        "series": (kp * (1 + ki * kd), kp * ki, kp * kd),  # k_p (1 + k_i/s)(1 + k_d s)
    }[form]
    np.testing.assert_allclose(_gains(lin, "C_B"), parallel, rtol=1e-15)
    N = derivative.get("N", 2.0 / raw["simulation"]["dt"])
    num, den = np.array(raw["plant"]["params"]["num"]), np.array(raw["plant"]["params"]["den"])
    Kp, Ki, Kd = parallel
    controller_num = np.polyadd(np.polyadd(Kp * np.array([1.0, N, 0.0]), Ki * np.array([1.0, N])), [Kd * N, 0.0, 0.0])
    characteristic = np.polyadd(np.polymul(den, [1.0, N, 0.0]), np.polymul(num, controller_num))
    expected = np.sort_complex(np.roots(characteristic))
    got = np.sort_complex(lin.poles.real.to_numpy() + 1j * lin.poles.imag.to_numpy())
    np.testing.assert_allclose(got, expected, rtol=1e-8)
    omega = np.abs(expected)
    np.testing.assert_allclose(np.sort(lin.poles.omega_n), np.sort(omega), rtol=1e-8)
    assert lin.stable == bool(np.all(expected.real < 0))


def test_a_pi_loop_has_no_derivative_state_and_its_poles_are_those_of_the_pi_loop() -> None:
    raw = _cstr_with({"loops": {"C_B": {"schedule": {"kind": "constant", "kp": 1.5, "ki": 2.0}}}})
    lin = nlcx.linearize(raw)
    assert lin.controller.state_labels == ["pid_C_B_integral"]
    num, den = np.array(raw["plant"]["params"]["num"]), np.array(raw["plant"]["params"]["den"])
    characteristic = np.polyadd(np.polymul(den, [1.0, 0.0]), np.polymul(num, [1.5, 2.0]))
    got = np.sort_complex(lin.poles.real.to_numpy() + 1j * lin.poles.imag.to_numpy())
    np.testing.assert_allclose(got, np.sort_complex(np.roots(characteristic)), rtol=1e-9)


def test_the_closed_loop_maps_the_reference_to_the_output_with_unit_gain_at_steady_state() -> None:
    """With integral action the closed loop's DC gain from C_B_ref to C_B is 1."""
    raw = _cstr_with({"loops": {"C_B": {"schedule": {"kind": "constant", "kp": 1.5, "ki": 2.0, "kd": 0.1}}}})
    lin = nlcx.linearize(raw)
    assert lin.closed_loop.input_labels == ["C_B_ref"]
    assert lin.closed_loop.output_labels == ["C_B", "u"]
    assert lin.closed_loop(0.0)[0, 0] == pytest.approx(1.0, rel=1e-9)


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("at", ["x=1", "t=", "t=abc", "t=-1", "e=inf", "t2", {"q": 1.0}, 3.0])
def test_a_malformed_frozen_point_is_one_config_error(at: Any) -> None:
    with pytest.raises(ConfigError, match=r"^config error: at = .*allowed: t=T"):
        parse_at(at)


def test_the_frozen_point_forms() -> None:
    assert parse_at(None) == (FrozenPoint(0.0, 0.0), ())
    assert parse_at("t=2.5") == (FrozenPoint(2.5, 0.0), ("t",))
    assert parse_at(" e = -0.25 ") == (FrozenPoint(0.0, -0.25), ("e",))
    assert parse_at({"e": 1, "t": 2}) == (FrozenPoint(2.0, 1.0), ("t", "e"))


def test_bad_arguments_are_one_config_error_each() -> None:
    with pytest.raises(ConfigError, match="controller = 'nope': not a controller of x_error_ags; allowed"):
        nlcx.linearize(X_ERROR, "nope")
    with pytest.raises(ConfigError, match="at = 't=2': the gains of controller 'proposed' do not vary with t"):
        nlcx.linearize(X_ERROR, "proposed", at="t=2")
    with pytest.raises(ConfigError, match=r"along = 'e': .* 'conventional' .* its gains are constant"):
        linearize_along(X_ERROR, "e", "conventional")
    with pytest.raises(ConfigError, match="points = 1: frozen points along the axis; allowed: an integer from 2 to"):
        linearize_along(X_ERROR, "e", points=1)


# --------------------------------------------------------------------------- (4) the command


def _run(*args: str) -> Any:
    return runner.invoke(app, ["linearize", *args])


@pytest.mark.slow
def test_the_command_writes_the_analysis_and_its_sweep(tmp_path: Path) -> None:
    out = tmp_path / "lin"
    done = _run(str(X_ERROR), "--controller", "proposed", "--at", "e=0.5", "--along", "e", "--points", "5",
                "--out", str(out))  # fmt: skip
    assert done.exit_code == 0, done.output
    assert "controller proposed, frozen at e = 0.5" in done.output and f"wrote {out}/" in done.output
    assert {p.name for p in out.iterdir()} == {
        "poles.csv", "margins.csv", "gains.csv", "poles_along.csv", "margins_along.csv", "gains_along.csv",
        "along.png", "config.yaml", "manifest.json", ".nlcx-output",
    }  # fmt: skip
    lin = nlcx.linearize(X_ERROR, "proposed", at="e=0.5")
    poles = pd.read_csv(out / "poles.csv")
    assert list(poles.columns) == ["real", "imag", "zeta", "omega_n"]
    np.testing.assert_array_equal(poles[["real", "imag", "omega_n"]], lin.poles[["real", "imag", "omega_n"]])
    margins = pd.read_csv(out / "margins.csv")
    np.testing.assert_array_equal(margins.gain_margin, lin.margins.gain_margin)
    along = pd.read_csv(out / "margins_along.csv")
    assert list(along.e.unique()) == [0.0, 0.25, 0.5, 0.75, 1.0]  # up to the unit step in x
    gains = pd.read_csv(out / "gains_along.csv").query("loop == 'theta'")
    schedule = _yaml(X_ERROR)["controllers"]["proposed"]["loops"]["theta"]["schedule"]
    np.testing.assert_allclose(gains.kp, [error_ags_by_hand(schedule, e)[0] for e in gains.e], rtol=1e-12)
    manifest = json.loads((out / "manifest.json").read_text())
    assert (manifest["nlcx_output"], manifest["controller"], manifest["at"]) == ("linearize", "proposed",
                                                                               {"t": 0.0, "e": 0.5})  # fmt: skip
    assert manifest["along"] == {"axis": "e", "from": 0.0, "to": 1.0, "points": 5}
    assert set(manifest["files"]) == {p.name for p in out.iterdir()} - {"manifest.json", ".nlcx-output"}
    assert yaml.safe_load((out / "config.yaml").read_text())["name"] == "x_error_ags"
    again = _run(str(X_ERROR), "--controller", "conventional", "--out", str(out))
    assert again.exit_code == 0, again.output
    assert {p.name for p in out.iterdir()} == {
        "poles.csv", "margins.csv", "gains.csv", "config.yaml", "manifest.json", ".nlcx-output"
    }  # fmt: skip


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--controller", "nope"], "config error: --controller = 'nope': not a controller of x_error_ags"),
        (["--at", "x=1"], "config error: --at = 'x=1': allowed: t=T"),
        (["--along", "t"], "config error: --along = 't': the gains of controller 'proposed' do not vary with t"),
    ],
)
def test_the_command_reports_bad_options_in_one_line(args: list[str], line: str, tmp_path: Path) -> None:
    done = _run(str(X_ERROR), *args, "--out", str(tmp_path / "lin"))
    assert done.exit_code == 2
    assert done.output.strip().startswith(line) and len(done.output.strip().splitlines()) == 1
    assert not (tmp_path / "lin").exists()

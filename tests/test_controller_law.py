"""Controllers of one's own: a law in plain Python (``@nlcx.controller``), the LQR, pole-placement
and state-feedback baselines, sliding mode, plugins named by a config's ``imports:``, and
python-control both ways (``nlcx.plants.from_control``, ``Result.response``), each against an
independent computation."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import control as ct
import numpy as np
import pandas as pd
import pytest
import scipy.linalg
import yaml
from typer.testing import CliRunner

import nlcx
from nlcx import registry
from nlcx.cli import app
from nlcx.controllers.sliding_mode import surface_for_poles
from nlcx.errors import ConfigError
from nlcx.plants import from_control

ROOT = Path(__file__).resolve().parent.parent
M, m, l, g = 1.0, 0.1, 0.3, 9.8  # Table 2.1
runner = CliRunner()
#: An LQR-with-integral gain for the x pendulum (Q = diag(1, 0, 1, 0, 1), R = 1 on its linear model).
K = (-2.69413428, -3.12917975, -30.50414309, -5.15983692, -1.0)


def _printed_rhs(x: np.ndarray, F: float) -> np.ndarray:
    """Eqs. 2.8-2.11 of the thesis, written out here."""
    s, c = math.sin(x[2]), math.cos(x[2])
    den = M + m * s * s
    return np.array([
        x[1],
        (-m * g * c * s + m * l * s * x[3] * x[3] + F) / den,
        x[3],
        (-m * l * c * s * x[3] * x[3] - c * F + (M + m) * g * s) / (l * den),
    ])  # fmt: skip


def _integrals(states: list[np.ndarray], dt: float) -> list[float]:
    """The law's integrator as updated at each control step (as it is logged): z_{k+1} = z_k + dt (x_k - 1)."""
    z, out = 0.0, []
    for x in states[:-1]:
        z += dt * (x[0] - 1.0)
        out.append(z)
    return out


def _lqi(x: np.ndarray, r: float, z: float, dt: float) -> tuple[float, float]:
    """The law of the test, written out: u = -K (x - x_ref) - K_i z, z += dt (x - r)."""
    u = -(K[0] * (x[0] - r) + K[1] * x[1] + K[2] * x[2] + K[3] * x[3] + K[4] * z)
    return u, z + dt * (x[0] - r)


@pytest.fixture(scope="module")
def lqi() -> str:
    gains = dict(zip(("k1", "k2", "k3", "k4", "ki"), K, strict=True))

    @nlcx.controller("test_lqi", measures=["x", "x_dot", "theta", "theta_dot"], references=["x", "theta"],
                     inputs=["F_x"], states={"z": 0.0}, params=gains)  # fmt: skip
    def law(t, dt, y, r, s, p):  # type: ignore[no-untyped-def]  # numba types the law
        u = -(p.k1 * (y[0] - r[0]) + p.k2 * y[1] + p.k3 * y[2] + p.k4 * y[3] + p.ki * s[0])
        return (u,), (s[0] + dt * (y[0] - r[0]),)

    return "test_lqi"


def _config(controllers: dict[str, object], t_end: float = 5.0, **extra: object) -> dict[str, object]:
    return {"name": "law", "plant": {"name": "x_pendulum"}, "controllers": controllers,
            "reference": {"x": {"kind": "step", "final": 1.0}}, "simulation": {"t_end": t_end, "dt": 1e-3},
            **extra}  # fmt: skip


def test_a_plain_python_law_is_the_hand_written_loop(lqi: str) -> None:
    """An LQR-with-integral law on the x pendulum equals an RK4 loop written out here (eqs.
    2.8-2.11, the input held over each step, the integrator stepped by forward Euler) within 1e-9."""
    result = nlcx.run(_config({"lqi": {"kind": lqi}}))
    frame = result.trajectory("lqi")
    dt, n = 1e-3, len(frame) - 1
    x, z = np.zeros(4), 0.0
    states, forces = [x.copy()], []
    for _ in range(n):
        u, z = _lqi(x, 1.0, z, dt)
        k1 = _printed_rhs(x, u)
        k2 = _printed_rhs(x + dt / 2 * k1, u)
        k3 = _printed_rhs(x + dt / 2 * k2, u)
        k4 = _printed_rhs(x + dt * k3, u)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        states.append(x.copy())
        forces.append(u)
    np.testing.assert_allclose(frame[["x", "x_dot", "theta", "theta_dot"]].to_numpy(), np.array(states), atol=1e-9)
    np.testing.assert_allclose(frame.F_x.to_numpy()[:-1], forces, atol=1e-9)
    np.testing.assert_allclose(frame["test_lqi.z"].to_numpy()[:-1], _integrals(states, dt), atol=1e-9)


def test_a_law_that_returns_the_wrong_shape_is_one_line_at_registration() -> None:
    with pytest.raises(ConfigError, match=r"controller = 'bad_shape': its law returned \(\(0\.0, 0\.0\), \(\)\)"):

        @nlcx.controller("bad_shape", measures=["x"], references=["x"], inputs=["F_x"])
        def two_inputs(t, dt, y, r, s, p):  # type: ignore[no-untyped-def]
            return (0.0, 0.0), ()

    with pytest.raises(ConfigError, match=r"controller = 'bad_arity': its law cannot be compiled or called"):

        @nlcx.controller("bad_arity", measures=["x"], references=["x"], inputs=["F_x"])
        def five(t, dt, y, r, s):  # type: ignore[no-untyped-def]
            return (0.0,), ()

    with pytest.raises(ConfigError, match=r"params = 'kind': a Python identifier"):
        nlcx.controller("bad_param", measures=[], references=[], inputs=["F_x"], params={"kind": 1.0})


def test_an_unknown_signal_is_one_line_naming_the_controller(lqi: str) -> None:
    @nlcx.controller("needs_psi", measures=["psi"], references=[], inputs=["F_x"])
    def law(t, dt, y, r, s, p):  # type: ignore[no-untyped-def]
        return (0.0,), ()

    with pytest.raises(ConfigError, match=r"controllers\.c = 'needs_psi': measures 'psi', which x_pendulum has not; "
                       r"allowed: its outputs and states \(x, theta, x_dot, theta_dot\)"):  # fmt: skip
        nlcx.run(_config({"c": {"kind": "needs_psi"}}))


def test_a_sampled_law_holds_its_input_between_calls() -> None:
    """sample_time = 0.05 s: the law runs every 50 integration steps, dt its period, and its
    input is held in between."""

    @nlcx.controller("every_50", measures=["theta"], references=[], inputs=["F_x"], states={"n": 0.0},
                     sample_time=0.05)  # fmt: skip
    def law(t, dt, y, r, s, p):  # type: ignore[no-untyped-def]
        return (100.0 * dt * (s[0] + 1.0),), (s[0] + 1.0,)

    config = _config({"c": {"kind": "every_50"}}, reference={}, simulation={"t_end": 0.2, "bounds": {"theta": 1e9}})
    frame = nlcx.run(config).trajectory("c")
    calls = frame["every_50.n"].to_numpy()
    assert calls[0] == 1.0 and calls[49] == 1.0 and calls[50] == 2.0 and calls[-1] == 5.0
    np.testing.assert_allclose(frame.F_x.to_numpy()[:50], 5.0)  # 100 * 0.05 * 1
    np.testing.assert_allclose(frame.F_x.to_numpy()[50:100], 10.0)


def test_lqr_gain_is_the_riccati_solution_on_an_independent_linearisation() -> None:
    """kind: lqr designs K by python-control's lqr on nlcx's linearisation; here the x pendulum
    is linearised by hand about the upright position and the Riccati equation solved by scipy."""
    q, r = [1.0, 1.0, 25.0, 1.0, 1.0], [0.01]
    result = nlcx.run(_config({"lqr": {"kind": "lqr", "integral": ["x"], "q": q, "r": r}}, t_end=1.0))
    tuning = pd.DataFrame(result._source.prepared.tuning)
    gains = dict(zip(tuning.parameter, tuning.value, strict=True))
    A = np.array([[0, 1, 0, 0], [0, 0, -m * g / M, 0], [0, 0, 0, 1], [0, 0, (M + m) * g / (M * l), 0]])
    B = np.array([[0.0], [1 / M], [0.0], [-1 / (M * l)]])
    A_a = np.block([[A, np.zeros((4, 1))], [np.array([[1.0, 0, 0, 0]]), np.zeros((1, 1))]])
    B_a = np.vstack([B, [[0.0]]])
    P = scipy.linalg.solve_continuous_are(A_a, B_a, np.diag(q), np.diag(r))
    expected = np.linalg.solve(np.diag(r), B_a.T @ P)[0]
    names = ["K[F_x,x]", "K[F_x,x_dot]", "K[F_x,theta]", "K[F_x,theta_dot]", "K[F_x,z_x]"]
    np.testing.assert_allclose([float(gains[n]) for n in names], expected, rtol=1e-6)


def test_pole_placement_and_state_feedback_give_the_closed_loop_they_name() -> None:
    poles = [-2.0, -2.5, -3.0, "-3.5+1j", "-3.5-1j"]
    placed = nlcx.run(_config({"pp": {"kind": "pole_placement", "integral": ["x"], "poles": poles}}, t_end=1.0))
    tuning = pd.DataFrame(placed._source.prepared.tuning)
    got = np.sort_complex(
        [complex(v) for p, v in zip(tuning.parameter, tuning.value, strict=True) if p.startswith("pole_")]
    )
    np.testing.assert_allclose(got, np.sort_complex([complex(p) for p in poles]), atol=1e-8)
    gain = [[float(v) for p, v in zip(tuning.parameter, tuning.value, strict=True) if p.startswith("K[")]]
    given = nlcx.run(_config({"sf": {"kind": "state_feedback", "integral": ["x"], "gain": gain}}, t_end=1.0))
    np.testing.assert_array_equal(given.trajectory("sf").x.to_numpy(), placed.trajectory("pp").x.to_numpy())


def test_linearize_shows_the_lqr_gain_and_the_designed_poles() -> None:
    config = _config({"lqr": {"kind": "lqr", "integral": ["x"], "q": [1, 1, 25, 1, 1], "r": [0.01]}})
    lin = nlcx.linearize(config)
    result = nlcx.run({**config, "simulation": {"t_end": 0.01}})
    tuning = pd.DataFrame(result._source.prepared.tuning)
    designed = np.sort_complex(
        [complex(v) for p, v in zip(tuning.parameter, tuning.value, strict=True) if p.startswith("pole_")]
    )
    closed = np.sort_complex(lin.poles.real.to_numpy() + 1j * lin.poles.imag.to_numpy())
    np.testing.assert_allclose(closed, designed, rtol=1e-5)
    gains = lin.gains.set_index("of").gain
    k = dict(zip(tuning.parameter, tuning.value, strict=True))
    assert gains["theta"] == pytest.approx(-float(k["K[F_x,theta]"]), rel=1e-6)
    assert lin.stable
    printed = runner.invoke(app, ["linearize", "--help"])
    assert printed.exit_code == 0


def test_sliding_mode_reaches_its_surface_and_stays_in_the_boundary_layer() -> None:
    """From the step, S reaches the boundary layer |S| <= phi and never leaves it; x settles."""
    result = nlcx.run(_config({"smc": {"kind": "sliding_mode", "c1": 0.6, "c2": 5.4, "alpha": 1.06}}, t_end=20.0))
    frame = result.trajectory("smc")
    S, phi = frame["sliding_mode.S"].to_numpy(), 0.05
    inside = np.flatnonzero(np.abs(S) <= phi)
    assert inside.size and abs(S[0]) > phi
    assert np.all(np.abs(S[inside[0] :]) <= phi + 1e-12)
    assert abs(frame.x.iloc[-1] - 1.0) < 0.05


def test_the_sliding_surface_puts_the_motion_on_it_at_the_poles_asked() -> None:
    """surface_for_poles (Ackermann and Utkin 1998): with the equivalent control, the linear
    model's motion on S = 0 has the three poles asked for (and one at 0, off the surface)."""
    A = np.array([[0, 1, 0, 0], [0, 0, -m * g / M, 0], [0, 0, 0, 1], [0, 0, (M + m) * g / (M * l), 0]])
    B = np.array([[0.0], [1 / M], [0.0], [-1 / (M * l)]])
    poles = [-1.0, -2.0, -3.0]
    s = surface_for_poles(A, B, poles)
    sigma = np.array([[s["alpha"] * s["c1"], s["alpha"], s["c2"], 1.0]])
    equivalent = (np.eye(4) - B @ np.linalg.solve(sigma @ B, sigma)) @ A
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(equivalent).real), [-3.0, -2.0, -1.0, 0.0], atol=1e-9)


def test_sliding_mode_is_for_the_x_pendulum_only() -> None:
    config = _config({"smc": {"kind": "sliding_mode"}})
    config["plant"] = {"name": "xz_pendulum"}
    with pytest.raises(ConfigError, match="a published design exists for the x pendulum only"):
        nlcx.run(config)


PLUGIN = textwrap.dedent(
    """
    import nlcx

    @nlcx.controller("plugged_lqi", measures=["x", "x_dot", "theta", "theta_dot"], references=["x", "theta"],
                     inputs=["F_x"], states={"z": 0.0},
                     params={"k1": -2.694, "k2": -3.129, "k3": -30.50, "k4": -5.160, "ki": -1.0})
    def law(t, dt, y, r, s, p):
        u = -(p.k1 * (y[0] - r[0]) + p.k2 * y[1] + p.k3 * y[2] + p.k4 * y[3] + p.ki * s[0])
        return (u,), (s[0] + dt * (y[0] - r[0]),)
    """
)


@pytest.fixture
def plugin_config(tmp_path: Path) -> Path:
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "my_law.py").write_text(PLUGIN)
    config = tmp_path / "law.yaml"
    config.write_text(yaml.safe_dump({**_config({"lqi": {"kind": "plugged_lqi"}}, t_end=2.0),
                                      "imports": ["plugins/my_law.py"], "outputs": {"figure": False}}))  # fmt: skip
    return config


def test_imports_make_a_plugin_known_to_the_command_line(plugin_config: Path, tmp_path: Path) -> None:
    """nlcx run in a child process imports the file the config names (relative to the config),
    records it and its SHA-256 in the manifest; load_run in another never imports it."""
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "nlcx.cli", "run", str(plugin_config), "--out", str(out), "-q"],
                          capture_output=True, text=True, cwd=tmp_path.parent)  # fmt: skip
    assert done.returncode == 0, done.stderr
    record = json.loads((out / "manifest.json").read_text())
    file = (tmp_path / "plugins" / "my_law.py").resolve()
    import hashlib

    assert record["imports"] == [
        {"name": str(file), "path": str(file), "sha256": hashlib.sha256(file.read_bytes()).hexdigest()}
    ]
    check = (
        "import sys, nlcx; r = nlcx.load_run(sys.argv[1]); "
        "print(r.controllers, [m for m in sys.modules if m.startswith('nlcx_plugin_')])"
    )
    loaded = subprocess.run([sys.executable, "-c", check, str(out)], capture_output=True, text=True)
    assert loaded.returncode == 0, loaded.stderr
    assert loaded.stdout.strip() == "['lqi'] []"


def test_a_plugin_unknown_to_the_command_line_names_both_ways(tmp_path: Path) -> None:
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump(_config({"lqi": {"kind": "not_imported_law"}})))
    result = runner.invoke(app, ["validate", str(config)])
    assert result.exit_code == 2
    assert "unknown controller" in result.stderr and "imports: [my_controllers.py] (or --plugins FILE)" in result.stderr
    assert "entry-point group nlcx.controllers" in result.stderr


def test_plugins_option_imports_for_one_command(tmp_path: Path) -> None:
    (tmp_path / "law.py").write_text(PLUGIN.replace("plugged_lqi", "optioned_lqi"))
    listed = runner.invoke(app, ["list", "controllers", "--plugins", str(tmp_path / "law.py")])
    assert listed.exit_code == 0 and "optioned_lqi" in listed.output


def test_from_control_equals_the_transfer_function_plant() -> None:
    """A StateSpace registered with from_control runs as the transfer_function plant of the same
    system: the same output under the same PID, to rounding."""
    num, den = [2.0, 1.0], [1.0, 3.0, 3.0, 1.0]
    from_control(ct.ss(ct.tf(num, den)), "test_ss_plant", inputs=["u"], outputs=["y"])
    pid = {"kind": "pid", "loops": {"y": {"schedule": {"kind": "constant", "kp": 1.5, "ki": 0.8, "kd": 0.2}}}}
    base = {"name": "fc", "controllers": {"pid": pid}, "reference": {"y": {"kind": "step", "final": 1.0}},
            "simulation": {"t_end": 20.0}}  # fmt: skip
    ours = nlcx.run({**base, "plant": {"name": "test_ss_plant"}}).response("pid")
    params = {"num": num, "den": den, "input_name": "u", "output_name": "y"}
    theirs = nlcx.run({**base, "plant": {"name": "transfer_function", "params": params}}).response("pid")
    np.testing.assert_allclose(ours.y[0], theirs.y[0], atol=1e-12)
    np.testing.assert_allclose(ours.u[0], theirs.u[0], atol=1e-12)
    with pytest.raises(ConfigError, match="strictly proper"):
        from_control(ct.tf([1.0, 0.0], [1.0, 1.0]), "proper")


def test_response_feeds_python_controls_step_info(tmp_path: Path) -> None:
    result = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=20"])
    response = result.response("proposed")
    assert response.output_labels == ["x", "theta"] and response.input_labels == ["F_x"]
    info = ct.step_info(response.y[0], response.time, final_output=1.0)
    measured = result.metrics.set_index(["controller", "signal", "metric"]).value
    assert info["Overshoot"] == pytest.approx(measured[("proposed", "x", "overshoot")], rel=1e-9)
    again = nlcx.load_run(result.save(tmp_path / "run", report=False)).response("proposed")
    np.testing.assert_array_equal(again.y, response.y)


@pytest.mark.gpu
def test_a_decorator_controller_on_the_gpu_simulator_matches_the_cpu(plugin_config: Path, tmp_path: Path) -> None:
    """The law's generated step retargeted for CUDA (numba's simulator): statuses and metrics
    within 1e-9 of the CPU's, over a short horizon."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1", "CUDA_VISIBLE_DEVICES": ""}
    frames = []
    for device in ("cpu", "cuda"):
        out = tmp_path / device
        args = [
            "run",
            str(plugin_config),
            "simulation.t_end=0.06",
            "--device",
            device,
            "--no-report",
            "--out",
            str(out),
        ]
        done = subprocess.run([sys.executable, "-m", "nlcx.cli", *args], capture_output=True, text=True, env=env)
        assert done.returncode == 0, done.stderr
        frames.append(pd.read_csv(out / "metrics.csv"))
    cpu, gpu = frames
    assert cpu.status.tolist() == gpu.status.tolist() and len(cpu) > 0
    finite = cpu.value.notna().to_numpy()
    np.testing.assert_allclose(gpu.value.to_numpy()[finite], cpu.value.to_numpy()[finite], rtol=1e-9, atol=0.0)


def test_registry_knows_the_baselines() -> None:
    for kind in ("lqr", "pole_placement", "state_feedback", "sliding_mode"):
        assert kind in registry.controllers.names()

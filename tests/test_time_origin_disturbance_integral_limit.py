"""Three loop options against their definitions: the origin of the event times of a step
response (``metrics.time_origin``), where and when the disturbance enters (``entry``,
``inputs``, ``start``), and the limits of a PID loop's integrator (``integral_limit``)."""

from __future__ import annotations

import copy
import math
from typing import Any

import control
import numpy as np
import pytest
from conftest import CONFIGS, run_raw
from scipy.integrate import solve_ivp

from nlcx import config, engine
from nlcx.controllers import pid
from nlcx.controllers.base import ControllerInstance
from nlcx.controllers.pid import LOOP, LOOP_STATE, pid_step
from nlcx.errors import ConfigError
from nlcx.kernel.abi import callback_slots
from nlcx.plants.x_pendulum import XPendulumParams

FIRST_ORDER = {"num": [1.0], "den": [1.0, 1.0]}  # G(s) = 1 / (s + 1)


def tf_raw(controllers: dict[str, Any], reference: dict[str, Any], t_end: float, dt: float, **extra: Any) -> dict:
    """An experiment on the first-order plant 1 / (s + 1), output y, input u."""
    return {
        "name": "options_test",
        "plant": {"name": "transfer_function", "params": FIRST_ORDER},
        "controllers": controllers,
        "reference": reference,
        "simulation": {"t_end": t_end, "dt": dt},
        **extra,
    }


def metric_table(result: engine.ExperimentResult) -> dict[tuple[str, str, str], float]:
    """(controller, signal, metric) -> value."""
    return {(c, s, name): v for c, s, name, v, *_ in result.metric_rows}


# ------------------------------------------------------------------------------ time_origin


def _pi_step_at_one_second() -> engine.ExperimentResult:
    """A PI loop on 1 / (s + 1), reference step 0 -> 1 at t = 1 s: an underdamped second-order
    response (s^2 + 2 s + 4, zeta = 0.5), which overshoots and settles within the run."""
    pi = {"kind": "pid", "loops": {"y": {"schedule": {"kind": "constant", "kp": 1.0, "ki": 4.0, "kd": 0.0}}}}
    (result,) = engine.evaluate([config.build(tf_raw({"pi": pi}, {"y": {"kind": "step", "time": 1.0}}, 8.0, 1e-3))])
    return result


def test_the_default_time_origin_is_the_step_as_before() -> None:
    """The event times of a step response were measured from the step; ``time_origin`` defaults
    to ``step``, so a config without it measures them as before (the same values)."""
    assert config.MetricsSection().time_origin == "step"
    result = _pi_step_at_one_second()
    (explicit,) = engine.remeasure([result], {"time_origin": "step"})
    assert result.metric_rows == explicit.metric_rows


def test_time_origin_step_is_start_less_the_step_time_and_agrees_with_python_control() -> None:
    """Reference step at t = 1 s: under ``step`` the settling and peak times are those under
    ``start`` less 1 s, the rise time (a duration) and every other metric the same; and each
    agrees, within a sample, with python-control's ``step_info`` of the same samples, on the
    record from t = 0 (``start``) and on the record from the step with its time axis shifted
    by 1 s (``step``)."""
    result = _pi_step_at_one_second()
    from_start, from_step = (metric_table(engine.remeasure([result], {"time_origin": o})[0]) for o in ("start", "step"))
    for name in ("settling_time", "peak_time"):
        key = ("pi", "y", name)
        assert from_start[key] > 1.0
        assert from_step[key] == pytest.approx(from_start[key] - 1.0, abs=1e-12)
    for key in from_start:
        if key[2] not in ("settling_time", "peak_time"):
            assert from_step[key] == from_start[key] or (math.isnan(from_step[key]) and math.isnan(from_start[key]))
    (run,) = result.runs
    y, t, dt = run.x[:, 0], run.t, run.t[1] - run.t[0]
    after = t >= 1.0
    whole = control.step_info(y, t, yfinal=1.0)
    shifted = control.step_info(y[after], t[after] - 1.0, yfinal=1.0)
    for ours, theirs in ((from_start, whole), (from_step, shifted)):
        # python-control reports the sample at or after each crossing
        assert 0.0 <= theirs["SettlingTime"] - ours[("pi", "y", "settling_time")] <= dt + 1e-12
        assert abs(theirs["RiseTime"] - ours[("pi", "y", "rise_time")]) <= dt + 1e-12
        assert theirs["PeakTime"] == pytest.approx(ours[("pi", "y", "peak_time")], abs=1e-12)


def test_time_origin_of_an_open_loop_step_response_by_hand() -> None:
    """An input step at t = 1 s into 1 / (s + 1): y = 1 - exp(-(t - 1)), measured against its
    own final value F = y(11) = 1 - exp(-10) (an open-loop output, MATLAB's ``stepinfo``). It
    enters the 2 % band |y - F| <= 0.02 F at tau_s = -ln(0.02 F + exp(-10)) after the step;
    |y| peaks at the last sample; it rises from 0.1 F to 0.9 F in ln((1 - 0.1 F)/(1 - 0.9 F))."""
    raw = tf_raw({"open": {"kind": "open_loop"}}, {"u": {"kind": "step", "time": 1.0}}, 11.0, 1e-3)
    (result,) = engine.evaluate([config.build(raw)])
    final = 1.0 - math.exp(-10.0)
    tau_s = -math.log(0.02 * final + math.exp(-10.0))
    rise = math.log((1.0 - 0.1 * final) / (1.0 - 0.9 * final))
    for origin, shift in (("step", 0.0), ("start", 1.0)):
        (measured,) = engine.remeasure([result], {"time_origin": origin})
        values = metric_table(measured)
        assert values[("open", "y", "settling_time")] == pytest.approx(tau_s + shift, abs=1e-6)
        assert values[("open", "y", "peak_time")] == pytest.approx(10.0 + shift, abs=1e-9)
        assert values[("open", "y", "rise_time")] == pytest.approx(rise, abs=1e-6)


def test_time_origin_moves_the_step_signal_and_leaves_the_regulated_angle() -> None:
    """The x pendulum's conventional PID (derivative on the measurement: no kick at the step)
    with its position step at t = 1 s: x's settling and peak times move by 1 s between the
    origins; theta, regulated to 0 (no step reference), is measured from t = 0 under both."""
    raw = config.read_config(CONFIGS / "x_error_ags.yaml")
    raw["reference"]["x"]["time"] = 1.0
    raw["controllers"] = {"conventional": {**raw["controllers"]["conventional"], "derivative": {"on": "measurement"}}}
    (result,) = engine.evaluate([config.build(config.interpolate(raw))])
    from_start, from_step = (metric_table(engine.remeasure([result], {"time_origin": o})[0]) for o in ("start", "step"))
    for name in ("settling_time", "peak_time"):
        assert from_start[("conventional", "x", name)] > 1.0
        assert from_step[("conventional", "x", name)] == pytest.approx(
            from_start[("conventional", "x", name)] - 1.0, abs=1e-12
        )
        assert from_step[("conventional", "theta", name)] == from_start[("conventional", "theta", name)]
    assert from_step[("conventional", "x", "rise_time")] == from_start[("conventional", "x", "rise_time")]
    assert from_start[("conventional", "theta", "peak_time")] > 1.0  # theta moves only after the step


def test_time_origin_accepts_only_start_or_step() -> None:
    raw = tf_raw({"open": {"kind": "open_loop"}}, {}, 1.0, 1e-3, metrics={"time_origin": "reference"})
    with pytest.raises(ConfigError, match=r"^config error: metrics\.time_origin = 'reference': allowed values"):
        config.build(raw)


# ------------------------------------------------------------------------------ disturbance


def _pendulum_raw(reference: dict[str, Any], uncertainty: dict[str, Any], t_end: float, dt: float) -> dict:
    """The x pendulum driven open loop by F_x = its reference, upright at rest."""
    return {
        "name": "disturbed_pendulum",
        "plant": {"name": "x_pendulum"},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {"F_x": reference},
        "uncertainty": uncertainty,
        "simulation": {"t_end": t_end, "dt": dt, "bounds": {"theta": 1e9}},
    }


def _prepared(uncertainty: dict[str, Any], dt: float = 1.0 / 64.0, t_end: float = 2.0) -> engine.Prepared:
    return engine.prepare(config.build(_pendulum_raw({"kind": "constant", "value": 0.0}, uncertainty, t_end, dt)))


@pytest.mark.parametrize("entry", ["accelerations", "input"])
def test_a_sine_disturbance_starts_at_start_with_its_phase(entry: str) -> None:
    """A = 2, f = 1 Hz, phase pi/2, start 0.25 s, sampled where it acts (the stage times for
    the accelerations, the sampling instants for the input; dt = 1/64 s puts every time
    named here on the grid): d = 0 before 0.25 s; d(0.25) = A sin(pi/2) = A; an eighth of a
    period later A sin(3 pi/4) = A/sqrt(2); a quarter period later A sin(pi) = 0; half a
    period later -A."""
    d_cfg = {"kind": "disturbance", "amplitude": 2.0, "frequency": 1.0, "phase": math.pi / 2, "start": 0.25}
    hooks = _prepared({"d": {**d_cfg, "entry": entry}}).hooks
    if entry == "accelerations":
        times, d = hooks.stage_times.ravel(), hooks.dist_values[0].ravel()
        assert list(hooks.dist_columns[0]) == [0.0, 1.0, 0.0, 1.0]  # x_dot and theta_dot
    else:
        (element,) = hooks.elements
        assert element.hook == "actuator" and element.data is not None
        times, d = hooks.t, element.data[:, 0]
    assert np.all(d[times < 0.25] == 0.0) and np.any(times < 0.25)
    at = {float(tk): float(dk) for tk, dk in zip(times, d, strict=True)}
    assert at[0.25] == pytest.approx(2.0, abs=1e-12)
    assert at[0.375] == pytest.approx(math.sqrt(2.0), abs=1e-12)
    assert at[0.5] == pytest.approx(0.0, abs=1e-12)
    assert at[0.75] == pytest.approx(-2.0, abs=1e-12)


def test_a_step_disturbance_and_a_sine_from_zero_keep_their_values() -> None:
    """start = 0 leaves the sine A sin(2 pi f t + phase) to the last bit (t - 0 is t); a step is
    0 before start and A from it on."""
    sine = {"kind": "disturbance", "amplitude": 20.0, "frequency": 10.0, "phase": 0.4}
    hooks = _prepared({"d": sine}, dt=1e-3, t_end=0.5).hooks
    t = hooks.stage_times
    assert np.array_equal(hooks.dist_values[0], 20.0 * np.sin(2 * np.pi * 10.0 * t + 0.4))
    step = {"kind": "disturbance", "waveform": "step", "amplitude": 0.5, "start": 0.25}
    hooks = _prepared({"d": step}).hooks
    d = hooks.dist_values[0]
    assert np.all(d[hooks.stage_times < 0.25] == 0.0) and np.all(d[hooks.stage_times >= 0.25] == 0.5)


def test_an_input_disturbance_is_a_controller_output_shifted_by_d() -> None:
    """entry: input adds d(t_k) to the force the controller commands, held over the step: the
    pendulum driven by F_x = 0 plus d = 3 sin(2 pi 2 t + 0.3) at its input moves exactly as the
    one driven by the open-loop force F_x = 3 sin(2 pi 2 t + 0.3), bit for bit."""
    d = {"kind": "disturbance", "entry": "input", "amplitude": 3.0, "frequency": 2.0, "phase": 0.3}
    (disturbed,) = run_raw(_pendulum_raw({"kind": "constant", "value": 0.0}, {"d": d}, 1.0, 1e-3)).runs
    sine = {"kind": "sine", "amplitude": 3.0, "frequency": 2.0, "phase": 0.3}
    (driven,) = run_raw(_pendulum_raw(sine, {}, 1.0, 1e-3)).runs
    assert np.array_equal(disturbed.x, driven.x) and np.array_equal(disturbed.u, driven.u)
    assert np.ptp(disturbed.x[:, 0]) > 1e-2  # it moved


def _pendulum_accelerations(state: np.ndarray, force: float) -> np.ndarray:
    """The cart and pendulum by Lagrange's equations (theta from upright), independent of the
    plant's printed ones: (M + m) x'' + m l cos(theta) theta'' = F + m l sin(theta) theta'^2 and
    cos(theta) x'' + l theta'' = g sin(theta)."""
    p = XPendulumParams()
    _, x_dot, theta, theta_dot = state
    s, c = math.sin(theta), math.cos(theta)
    mass = np.array([[p.M + p.m, p.m * p.l * c], [c, p.l]])
    x_acc, theta_acc = np.linalg.solve(mass, [force + p.m * p.l * s * theta_dot**2, p.g * s])
    return np.array([x_dot, x_acc, theta_dot, theta_acc])


def test_an_input_disturbance_matches_an_independent_solution_of_the_pendulum() -> None:
    """d = 2 sin(2 pi 5 (t - 0.1) + 0.7) from t = 0.1 s as a force at the input of the x
    pendulum (open loop, F_x = 0): the trajectory agrees with scipy's solution of Lagrange's
    equations with F = d(t) continuous, to within what holding d over each step dt = 0.1 ms
    changes (about pi f dt = 0.16 % of the response); a disturbance on the accelerations
    instead moves the cart quite differently."""
    d = {"kind": "disturbance", "entry": "input", "amplitude": 2.0, "frequency": 5.0, "phase": 0.7, "start": 0.1}
    zero = {"kind": "constant", "value": 0.0}
    (run,) = run_raw(_pendulum_raw(zero, {"d": d}, 0.6, 1e-4)).runs
    assert np.all(run.x[run.t <= 0.1] == 0.0)  # at rest until the disturbance starts

    def force(t: float) -> float:
        return 2.0 * math.sin(2 * math.pi * 5.0 * (t - 0.1) + 0.7) if t >= 0.1 else 0.0

    after = run.t >= 0.1
    exact = solve_ivp(
        lambda t, x: _pendulum_accelerations(x, force(t)), (0.1, 0.6), np.zeros(4), t_eval=run.t[after],
        rtol=1e-11, atol=1e-13,
    ).y.T  # fmt: skip
    scale = np.max(np.abs(exact), axis=0)
    assert np.all(scale[[0, 2]] > 1e-3)
    assert np.all(np.max(np.abs(run.x[after] - exact), axis=0) <= 5e-3 * scale)
    (on_accelerations,) = run_raw(_pendulum_raw(zero, {"d": {**d, "entry": "accelerations"}}, 0.6, 1e-4)).runs
    assert np.max(np.abs(on_accelerations.x[after, 0] - exact[:, 0])) > 0.1 * scale[0]


def test_an_input_disturbance_in_a_closed_loop_sample_by_sample() -> None:
    """A PID on the x pendulum with d = 5 sin(2 pi 2 (t - 0.5) + pi/3) from t = 0.5 s on F_x:
    at every sample the recorded force is the PID's output (the sum of its loops' logged
    contributions) plus d(t_k), and d is 0 before 0.5 s."""
    raw = config.read_config(CONFIGS / "x_error_ags.yaml")
    raw["controllers"] = {"conventional": raw["controllers"]["conventional"]}
    raw["simulation"]["t_end"] = 2.0
    d = {"kind": "disturbance", "entry": "input", "inputs": ["F_x"], "amplitude": 5.0, "frequency": 2.0,
         "phase": math.pi / 3, "start": 0.5}  # fmt: skip
    raw["uncertainty"] = {"d": d}
    (run,) = run_raw(config.interpolate(raw)).runs
    assert run.status == "ok" and run.log is not None
    names = run.controller.log_names
    pid_output = run.log[:, names.index("theta.u")] + run.log[:, names.index("x.u")]
    t = run.t
    expected = np.where(t >= 0.5, 5.0 * np.sin(4.0 * math.pi * (t - 0.5) + math.pi / 3), 0.0)
    assert np.max(np.abs(run.u[:, 0] - pid_output - expected)) < 1e-9
    assert np.all(run.u[t < 0.5, 0] == pid_output[t < 0.5])


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ({"entry": "input", "states": ["x_dot"]}, r"uncertainty\.d\.states = \['x_dot'\]: allowed only with entry: "),
        ({"inputs": ["F_x"]}, r"uncertainty\.d\.inputs = \['F_x'\]: allowed only with entry: input"),
        ({"entry": "force"}, r"uncertainty\.d\.entry = 'force': allowed values"),
        ({"entry": "input", "inputs": ["F_y"]}, r"uncertainty\.d\.inputs\.0 = 'F_y': not an input of x_pendulum"),
    ],
)
def test_disturbance_entry_errors_name_the_key(section: dict[str, Any], message: str) -> None:
    raw = _pendulum_raw({"kind": "constant", "value": 0.0}, {"d": {"kind": "disturbance", **section}}, 0.1, 1e-3)
    with pytest.raises(ConfigError, match=f"^config error: {message}") as error:
        engine.prepare(config.build(raw))
    assert "\n" not in str(error.value)


# ------------------------------------------------------------------------------ integral_limit


def _integrating_pid(limit: float | None, integral: str = "outside", ki: float = 1.0) -> ControllerInstance:
    """An I controller u = k_i I on 1 / (s + 1), its integrator limited to [-limit, limit]."""
    loop = {"schedule": {"kind": "constant", "kp": 0.0, "ki": ki, "kd": 0.0}, "integral_limit": limit}
    controllers = {"i": {"kind": "pid", "integral": integral, "loops": {"y": loop}}}
    (c,) = engine.prepare(config.build(tf_raw(controllers, {"y": {"kind": "step"}}, 1.0, 0.01))).controllers
    return c


def _drive(c: ControllerInstance, errors: np.ndarray, dt: float, step: Any) -> tuple[np.ndarray, np.ndarray]:
    """``step`` called on r_k = e_k, y_k = 0; returns (u_k, the integrator state after sample k)."""
    cp, cs = c.cp[None].copy(), c.cs0[None].copy()
    u, log = np.zeros((1, 1)), np.zeros((1, len(c.log_names)))
    us, integrals = [], []
    for k, e in enumerate(errors):
        step(k * dt, dt, np.zeros((1, 1)), np.zeros((1, 1)), np.array([[e]]), cp, cs, u, log,
             callback_slots(c.callbacks))  # fmt: skip
        us.append(u[0, 0])
        integrals.append(cs[0, LOOP_STATE.at.integral])
    return np.array(us), np.array(integrals)


@pytest.mark.parametrize(("integral", "ki"), [("outside", 1.0), ("outside", 2.0), ("inside", 4.0)])
def test_the_integrator_holds_at_its_limit_when_it_would_cross_it(integral: str, ki: float) -> None:
    """Constant error e = 1, dt = 0.01, L = 0.255: the integrator state (the integral of e, or of
    k_i e with the gain inside) grows by g dt a sample (g = 1, or k_i) to the last sample before
    it would pass L, is L from there on, exactly, and unwinds at once when e turns to -1 (no
    windup to undo); u = k_i I outside, I inside. The same for e = -1 at -L. Both the step made
    for the loop's structure and the general step."""
    dt, limit = 0.01, 0.255
    c = _integrating_pid(limit, integral, ki)
    gain = ki if integral == "inside" else 1.0
    errors = np.r_[np.ones(60), -np.ones(10)]
    k = np.arange(60)
    crossing = int(np.argmax(gain * (k + 1) * dt > limit))  # the first sample that would pass L
    for step in (c.step, pid_step):
        u, state = _drive(c, errors, dt, step)
        assert state[:crossing] == pytest.approx(gain * (k[:crossing] + 1) * dt, abs=1e-12)
        assert np.all(state[crossing:60] == limit) and state[crossing - 1] < limit
        assert state[60:] == pytest.approx(limit - gain * dt * np.arange(1, 11), abs=1e-12)
        assert np.array_equal(u, state * (1.0 if integral == "inside" else ki))
        _, negative = _drive(c, -errors, dt, step)
        assert np.array_equal(negative, -state)


def test_a_limited_integrator_in_a_closed_loop() -> None:
    """I control of 1 / (s + 1) on a unit step, u = I (k_i = 1), L = 0.3: the loop runs as the
    unlimited one, bit for bit, up to the sample where u would first pass 0.3; from there u
    = 0.3 (the error stays positive: y < 0.3 < r), and y tends to 0.3 (G(0) = 1)."""
    runs = []
    for limit in (None, 0.3):
        raw = tf_raw({"i": {"kind": "pid", "loops": {"y": {"integral_limit": limit, "schedule": {
            "kind": "constant", "kp": 0.0, "ki": 1.0, "kd": 0.0}}}}}, {"y": {"kind": "step"}}, 10.0, 1e-3)  # fmt: skip
        (run,) = run_raw(raw).runs
        runs.append(run)
    free, limited = runs
    crossing = int(np.argmax(free.u[:, 0] > 0.3))
    assert 0 < crossing < free.t.size // 2
    assert np.array_equal(limited.x[: crossing + 1], free.x[: crossing + 1])
    assert np.array_equal(limited.u[:crossing], free.u[:crossing])
    assert np.all(limited.u[crossing:, 0] == 0.3)
    assert limited.x[-1, 0] == pytest.approx(0.3, abs=1e-3) and free.x[-1, 0] > 0.9


def test_no_integral_limit_computes_the_same_bits() -> None:
    """Without a limit the loop's block holds L = inf and its structure says unlimited; on a
    random drive a limit never reached gives the same inputs, logs and states as none."""
    c = _integrating_pid(None)
    assert LOOP.unpack(c.cp, pid.HEAD.size + pid.INPUT.size)["integral_limit"] == math.inf
    assert pid.structure_of(c.cp).limited == (0,)
    far = _integrating_pid(1e6)
    assert pid.structure_of(far.cp).limited == (1,) and far.step is not c.step
    errors = np.random.default_rng(7).normal(size=200)
    for step in (pid_step, c.step):
        unlimited, unreached = _drive(c, errors, 0.01, step), _drive(far, errors, 0.01, step)
        assert all(np.array_equal(a, b) for a, b in zip(unlimited, unreached, strict=True))


SIGNS = {"theta": -1, "x": 1}


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"integral": "inside", "form": "ideal"},
        {"saturation": {"limits": {"F_x": 3.0}, "anti_windup": "clamping"}},
        {"saturation": {"limits": {"F_x": 3.0}, "anti_windup": "back_calculation", "kb": 3.0}, "sample_time": 0.03},
    ],
)
def test_limited_loops_step_for_their_structure_as_the_general_step(options: dict[str, Any]) -> None:
    """Two loops on the x pendulum, one with an integral limit, driven on three rows by random
    outputs and references: the step made for the structure and the general step give the
    same inputs, logs and states to the last bit; the limited integrator reaches its limit
    and never leaves [-L, L], whatever the anti-windup does to it."""
    limit = 0.05
    loops = {
        "theta": {"sign": -1, "schedule": {"kind": "constant", "kp": 30.0, "ki": 2.0, "kd": 4.0}},
        "x": {"sign": 1, "integral_limit": limit, "schedule": {"kind": "constant", "kp": -3.0, "ki": -1.0, "kd": -2.0}},
    }
    raw = {
        "name": "limited_pid",
        "plant": {"name": "x_pendulum"},
        "controllers": {"c": {"kind": "pid", "loops": loops, **copy.deepcopy(options)}},
        "reference": {"x": {"kind": "step"}},
        "simulation": {"t_end": 1.0, "dt": 0.01},
    }
    (c,) = engine.prepare(config.build(raw)).controllers
    assert pid.structure_of(c.cp).limited == (0, 1) and c.step is not pid_step
    dt, rows = 0.01, 3
    traces = []
    for step in (pid_step, c.step):
        cp, cs = np.tile(c.cp, (rows, 1)), np.tile(c.cs0, (rows, 1))
        u, log = np.zeros((rows, 1)), np.zeros((rows, len(c.log_names)))
        rng = np.random.default_rng(11)
        trace = []
        for k in range(150):
            y, r = rng.normal(scale=0.5, size=(rows, 2)), rng.normal(loc=0.3, scale=0.5, size=(rows, 2))
            step(k * dt, dt, np.zeros((rows, 4)), y, r, cp, cs, u, log, callback_slots(c.callbacks))
            trace.append(np.concatenate([u.ravel(), log.ravel(), cs.ravel()]))
        traces.append(np.array(trace))
    general, made = traces
    assert np.array_equal(general.view(np.int64), made.view(np.int64))
    x_integral = general[:, rows + rows * len(c.log_names) :].reshape(150, rows, -1)[
        :, :, LOOP_STATE.size + LOOP_STATE.at.integral
    ]
    assert np.max(np.abs(x_integral)) == limit
    assert np.ptp(general[:, :rows]) > 1.0  # the inputs moved


@pytest.mark.parametrize("value", [0.0, -1.0])
def test_an_integral_limit_must_be_positive(value: float) -> None:
    loop = {"schedule": {"kind": "constant", "kp": 1.0, "ki": 1.0, "kd": 0.0}, "integral_limit": value}
    raw = tf_raw({"c": {"kind": "pid", "loops": {"y": loop}}}, {}, 1.0, 0.01)
    with pytest.raises(ConfigError, match=rf"^config error: controllers\.c\.loops\.y\.integral_limit = {value}: "):
        config.build(raw)

"""Tests of nlcx.metrics: against python-control, closed forms, invariances and edge cases."""

from __future__ import annotations

from functools import cache

import control
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from nlcx import metrics
from nlcx.metrics import (
    METRIC_UNITS,
    error_integrals,
    input_metrics,
    regulation_metrics,
    step_response_metrics,
)

# ------------------------------------------------------------------ python-control step_info

# (name, numerator, denominator, horizon [s]); simulated on N_FINE points.
LTI_CASES = [
    # CSTR linearisation: non-minimum phase (zero at +2.82), inverse response, no overshoot.
    ("cstr_nmp", [-1.117, 3.1472], [1.0, 4.6429, 5.3821], 10.0),
    # Underdamped second order, zeta = 0.3: about 37 % overshoot.
    ("second_order", [1.0], [1.0, 0.6, 1.0], 30.0),
    # Third-order Butterworth: about 8 % overshoot.
    ("third_order", [1.0], [1.0, 2.0, 2.0, 1.0], 20.0),
]
N_FINE = 100_001


@cache
def _lti_step(num: tuple[float, ...], den: tuple[float, ...], horizon: float):
    sys = control.tf(list(num), list(den))
    t = np.linspace(0.0, horizon, N_FINE)
    y = np.squeeze(control.step_response(sys, t).outputs)
    return t, y, float(np.real(sys.dcgain()))


@pytest.mark.parametrize(("name", "num", "den", "horizon"), LTI_CASES, ids=[c[0] for c in LTI_CASES])
def test_agrees_with_control_step_info(name, num, den, horizon):
    """Same definitions as control.step_info when the response starts at 0.

    step_info reports the first sample at/after a crossing (up to one sample late); we
    interpolate.  So each crossing differs by less than one sample: the rise time (a
    difference of two crossings) by less than dt, and the settling time, whose sample
    T[k+1] we refine to a point of [T[k], T[k+1]], lies in [theirs - dt, theirs].  Overshoot,
    undershoot, peak and peak time are sample-based in both and agree to rounding.
    """
    t, y, dc = _lti_step(tuple(num), tuple(den), horizon)
    dt = t[1] - t[0]
    assert y[0] == 0.0  # python-control assumes the response starts at 0
    ref = control.step_info(y, t, final_output=dc)
    ours = step_response_metrics(t, y, final=dc)  # initial defaults to y(0) = 0
    eps = 1e-9
    assert abs(float(ours["rise_time"]) - ref["RiseTime"]) < dt + eps
    assert ref["SettlingTime"] - dt - eps <= float(ours["settling_time"]) <= ref["SettlingTime"] + eps
    np.testing.assert_allclose(ours["overshoot"], ref["Overshoot"], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ours["undershoot"], ref["Undershoot"], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ours["peak"], ref["Peak"], rtol=1e-12)
    assert float(ours["peak_time"]) == ref["PeakTime"]
    # The cases exercise what they are meant to.
    if name == "cstr_nmp":
        assert ref["Undershoot"] > 10.0 and ref["Overshoot"] == 0.0
    else:
        assert ref["Overshoot"] > 5.0


# ------------------------------------------------------------------ interpolation


@pytest.mark.parametrize("grid", ["uniform", "nonuniform"])
def test_crossings_are_interpolated_not_grid_bound(grid):
    """First-order lag on a coarse grid: rise time ln 9 and settling time ln 50 to 1e-3.

    Linear interpolation of 1 - e^{-t} delays a crossing by at most h^2/8 for a cell of
    width h (curvature / slope = 1), i.e. < 1e-3 for h <= 0.089; the grid-bound answer is
    off by up to a whole cell.
    """
    # uniform: dt = 0.1; otherwise spacing from 0.015 to 0.087
    t = np.linspace(0.0, 10.0, 101) if grid == "uniform" else 10.0 * np.linspace(0.0, 1.0, 151) ** 1.3
    y = 1.0 - np.exp(-t)
    m = step_response_metrics(t, y, final=1.0)
    assert abs(float(m["rise_time"]) - np.log(9.0)) < 1e-3
    assert abs(float(m["settling_time"]) - np.log(50.0)) < 1e-3
    # ... while the grid-bound answer (python-control on the same samples) is not.
    ref = control.step_info(y, t, final_output=1.0)
    assert abs(ref["RiseTime"] - np.log(9.0)) > 1e-3
    assert abs(ref["SettlingTime"] - np.log(50.0)) > 1e-3


def test_steady_state_error_window():
    """Time-weighted mean over exactly the last ss_window seconds, or the whole record."""
    t = np.linspace(0.0, 10.0, 101)
    ramp = t.copy()  # trapezoidal rule is exact for a ramp
    # Window start 9.05 is between samples: mean of t over [9.05, 10] is 9.525.
    m = step_response_metrics(t, ramp, final=10.0, initial=0.0, ss_window=0.95)
    np.testing.assert_allclose(m["steady_state_error"], 10.0 - 9.525, rtol=0, atol=1e-12)
    r = regulation_metrics(t, ramp, reference=1.0, ss_window=0.95)
    np.testing.assert_allclose(r["steady_state_error"], 1.0 - 9.525, rtol=0, atol=1e-12)
    # Record shorter than the window: mean over [0, 10] is 5.
    r = regulation_metrics(t, ramp, ss_window=100.0)
    np.testing.assert_allclose(r["steady_state_error"], -5.0, rtol=0, atol=1e-12)
    # First-order lag: final - mean over [9, 10] = e^-9 - e^-10.
    m = step_response_metrics(t, 1.0 - np.exp(-t), final=1.0)
    np.testing.assert_allclose(m["steady_state_error"], np.exp(-9) - np.exp(-10), rtol=1e-3)


# ------------------------------------------------------------------ initial value, t_step


def _shape(t: np.ndarray) -> np.ndarray:
    """A 0 -> 1 response with both undershoot (y'(0) = -1.5) and overshoot."""
    return 1.0 - np.exp(-0.5 * t) * (np.cos(2.0 * t) + np.sin(2.0 * t))


STEP_KEYS_SHAPE = ("rise_time", "settling_time", "overshoot", "undershoot", "peak_time")


def test_initial_value_and_direction_are_accounted_for():
    t = np.linspace(0.0, 20.0, 2001)
    f = _shape(t)
    base = step_response_metrics(t, f, final=1.0)
    assert float(base["undershoot"]) > 5.0 and float(base["overshoot"]) > 5.0
    up = step_response_metrics(t, 2.0 + f, final=3.0)  # 2 -> 3, initial = y(0) = 2
    down = step_response_metrics(t, 3.0 - f, final=2.0)  # 3 -> 2, mirrored
    down_explicit = step_response_metrics(t, 3.0 - f, final=2.0, initial=3.0)
    for k in STEP_KEYS_SHAPE:
        for other in (up, down, down_explicit):
            np.testing.assert_allclose(other[k], base[k], rtol=1e-9, atol=1e-12, err_msg=k)
    np.testing.assert_allclose(up["peak"], 2.0 + base["peak"], rtol=1e-12)
    np.testing.assert_allclose(down["peak"], 3.0 - base["peak"], rtol=1e-12)
    ss = base["steady_state_error"]
    np.testing.assert_allclose(up["steady_state_error"], ss, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(down["steady_state_error"], -ss, rtol=1e-6, atol=1e-12)


def test_time_shift_leaves_metrics_unchanged():
    """Step at t_step = 5: samples before it (here junk) are ignored, times are from t_step."""
    t = np.linspace(0.0, 20.0, 2001)
    base = step_response_metrics(t, _shape(t), final=1.0)
    t_long = np.linspace(0.0, 25.0, 2501)  # t_long[500] == 5.0
    y_long = np.where(t_long >= 5.0, _shape(t_long - 5.0), 7.0 * np.sin(t_long))
    shifted = step_response_metrics(t_long, y_long, t_step=5.0, final=1.0)
    for k in metrics.STEP_METRICS:
        np.testing.assert_allclose(shifted[k], base[k], rtol=1e-9, atol=1e-12, err_msg=k)


def test_default_initial_is_interpolated_at_t_step():
    t = np.linspace(0.0, 10.0, 1001)  # dt = 0.01
    y = np.where(t >= 2.3, 1.0 - np.exp(-3.0 * (t - 2.3)), 0.0)
    t_step = 2.305  # between samples 2.30 and 2.31
    expected_initial = float(np.interp(t_step, t, y))
    default = step_response_metrics(t, y, t_step=t_step, final=1.0)
    explicit = step_response_metrics(t, y, t_step=t_step, final=1.0, initial=expected_initial)
    first_sample = step_response_metrics(t, y, t_step=t_step, final=1.0, initial=y[231])
    for k in metrics.STEP_METRICS:
        np.testing.assert_allclose(default[k], explicit[k], rtol=1e-12, atol=1e-15, err_msg=k)
    assert not np.isclose(float(default["rise_time"]), float(first_sample["rise_time"]))


# ------------------------------------------------------------------ regulation


def _last_band_exit(f, band: float, t_lo: float, t_hi: float) -> float:
    """Last root of |f(t)| = band in [t_lo, t_hi], by a dense scan and brentq."""
    ts = np.linspace(t_lo, t_hi, 20001)
    g = np.abs(f(ts)) - band
    i = np.nonzero(np.sign(g[:-1]) != np.sign(g[1:]))[0][-1]
    return brentq(lambda s: abs(f(s)) - band, ts[i], ts[i + 1], xtol=1e-13)


def test_regulation_metrics_damped_oscillation():
    """y = A e^{-sigma tau} sin(omega tau), tau = t - t[0] (record starts at t = 3)."""
    A, sigma, omega = 0.3, 0.5, 3.0
    dt = 0.01
    tau = np.arange(0, 2001) * dt
    t = 3.0 + tau

    def f(s):
        return A * np.exp(-sigma * s) * np.sin(omega * s)

    y = f(tau)
    tp = np.arctan(omega / sigma) / omega
    mp = A * np.exp(-sigma * tp) * omega / np.hypot(omega, sigma)
    m = regulation_metrics(t, y)
    np.testing.assert_allclose(m["peak_deviation"], mp, rtol=1e-4)
    assert abs(float(m["peak_time"]) - tp) <= dt / 2 + 1e-12
    # Settling: last exit from |y| <= 0.02 Mp; the envelope bound ln(A/band)/sigma is an
    # upper bound and the true last exit lies within half a period of it.
    for band_abs, kwargs in ((0.02 * mp, {}), (0.1 * mp, {"abs_tol": 0.1 * mp})):
        t_env = np.log(A / band_abs) / sigma
        exact = _last_band_exit(f, band_abs, t_env - np.pi / omega, t_env)
        got = float(regulation_metrics(t, y, **kwargs)["settling_time"])
        assert abs(got - exact) < 1e-3, (band_abs, got, exact)
        assert t_env - np.pi / omega < got <= t_env
    # A constant offset shows up as steady-state error (the tail of y over the last second
    # adds a little); a reference shift cancels it.
    tail = quad(f, tau[-1] - 1.0, tau[-1])[0]
    ss = regulation_metrics(t, y + 0.05)["steady_state_error"]
    np.testing.assert_allclose(ss, -0.05 - tail, rtol=0, atol=1e-9)
    shifted = regulation_metrics(t, y + 0.05, reference=0.05)
    for k in metrics.REGULATION_METRICS:
        np.testing.assert_allclose(shifted[k], m[k], rtol=1e-9, atol=1e-12, err_msg=k)


# ------------------------------------------------------------------ error integrals, input


@pytest.mark.parametrize("t0", [0.0, 2.0])
def test_error_integrals_closed_form(t0):
    """e = ±exp(-(t - t0)) on [t0, t0 + 5]; samples before t0 are junk and must be ignored."""
    horizon = 5.0
    t = np.linspace(0.0, t0 + horizon, round((t0 + horizon) * 10_000) + 1)  # dt = 1e-4
    e = np.where(t >= t0, -np.exp(-(t - t0)), 100.0)
    m = error_integrals(t, e, t0=t0)
    ise = (1 - np.exp(-2 * horizon)) / 2
    np.testing.assert_allclose(m["ise"], ise, rtol=1e-7)
    np.testing.assert_allclose(m["iae"], 1 - np.exp(-horizon), rtol=1e-7)
    np.testing.assert_allclose(m["itae"], 1 - (horizon + 1) * np.exp(-horizon), rtol=1e-7)
    np.testing.assert_allclose(m["max_abs_error"], 1.0, rtol=1e-12)
    np.testing.assert_allclose(m["rms_error"], np.sqrt(ise / horizon), rtol=1e-7)


def test_input_metrics_known_sequence():
    t = np.array([0.0, 0.5, 1.5, 2.0, 4.0, 4.5])
    u = np.array([0.0, 1.0, -1.0, 2.0, 2.0, 0.0])
    m = input_metrics(t, u)
    assert float(m["total_variation"]) == 1 + 2 + 3 + 0 + 2
    assert float(m["peak_input"]) == 2.0
    # Trapezoids of u^2: 0.25 + 1 + 1.25 + 8 + 1
    np.testing.assert_allclose(m["control_effort"], 11.5, rtol=1e-15)
    # Chattering between ±1 at every sample: TV = 2 (N - 1), effort = duration.
    tc = np.linspace(0.0, 1.0, 1001)
    chat = input_metrics(tc, (-1.0) ** np.arange(1001))
    assert float(chat["total_variation"]) == 2000.0
    np.testing.assert_allclose(chat["control_effort"], 1.0, rtol=1e-12)


# ------------------------------------------------------------------ batch == single


def _batch() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0.0, 15.0, 1500))
    t[0] = 0.0
    rows = [
        _shape(t),
        2.0 + 0.5 * _shape(1.3 * t),
        3.0 - _shape(0.7 * t),  # downward
        1.0 - np.exp(-t) + 0.01 * rng.standard_normal(t.size),
        0.5 * (1.0 - np.exp(-t)),  # never reaches 90 % of a unit step
        1.0 + 0.5 * np.sin(t),  # never settles
        0.1 * np.sin(t),  # Delta = 0 with final = 0
        rng.standard_normal(t.size),
    ]
    y = np.vstack(rows)
    final = np.array([1.0, 2.5, 2.0, 1.0, 1.0, 1.0, 0.0, 0.3])
    initial = np.array([0.0, 2.0, 3.0, 0.0, 0.0, 1.0, 0.0, -0.2])
    return t, y, final, initial


def test_batch_equals_single_exactly():
    t, y, final, initial = _batch()
    calls = [
        (step_response_metrics, {"final": final}, True),
        (step_response_metrics, {"final": final, "initial": initial, "t_step": 0.3}, True),
        (regulation_metrics, {"reference": final, "abs_tol": 0.01}, True),
        (error_integrals, {"t0": 1.0}, False),
        (input_metrics, {}, False),
    ]
    for fn, kwargs, per_row in calls:
        batched = fn(t, y, **kwargs)
        for b in range(y.shape[0]):
            kw = {k: (v[b] if per_row and isinstance(v, np.ndarray) else v) for k, v in kwargs.items()}
            single = fn(t, y[b], **kw)
            for k, v in single.items():
                assert isinstance(v, np.ndarray) and v.shape == ()
                assert batched[k].shape == (y.shape[0],)
                np.testing.assert_array_equal(batched[k][b], v, err_msg=f"{fn.__name__} {k} {b}")


# ------------------------------------------------------------------ edge cases


def test_edge_cases():
    t = np.linspace(0.0, 10.0, 1001)
    never_settles = step_response_metrics(t, 1.0 + 0.5 * np.sin(t), final=1.0, initial=0.0)
    assert np.isnan(never_settles["settling_time"])
    assert np.isnan(regulation_metrics(t, np.sin(t))["settling_time"])
    low = step_response_metrics(t, 0.5 * (1.0 - np.exp(-t)), final=1.0)
    assert np.isnan(low["rise_time"]) and np.isnan(low["settling_time"])
    flat = step_response_metrics(t, 0.1 * np.sin(t), final=0.0)  # Delta = 0
    for k in ("rise_time", "settling_time", "overshoot", "undershoot", "peak", "peak_time"):
        assert np.isnan(flat[k]), k
    assert np.isfinite(flat["steady_state_error"])
    # Already at the final value: settled at once, rise time 0.
    at_final = step_response_metrics(t, np.ones_like(t), final=1.0, initial=0.0)
    assert float(at_final["settling_time"]) == 0.0 and float(at_final["rise_time"]) == 0.0
    # Nothing to regulate: peak deviation 0 and settled at once.
    zero = regulation_metrics(t, np.zeros_like(t))
    assert float(zero["peak_deviation"]) == 0.0 and float(zero["settling_time"]) == 0.0


def test_invalid_input_raises():
    t = np.linspace(0.0, 1.0, 11)
    with pytest.raises(ValueError, match="strictly increasing"):
        input_metrics(t[::-1], t)
    with pytest.raises(ValueError, match="samples"):
        error_integrals(t, np.zeros(10))
    with pytest.raises(ValueError, match="final"):
        step_response_metrics(t, np.zeros((2, 11)), final=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="t_step"):
        step_response_metrics(t, t, final=1.0, t_step=1.0)


def test_metric_units_cover_every_metric():
    t = np.linspace(0.0, 1.0, 11)
    names = set()
    names |= set(step_response_metrics(t, t, final=1.0))
    names |= set(regulation_metrics(t, t))
    names |= set(error_integrals(t, t))
    names |= set(input_metrics(t, t))
    assert names == set(METRIC_UNITS)
    assert {METRIC_UNITS[k] for k in ("rise_time", "settling_time", "peak_time")} == {"s"}
    assert METRIC_UNITS["overshoot"] == METRIC_UNITS["undershoot"] == "%"
    assert METRIC_UNITS["itae"] == "signal*s^2" and METRIC_UNITS["control_effort"] == "input^2*s"

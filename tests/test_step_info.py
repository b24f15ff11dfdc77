"""Tests of nlcx.metrics.step_info: python-control's and MATLAB's numbers, closed forms, batches."""

from __future__ import annotations

from functools import cache

import control
import numpy as np
import pytest

from nlcx.metrics import STEP_INFO_UNITS, step_info, step_response_metrics

# python-control's step_info keys for ours.
PC_KEYS = {
    "rise_time": "RiseTime",
    "settling_time": "SettlingTime",
    "overshoot": "Overshoot",
    "undershoot": "Undershoot",
    "peak": "Peak",
    "peak_time": "PeakTime",
    "steady_state_value": "SteadyStateValue",
    "settling_min": "SettlingMin",
    "settling_max": "SettlingMax",
}
# The values python-control computes from the same samples as we do (no crossing involved).
SAMPLE_KEYS = ("peak", "peak_time", "steady_state_value", "settling_min", "settling_max")

# MATLAB's stepinfo example, also python-control's test system siso_tf_step_matlab.
MATLAB_NUM, MATLAB_DEN = (1.0, 5.0, 5.0), (1.0, 1.65, 5.0, 6.5, 2.0)
MATLAB_PUBLISHED = {
    "rise_time": 3.8456,
    "settling_time": 27.9762,
    "settling_min": 2.0689,
    "settling_max": 2.6873,
    "overshoot": 7.4915,
    "undershoot": 0.0,
    "peak": 2.6873,
    "peak_time": 8.0530,
    "steady_state_value": 2.5,
}


@cache
def _step(num: tuple[float, ...], den: tuple[float, ...], horizon: float | None, n: int) -> tuple[np.ndarray, ...]:
    """The unit-step response of num/den on linspace(0, horizon, n), or on python-control's
    default time vector if ``horizon`` is None."""
    sys = control.tf(list(num), list(den))
    resp = control.step_response(sys) if horizon is None else control.step_response(sys, np.linspace(0, horizon, n))
    return resp.time, np.squeeze(resp.outputs)


def _assert_agrees_with_control(ours: dict[str, float], ref: dict[str, float], dt: float) -> None:
    """python-control's times are those of the first sample at or after a crossing.

    Our rise time (a difference of two interpolated crossings) is within one sample interval
    of theirs; our settling time (the band edge between their sample and the one before) is in
    [theirs - dt, theirs].  Everything else comes from the same samples.
    """
    eps = 1e-9
    assert abs(ours["rise_time"] - ref["RiseTime"]) < dt + eps
    assert ref["SettlingTime"] - dt - eps <= ours["settling_time"] <= ref["SettlingTime"] + eps
    np.testing.assert_allclose(ours["overshoot"], ref["Overshoot"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ours["undershoot"], ref["Undershoot"], rtol=1e-12, atol=1e-12)
    for key in SAMPLE_KEYS:
        assert ours[key] == ref[PC_KEYS[key]], key


# ------------------------------------------------------------------ MATLAB's example system


@pytest.mark.parametrize("grid", ["control_default", "fine"])
@pytest.mark.parametrize("final", ["reference", "last_sample"])
def test_matlab_example_agrees_with_control_on_the_same_samples(grid: str, final: str) -> None:
    horizon, n = (None, 0) if grid == "control_default" else (60.0, 6001)
    t, y = _step(MATLAB_NUM, MATLAB_DEN, horizon, n)
    dt = float(np.max(np.diff(t)))
    assert y[0] == 0.0  # python-control's and MATLAB's y_init = 0 is y(t_step) here
    if final == "reference":
        ours, ref = step_info(t, y, reference=2.5), control.step_info(y, t, yfinal=2.5)
        assert ours["steady_state_value"] == 2.5
    else:
        ours, ref = step_info(t, y), control.step_info(y, t)
        assert ours["steady_state_value"] == y[-1] != 2.5  # 60 s is not quite settled
    _assert_agrees_with_control(ours, ref, dt)
    assert ours["overshoot"] > 7.0 and ours["undershoot"] == 0.0


def test_matlab_example_reproduces_the_published_values() -> None:
    """MATLAB's stepinfo(sys) values (python-control's reference values for this system) come
    from MATLAB's own time vector: its PeakTime 8.053 is a sample 0.031 s before the true peak
    (8.0839), so its sampled Peak, Overshoot and SettlingMax are a little low.  Times agree to
    0.04 s, values to 1e-3 relative and the overshoot to 0.03 percentage points."""
    t, y = _step(MATLAB_NUM, MATLAB_DEN, 60.0, 6001)
    ours = step_info(t, y, reference=2.5)
    for key in ("rise_time", "settling_time", "peak_time"):
        assert abs(ours[key] - MATLAB_PUBLISHED[key]) < 0.04, key
    for key in ("peak", "steady_state_value", "settling_min", "settling_max"):
        np.testing.assert_allclose(ours[key], MATLAB_PUBLISHED[key], rtol=1e-3, err_msg=key)
    assert abs(ours["overshoot"] - MATLAB_PUBLISHED["overshoot"]) < 0.03
    assert ours["undershoot"] == 0.0
    # python-control's own answer for the system (its default time vector) is as far off.
    pc = control.step_info(control.tf(list(MATLAB_NUM), list(MATLAB_DEN)))
    dt_default = float(np.diff(_step(MATLAB_NUM, MATLAB_DEN, None, 0)[0])[0])
    for key in ("rise_time", "settling_time", "peak_time"):
        assert abs(pc[PC_KEYS[key]] - MATLAB_PUBLISHED[key]) < dt_default, key


def test_interpolated_crossings_converge_faster_than_sample_times() -> None:
    """On the 0.01 s grid our rise and settling times equal those on a 20x finer grid to 1e-4 s;
    python-control's sample times on the 0.01 s grid are off by up to one sample (0.01 s)."""
    t, y = _step(MATLAB_NUM, MATLAB_DEN, 60.0, 6001)
    t_fine, y_fine = _step(MATLAB_NUM, MATLAB_DEN, 60.0, 120_001)
    ours, fine = step_info(t, y, reference=2.5), step_info(t_fine, y_fine, reference=2.5)
    ref = control.step_info(y, t, yfinal=2.5)
    for key in ("rise_time", "settling_time"):
        assert abs(ours[key] - fine[key]) < 1e-4, key
        assert abs(ref[PC_KEYS[key]] - fine[key]) > 2e-3, key  # the sample-based value is not as close


# ------------------------------------------------------------------ python-control's other step_info systems

# (name, num, den, python-control's reference values from its timeresp_test.py)
PC_SYSTEMS = [
    # Non-minimum phase, positive final value: undershoot and overshoot.
    (
        "siso_tf_kpos",
        (-1.0, 1.0),
        (1.0, 1.0, 1.0),
        {"rise_time": 1.242, "settling_time": 9.110, "settling_min": 0.90, "settling_max": 1.208, "overshoot": 20.840,
         "undershoot": 28.0, "peak": 1.208, "peak_time": 4.282, "steady_state_value": 1.0},
    ),
    # The same with a negative final value.
    (
        "siso_tf_kneg",
        (1.0, -1.0),
        (1.0, 1.0, 1.0),
        {"rise_time": 1.242, "settling_time": 9.110, "settling_min": -1.208, "settling_max": -0.90, "overshoot": 20.840,
         "undershoot": 28.0, "peak": 1.208, "peak_time": 4.282, "steady_state_value": -1.0},
    ),
]  # fmt: skip


@pytest.mark.parametrize(("name", "num", "den", "published"), PC_SYSTEMS, ids=[c[0] for c in PC_SYSTEMS])
def test_control_test_systems(name: str, num: tuple, den: tuple, published: dict[str, float]) -> None:
    t, y = _step(num, den, 30.0, 30_001)
    dc = float(np.real(control.tf(list(num), list(den)).dcgain()))
    ours = step_info(t, y, reference=dc)
    _assert_agrees_with_control(ours, control.step_info(y, t, yfinal=dc), dt=t[1] - t[0])
    # python-control's test tolerances: times to its default sample interval, values to 0.5 %.
    dt = float(np.diff(_step(num, den, None, 0)[0])[0])
    for key in ("rise_time", "settling_time", "peak_time"):
        assert abs(ours[key] - published[key]) < dt, key
    for key in ("overshoot", "undershoot", "peak", "steady_state_value", "settling_min", "settling_max"):
        np.testing.assert_allclose(ours[key], published[key], rtol=5e-3, err_msg=key)
    assert ours["undershoot"] > 25.0 and ours["overshoot"] > 20.0


def test_response_starting_at_minus_one_closed_form() -> None:
    """python-control's siso_tf_asymptotic_from_neg1, (1 - s)/(s + 1): y = 1 - 2 e^{-t}.

    With MATLAB's y_init = 0 (``y_initial=0.0``) the rise levels are 0.1 and 0.9, so the rise
    time is ln 9, the 2 % band is |y - 1| <= 0.02, so the settling time is ln 100, and the
    undershoot is 100 %.  Our default y_init = y(0) = -1 gives a step of 2: the rise time is
    again ln 9, the band is 0.04 wide (ln 50) and there is no undershoot.
    """
    t, y = _step((-1.0, 1.0), (1.0, 1.0), 10.0, 10_001)
    matlab = step_info(t, y, reference=1.0, y_initial=0.0)
    assert abs(matlab["rise_time"] - np.log(9.0)) < 1e-6
    assert abs(matlab["settling_time"] - np.log(100.0)) < 1e-6
    assert matlab["undershoot"] == pytest.approx(100.0, abs=1e-9)
    assert matlab["peak"] == 1.0 and matlab["peak_time"] == 0.0
    _assert_agrees_with_control(matlab, control.step_info(y, t, yfinal=1.0), dt=t[1] - t[0])
    own = step_info(t, y, reference=1.0)
    assert abs(own["rise_time"] - np.log(9.0)) < 1e-6
    assert abs(own["settling_time"] - np.log(50.0)) < 1e-6
    assert own["undershoot"] == 0.0


# ------------------------------------------------------------------ definitions shared with nlcx run


def test_same_step_definitions_as_step_response_metrics() -> None:
    t, y = _step(MATLAB_NUM, MATLAB_DEN, 60.0, 6001)
    ours = step_info(t, y, reference=2.5)
    run = step_response_metrics(t, y, final=2.5)
    for key in ("rise_time", "settling_time", "overshoot", "undershoot", "peak", "peak_time"):
        assert ours[key] == float(run[key]), key  # peak too: y > 0, so max |y| = max y


def test_offset_and_delayed_step_change_only_the_values() -> None:
    """A response sitting at 20 until a step at t = 3 s, then rising by 2.5: the same times and
    percentages as the response from 0 at t = 0, and values shifted by 20."""
    t0, y0 = _step(MATLAB_NUM, MATLAB_DEN, 60.0, 6001)
    t = np.concatenate([0.01 * np.arange(300), 3.0 + t0])
    y = 20.0 + np.concatenate([np.zeros(300), y0])
    base = step_info(t0, y0, reference=2.5)
    moved = step_info(t, y, t_step=3.0, reference=22.5)  # y_initial = y(3) = 20
    for key in ("rise_time", "settling_time", "overshoot", "undershoot", "peak_time"):
        np.testing.assert_allclose(moved[key], base[key], rtol=0, atol=1e-9, err_msg=key)
    for key in ("steady_state_value", "settling_min", "settling_max", "peak"):
        np.testing.assert_allclose(moved[key], base[key] + 20.0, rtol=0, atol=1e-9, err_msg=key)
    # Without t_step the record from t = 0 counts and nothing happens before 3 s.
    assert step_info(t, y, reference=22.5)["settling_time"] > base["settling_time"] + 2.9


# ------------------------------------------------------------------ batches


def _batch() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 30.0, 3001)
    rows = [np.interp(t, *_step(num, den, 30.0, 30_001)) for _, num, den, _ in PC_SYSTEMS]
    rows += [
        np.interp(t, *_step(MATLAB_NUM, MATLAB_DEN, 60.0, 6001)),
        1.0 - 2.0 * np.exp(-t),  # starts at -1
        np.full_like(t, 0.7),  # flat: no step
        0.5 * (1.0 - np.exp(-t)),  # never reaches the reference 1
        1.0 + 0.5 * np.sin(t),  # never settles
    ]
    reference = np.array([1.0, -1.0, 2.5, 1.0, 0.7, 1.0, 1.0])
    initial = np.array([0.0, 0.0, 0.0, -1.0, 0.7, 0.0, 0.0])
    return t, np.vstack(rows), reference, initial


@pytest.mark.parametrize(
    "kwargs",
    [{}, {"reference": "rows"}, {"reference": 1.0, "y_initial": "rows", "t_step": 0.123}],
    ids=["own_final", "reference_per_row", "scalar_reference_t_step"],
)
def test_batch_equals_single_exactly(kwargs: dict) -> None:
    t, y, reference, initial = _batch()
    rows_of = {"reference": reference, "y_initial": initial}
    batch_kw = {k: rows_of[k] if v == "rows" else v for k, v in kwargs.items()}
    batched = step_info(t, y, **batch_kw)
    assert set(batched) == set(STEP_INFO_UNITS)
    for b in range(y.shape[0]):
        single = step_info(t, y[b], **{k: rows_of[k][b] if v == "rows" else v for k, v in kwargs.items()})
        for key, value in single.items():
            assert type(value) is float
            assert batched[key].shape == (y.shape[0],) and batched[key].dtype == np.float64
            np.testing.assert_array_equal(batched[key][b], value, err_msg=f"{key} row {b}")


def test_unsettled_and_degenerate_rows() -> None:
    t, y, reference, initial = _batch()
    m = step_info(t, y, reference=reference, y_initial=initial)
    flat, low, unsettled = 4, 5, 6
    for key in ("rise_time", "settling_time", "overshoot", "undershoot", "settling_min", "settling_max"):
        assert np.isnan(m[key][flat]), key
    assert m["peak"][flat] == 0.7 and m["peak_time"][flat] == 0.0 and m["steady_state_value"][flat] == 0.7
    assert np.isnan(m["rise_time"][low]) and np.isnan(m["settling_min"][low]) and np.isnan(m["settling_time"][low])
    assert np.isnan(m["settling_time"][unsettled]) and np.isfinite(m["rise_time"][unsettled])
    assert np.all(np.isfinite(m["settling_time"][:4]))


def test_invalid_input_raises() -> None:
    t = np.linspace(0.0, 1.0, 11)
    with pytest.raises(ValueError, match="rise_limits"):
        step_info(t, t, rise_limits=(0.9, 0.1))
    with pytest.raises(ValueError, match="band"):
        step_info(t, t, settling_band=0.0)
    with pytest.raises(ValueError, match="reference"):
        step_info(t, np.zeros((2, 11)), reference=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="y_initial"):
        step_info(t, t, t_step=-1.0)
    with pytest.raises(ValueError, match="t_step"):
        step_info(t, t, t_step=1.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        step_info(t[::-1], t)

"""Gain schedules against eqs. 2.17-2.22: end values, monotone shape and exact formula."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nlcx.controllers.schedules import (
    Constant,
    ConstantConfig,
    ErrorAGS,
    ErrorAGSConfig,
    TimeAGS,
    TimeAGSConfig,
    constant_gains,
    error_ags_gains,
    time_ags_gains,
)

RANGES = {"kp": {"min": 24, "max": 36}, "ki": {"min": 1.5, "max": 3.6}, "kd": {"min": 3, "max": 5}}
RATES = {"kp": 0.1, "ki": 0.1, "kd": 0.05}


def gains(fn, sp: np.ndarray, t: float = 0.0, e: float = 0.0) -> np.ndarray:
    """The compiled schedule with its parameters in row 1 of a 2-row table, after 2 others."""
    row = np.concatenate([[-7.0, 3.0], sp])
    p = np.stack([np.zeros_like(row), row])
    return np.array(fn(float(t), float(e), 0.0, p, 1, 2))


def test_constant_schedule_is_constant() -> None:
    sp = Constant().pack(ConstantConfig(kp=30, ki=2.5, kd=4))
    for t, e in [(0, 0), (5, 1.0), (1e6, -3.0)]:
        assert np.array_equal(gains(constant_gains, sp, t, e), [30, 2.5, 4])


def test_time_ags_end_values_eqs_2_17_to_2_19() -> None:
    sp = TimeAGS().pack(TimeAGSConfig(**RANGES, rate=RATES))
    # t = 0: kp = kp_max, ki = ki_min, kd = kd_max
    assert np.allclose(gains(time_ags_gains, sp, t=0), [36, 1.5, 5])
    # t -> infinity: kp = kp_min, ki = ki_max, kd = kd_min
    assert np.allclose(gains(time_ags_gains, sp, t=1e4), [24, 3.6, 3])


def test_time_ags_shape_and_formula() -> None:
    sp = TimeAGS().pack(TimeAGSConfig(**RANGES, rate=RATES))
    ts = np.linspace(0, 60, 301)
    g = np.array([gains(time_ags_gains, sp, t=t) for t in ts])
    assert np.all(np.diff(g[:, 0]) < 0) and np.all(np.diff(g[:, 1]) > 0) and np.all(np.diff(g[:, 2]) < 0)
    t = 7.3
    expected = [
        24 + (36 - 24) * math.exp(-0.1 * t),
        3.6 - (3.6 - 1.5) * math.exp(-0.1 * t),
        3 + (5 - 3) * math.exp(-0.05 * t),
    ]
    assert np.allclose(gains(time_ags_gains, sp, t=t), expected, rtol=0, atol=1e-12)
    # one time constant 1/k: the gain has travelled 1 - 1/e of its range
    assert gains(time_ags_gains, sp, t=10.0)[0] == pytest.approx(24 + 12 / math.e)


def test_error_ags_end_values_eqs_2_20_to_2_22() -> None:
    sp = ErrorAGS().pack(ErrorAGSConfig(**RANGES, rate=RATES))
    # e = 0: kp = kp_min, ki = ki_max, kd = kd_min
    assert np.allclose(gains(error_ags_gains, sp, e=0), [24, 3.6, 3])
    # |e| -> infinity: kp = kp_max, ki = ki_min, kd = kd_max
    assert np.allclose(gains(error_ags_gains, sp, e=1e4), [36, 1.5, 5])
    assert np.allclose(gains(error_ags_gains, sp, e=-1e4), [36, 1.5, 5])  # |e| by default


def test_error_ags_shape_and_formula() -> None:
    sp = ErrorAGS().pack(ErrorAGSConfig(**RANGES, rate=RATES))
    es = np.linspace(0, 40, 201)
    g = np.array([gains(error_ags_gains, sp, e=e) for e in es])
    assert np.all(np.diff(g[:, 0]) > 0) and np.all(np.diff(g[:, 1]) < 0) and np.all(np.diff(g[:, 2]) > 0)
    e = 0.8
    expected = [
        36 - (36 - 24) * math.exp(-0.1 * e),
        1.5 - (1.5 - 3.6) * math.exp(-0.1 * e),
        5 - (5 - 3) * math.exp(-0.05 * e),
    ]
    assert np.allclose(gains(error_ags_gains, sp, e=e), expected, rtol=0, atol=1e-12)
    assert np.array_equal(gains(error_ags_gains, sp, e=-e), gains(error_ags_gains, sp, e=e))


def test_error_ags_signed_follows_the_printed_formula() -> None:
    """error: signed uses e(t) as printed, so a negative error leaves the printed range."""
    sp = ErrorAGS().pack(ErrorAGSConfig(**RANGES, rate=RATES, error="signed"))
    e = -2.0
    kp = gains(error_ags_gains, sp, e=e)[0]
    assert kp == pytest.approx(36 - 12 * math.exp(0.2))
    assert kp < 24


def test_reversed_range_as_printed_for_the_z_loop() -> None:
    """Table 3.6 prints kp 'min' 25 and 'max' 15: the formulas are applied literally."""
    cfg = TimeAGSConfig(kp={"min": 25, "max": 15}, ki={"min": 15, "max": 10}, kd={"min": 15, "max": 10}, rate=RATES)
    sp = TimeAGS().pack(cfg)
    assert np.allclose(gains(time_ags_gains, sp, t=0), [15, 15, 10])
    assert np.allclose(gains(time_ags_gains, sp, t=1e4), [25, 10, 15])


def test_error_ags_argument_scale_multiplies_only_the_schedules_argument() -> None:
    """error_scale c: the gains at e are eqs. 2.20-2.22 at s = |c e| (c = 180/pi: e in degrees)."""
    c = 180 / math.pi
    scaled = ErrorAGS().pack(ErrorAGSConfig(**RANGES, rate=RATES, error_scale=c))
    plain = ErrorAGS().pack(ErrorAGSConfig(**RANGES, rate=RATES))
    for e in (-0.3, 0.01, 0.2):
        assert np.array_equal(gains(error_ags_gains, scaled, e=e), gains(error_ags_gains, plain, e=e * c))
    assert not np.allclose(gains(error_ags_gains, scaled, e=0.2), gains(error_ags_gains, plain, e=0.2))

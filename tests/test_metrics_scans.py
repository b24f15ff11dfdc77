"""The compiled row scans of nlcx.metrics.scans equal their numpy formulation to the last bit.

The scans (first crossing, last exit, extremes, deviation peak, the trapezoid terms the
integrals sum) replaced whole-array numpy passes; each is checked here against the numpy
formulation it replaced, on random rows with NaNs, plateaus and steps of either sign, bit
for bit (NaN where NaN).
"""

from __future__ import annotations

import numpy as np
import pytest

from nlcx.metrics import scans


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    return bool(np.array_equal(nan_a, nan_b) and np.array_equal(a[~nan_a].view(np.int64), b[~nan_b].view(np.int64)))


def rows(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A time grid and rows of rising, falling, flat, rounded and NaN-holding responses."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 400))
    tau = np.cumsum(rng.uniform(0.001, 0.02, n)) - rng.uniform(0, 0.01)
    y = np.cumsum(rng.normal(0.0, 0.05, (12, n)), axis=1) + rng.uniform(-1, 2, (12, 1)) * np.linspace(0, 1, n)
    y[1] = np.round(y[1], 1)
    y[2, : n // 2] = 1.0
    y[3, rng.integers(0, n)] = np.nan
    y[4] = -y[4]
    return tau, y


def numpy_first_crossing(tau, sy, s_level):
    rows_ = np.arange(sy.shape[0])
    cond = sy >= s_level[:, np.newaxis]
    idx = np.argmax(cond, axis=1)
    prev = np.maximum(idx - 1, 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(idx > 0, (s_level - sy[rows_, prev]) / (sy[rows_, idx] - sy[rows_, prev]), 0.0)
    t = tau[prev] + np.clip(frac, 0.0, 1.0) * (tau[idx] - tau[prev])
    return np.where(cond.any(axis=1), t, np.nan), idx


def numpy_last_exit(tau, y, center, band_abs):
    n = y.shape[1]
    rows_ = np.arange(y.shape[0])
    dev = y - center[:, np.newaxis]
    outside = np.abs(dev) > band_abs[:, np.newaxis]
    k = (n - 1) - np.argmax(outside[:, ::-1], axis=1)
    k1 = np.minimum(k + 1, n - 1)
    edge = np.sign(dev[rows_, k]) * band_abs
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.clip((dev[rows_, k] - edge) / (dev[rows_, k] - dev[rows_, k1]), 0.0, 1.0)
    t = np.where(k == n - 1, np.nan, tau[k] + frac * (tau[k1] - tau[k]))
    return np.where(outside.any(axis=1), t, 0.0)


def numpy_trapz_terms(t, y):
    s = np.add(y[:, 1:], y[:, :-1])
    s *= 0.5
    s *= np.diff(t)
    return s


@pytest.mark.parametrize("seed", range(40))
def test_scans_equal_their_numpy_formulation(seed: int) -> None:
    tau, y = rows(seed)
    rng = np.random.default_rng(seed + 1000)
    s = rng.choice([-1.0, 0.0, 1.0], y.shape[0])
    level = s * rng.uniform(-1, 2, y.shape[0])
    sy = s[:, np.newaxis] * y
    t_cross, index = scans.first_crossing(tau, y, s, level)
    t_np, index_np = numpy_first_crossing(tau, sy, level)
    assert same_bits(t_cross, t_np)
    found = ~np.isnan(t_np)
    assert np.array_equal(index[found], index_np[found])
    center, band = rng.uniform(-1, 2, y.shape[0]), rng.uniform(0, 0.3, y.shape[0])
    assert same_bits(scans.last_exit(tau, y, center, band), numpy_last_exit(tau, y, center, band))
    s_final, s_initial = s * center, s * rng.uniform(-1, 1, y.shape[0])
    over, under, peak = scans.extremes(y, s, s_final, s_initial)
    for ours, theirs in ((over, np.max(sy - s_final[:, np.newaxis], axis=1)),
                         (under, np.max(s_initial[:, np.newaxis] - sy, axis=1))):  # fmt: skip
        # equal values; numpy's SIMD max returns either zero of a row holding +0 and -0, and
        # the overshoot takes np.maximum(max, 0.0), which is +0.0 for both: the same bits
        assert np.array_equal(ours, theirs, equal_nan=True)
        assert same_bits(np.maximum(ours, 0.0), np.maximum(theirs, 0.0))
    assert np.array_equal(peak, np.argmax(sy, axis=1))
    index, deviation = scans.deviation_peak(y, center)
    absdev = np.abs(y - center[:, np.newaxis])
    assert np.array_equal(index, np.argmax(absdev, axis=1))
    assert same_bits(deviation, absdev[np.arange(y.shape[0]), index])


@pytest.mark.parametrize("seed", range(20))
def test_integral_terms_equal_the_trapezoid_numpy_formed(seed: int) -> None:
    t, e = rows(seed)
    start = t[0] - 0.003
    squared, absolute, weighted, max_abs = scans.error_terms(t, e, start)
    assert same_bits(squared, numpy_trapz_terms(t, e * e))
    assert same_bits(absolute, numpy_trapz_terms(t, np.abs(e)))
    assert same_bits(weighted, numpy_trapz_terms(t, (t - start) * np.abs(e)))
    assert same_bits(max_abs, np.max(np.abs(e), axis=1))
    squared, steps, peak = scans.input_terms(t, e)
    assert same_bits(squared, numpy_trapz_terms(t, e * e))
    assert same_bits(steps, np.abs(np.diff(e, axis=1)))
    assert same_bits(peak, np.max(np.abs(e), axis=1))

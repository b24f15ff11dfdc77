"""The metric kernels' parts equal their numpy formulation to the last bit.

The searches along a row (:mod:`nlcx.metrics.scans`: first crossing, last exit, extremes,
deviation peak) and the pairwise trapezoid sums (:mod:`nlcx.metrics.sums`) are checked here
against the numpy formulation of each, on random rows with NaNs, plateaus and steps of either
sign, bit for bit (NaN where NaN); the kernels over a batch against the same kernels row by row.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from numba import njit

from nlcx import metrics
from nlcx.metrics import scans, sums

Row = np.ndarray

# The scans and sums are compiled for compiled callers only (no Python wrapper): each is called
# here through a compiled function that passes its arguments on.


@njit
def first_crossing(t: Row, y: Row, first: int, t0: float, s: float, level: float) -> tuple[float, int]:
    return scans.first_crossing(t, y, first, t0, s, level)


@njit
def last_exit(t: Row, y: Row, first: int, t0: float, center: float, band: float) -> float:
    return scans.last_exit(t, y, first, t0, center, band)


@njit
def extremes(y: Row, first: int, s: float, s_final: float, s_initial: float) -> tuple[float, float, int]:
    return scans.extremes(y, first, s, s_final, s_initial)


@njit
def deviation_peak(y: Row, first: int, center: float) -> int:
    return scans.deviation_peak(y, first, center)


@njit
def max_abs(y: Row, first: int) -> float:
    return scans.max_abs(y, first)


@njit
def np_maximum(a: float, b: float) -> float:
    return scans.np_maximum(a, b)


@njit
def np_minimum(a: float, b: float) -> float:
    return scans.np_minimum(a, b)


@njit
def search_right(t: Row, first: int, value: float) -> int:
    return scans.search_right(t, first, value)


@njit
def pairwise_sums(
    kind: int, t: Row, y: Row, ref: Row, start: float, lo: int, n: int, ranges: np.ndarray, partial: np.ndarray
) -> tuple[float, float, float]:
    return sums.pairwise_sums(kind, t, y, ref, start, lo, n, ranges, partial)


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


def per_row(fn, y, *columns):
    """``fn`` of each row of y (the row, then the row's entry of each column), stacked."""
    return [fn(y[b], *(c[b] for c in columns)) for b in range(y.shape[0])]


@pytest.mark.parametrize("seed", range(40))
def test_scans_equal_their_numpy_formulation(seed: int) -> None:
    tau, y = rows(seed)
    rng = np.random.default_rng(seed + 1000)
    s = rng.choice([-1.0, 0.0, 1.0], y.shape[0])
    level = s * rng.uniform(-1, 2, y.shape[0])
    sy = s[:, np.newaxis] * y
    t0 = float(rng.uniform(-0.01, 0.01))
    t = tau + t0  # the scans measure from t0: tau = t - t0, formed sample by sample
    crossings = per_row(lambda row, s_b, level_b: first_crossing(t, row, 0, t0, s_b, level_b), y, s, level)
    t_np, index_np = numpy_first_crossing(t - t0, sy, level)
    assert same_bits(np.array([c[0] for c in crossings]), t_np)
    found = ~np.isnan(t_np)
    assert np.array_equal(np.array([c[1] for c in crossings])[found], index_np[found])
    center, band = rng.uniform(-1, 2, y.shape[0]), rng.uniform(0, 0.3, y.shape[0])
    exits = per_row(lambda row, c, b: last_exit(t, row, 0, t0, c, b), y, center, band)
    assert same_bits(np.array(exits), numpy_last_exit(t - t0, y, center, band))
    s_final, s_initial = s * center, s * rng.uniform(-1, 1, y.shape[0])
    found = per_row(lambda row, a, b, c: extremes(row, 0, a, b, c), y, s, s_final, s_initial)
    over, under, peak = (np.array(column) for column in zip(*found, strict=True))
    for ours, theirs in ((over, np.max(sy - s_final[:, np.newaxis], axis=1)),
                         (under, np.max(s_initial[:, np.newaxis] - sy, axis=1))):  # fmt: skip
        # equal values; numpy's SIMD max returns either zero of a row holding +0 and -0, and
        # the overshoot takes np.maximum(max, 0.0), which is +0.0 for both: the same bits
        assert np.array_equal(ours, theirs, equal_nan=True)
        assert same_bits(np.maximum(ours, 0.0), np.maximum(theirs, 0.0))
    assert np.array_equal(peak, np.argmax(sy, axis=1))
    index = np.array(per_row(lambda row, c: deviation_peak(row, 0, c), y, center))
    absdev = np.abs(y - center[:, np.newaxis])
    assert np.array_equal(index, np.argmax(absdev, axis=1))
    assert same_bits(np.array(per_row(lambda row: max_abs(row, 0), y)), np.max(np.abs(y), axis=1))


def test_two_value_extremes_are_numpys() -> None:
    """np_maximum/np_minimum of every pair of signed zeros, NaN, infinities and numbers: numpy's
    value and sign (of two equal values numpy returns the second)."""
    values = [0.0, -0.0, np.nan, np.inf, -np.inf, 1.0, -1.0, 2.5]
    for a, b in itertools.product(values, repeat=2):
        for ours, theirs in ((np_maximum(a, b), np.maximum(a, b)), (np_minimum(a, b), np.minimum(a, b))):
            assert same_bits(np.array([ours]), np.array([theirs]))


def test_search_right_is_searchsorted() -> None:
    t = np.cumsum(np.random.default_rng(3).uniform(0.001, 0.1, 300))
    for value in [t[0] - 1, *t[::7], *(t[::11] + 1e-4), t[-1] + 1]:
        for first in (0, 5):
            expected = first + int(np.searchsorted(t[first:], value, side="right"))
            assert search_right(t, first, value) == expected


def _terms(kind: int, t: np.ndarray, y: np.ndarray, ref: np.ndarray, start: float) -> list[np.ndarray]:
    """The trapezoid terms of ``kind`` formed with numpy, each an array (nlcx.metrics.sums)."""
    dt = np.diff(t)
    if kind == sums.ERRORS:
        e = ref - y
        a = np.abs(e)
        return [numpy_trapz_terms(t, (e * e)[None])[0], numpy_trapz_terms(t, a[None])[0],
                numpy_trapz_terms(t, ((t - start) * a)[None])[0]]  # fmt: skip
    if kind == sums.TRAPEZOID:
        return [((y[1:] + y[:-1]) * 0.5) * dt]
    return [numpy_trapz_terms(t, (y * y)[None])[0], np.abs(np.diff(y))]


@pytest.mark.parametrize("n", [1, 2, 7, 8, 9, 15, 16, 128, 129, 130, 136, 257, 1000, 4097, 20001, 100003])
def test_pairwise_sums_are_numpys_sums(n: int) -> None:
    """The sums of the trapezoid terms are np.sum of the terms formed as arrays, bit for bit,
    for rows short and long (numpy's blocks of 8 and 128 and its halving)."""
    rng = np.random.default_rng(n)
    t = np.cumsum(rng.uniform(0.001, 0.01, n + 1))
    y = rng.standard_normal(n + 1) * 10.0 ** rng.integers(-6, 6, n + 1)
    ref = rng.standard_normal(n + 1)
    ranges, partial = sums.stack()
    for kind in (sums.ERRORS, sums.TRAPEZOID, sums.INPUT):
        ours = pairwise_sums(kind, t, y, ref, t[0] - 0.3, 0, n, ranges, partial)
        for value, terms in zip(ours, _terms(kind, t, y, ref, t[0] - 0.3), strict=False):
            assert same_bits(np.array([value]), np.array([np.sum(terms)]))
    lo = n // 3  # a range that starts inside the row: the sum of terms lo .. n-1
    ours = pairwise_sums(sums.TRAPEZOID, t, y, y, 0.0, lo, n - lo, ranges, partial)
    assert same_bits(np.array([ours[0]]), np.array([np.sum(_terms(sums.TRAPEZOID, t[lo:], y[lo:], y[lo:], 0.0)[0])]))


@pytest.mark.parametrize("seed", range(6))
def test_a_batch_is_its_rows(seed: int) -> None:
    """Every public metric function of a batch equals the same function of each row alone."""
    t, y = rows(seed)
    t = t - t[0]
    calls = (
        lambda rows_: metrics.step_response_metrics(t, rows_, t_step=t[3], final=1.0, ss_window=0.5),
        lambda rows_: metrics.step_info(t, rows_, t_step=t[1]),
        lambda rows_: metrics.regulation_metrics(t, rows_, reference=0.2, abs_tol=0.01),
        lambda rows_: metrics.error_integrals(t, rows_, t0=t[2]),
        lambda rows_: metrics.input_metrics(t, rows_),
    )
    for call in calls:
        batch = call(y)
        for b in range(y.shape[0]):
            alone = call(y[b])
            for name, value in batch.items():
                assert same_bits(np.array([value[b]]), np.array([alone[name]]))

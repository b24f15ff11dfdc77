"""The compiled row scans behind the metrics: searches along each row and the terms of its sums.

The searches along a row (crossings, last exits, extremes) and the terms of the trapezoidal
sums are each one pass that stops as early as it can; the sums are numpy's (pairwise), so
every value is the numpy formulation's to the last bit (tests/test_metrics_scans.py).
Crossing times are interpolated linearly between samples (the signal is treated as
piecewise linear), so they are not quantised to the grid.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def _argmax(a):  # pragma: no cover - compiled
    """numpy's argmax of a row: the first maximum, or the first NaN."""
    best, at = a[0], 0
    if best != best:
        return 0
    for i in range(1, a.shape[0]):
        v = a[i]
        if v != v:
            return i
        if v > best:
            best, at = v, i
    return at


@njit(cache=True, error_model="numpy")
def _clip01(x):  # pragma: no cover - compiled
    """np.clip(x, 0, 1): NaN stays NaN, -0.0 stays -0.0."""
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@njit(cache=True, error_model="numpy")
def _first_crossing_row(tau, y, s, s_level):  # pragma: no cover - compiled
    """(time, index) of the first sample of the row ``y`` with s*y >= s_level, the time
    interpolated linearly from the sample before; (NaN, 0) if none."""
    for i in range(y.shape[0]):
        if s * y[i] >= s_level:
            if i == 0:
                return tau[0] + 0.0 * (tau[0] - tau[0]), 0
            prev = s * y[i - 1]
            frac = _clip01((s_level - prev) / (s * y[i] - prev))
            return tau[i - 1] + frac * (tau[i] - tau[i - 1]), i
    return np.nan, 0


@njit(cache=True, error_model="numpy")
def first_crossing(tau, y, s, s_level):  # pragma: no cover - compiled
    """First time each row of ``y`` reaches its level: s*y >= s_level, with s = ``s[b]`` and
    s_level = ``s_level[b]`` (s = sign of the step, so s*(y - level) >= 0).  If the first
    sample already satisfies it the result is ``tau[0]``; otherwise the crossing is
    interpolated linearly between the last sample before and the first sample that satisfies
    it.  NaN if it is never reached.  Also returns the index of that first sample (0 where
    the time is NaN)."""
    n_rows = y.shape[0]
    t_cross = np.empty(n_rows)
    index = np.zeros(n_rows, dtype=np.intp)
    for b in range(n_rows):
        t_cross[b], index[b] = _first_crossing_row(tau, y[b], s[b], s_level[b])
    return t_cross, index


@njit(cache=True, error_model="numpy")
def last_exit(tau, y, center, band_abs):  # pragma: no cover - compiled
    """Time of the last exit of each row from ``|y - center| <= band_abs`` (last-exit rule).

    With k the last index where ``|y_k - center| > band_abs``: no such k gives 0, k the last
    sample gives NaN (not settled within the record), otherwise the time where the piecewise
    linear signal between samples k and k+1 meets the band edge on the side of ``y_k``,
    ``center + sign(y_k - center) * band_abs``.
    """
    n_rows, n = y.shape
    out = np.empty(n_rows)
    for b in range(n_rows):
        c, band = center[b], band_abs[b]
        k = n - 1
        while k >= 0 and not abs(y[b, k] - c) > band:
            k -= 1
        if k < 0:
            out[b] = 0.0
        elif k == n - 1:
            out[b] = np.nan
        else:
            d_k, d_k1 = y[b, k] - c, y[b, k + 1] - c
            edge = (1.0 if d_k > 0.0 else -1.0) * band
            out[b] = tau[k] + _clip01((d_k - edge) / (d_k - d_k1)) * (tau[k + 1] - tau[k])
    return out


@njit(cache=True, error_model="numpy")
def extremes(y, s, s_final, s_initial):  # pragma: no cover - compiled
    """Per row b: max(s*y - s_final) and max(s_initial - s*y), each NaN if a term is NaN (as
    np.max), and the index of the first maximum of s*y (as np.argmax); s = ``s[b]``."""
    n_rows, n = y.shape
    over, under = np.empty(n_rows), np.empty(n_rows)
    peak = np.zeros(n_rows, dtype=np.intp)
    sy = np.empty(n)
    for b in range(n_rows):
        hi, lo, hi_nan, lo_nan = -np.inf, -np.inf, False, False
        s_b, final_b, initial_b = s[b], s_final[b], s_initial[b]
        for i in range(n):
            v = s_b * y[b, i]
            sy[i] = v
            a, c = v - final_b, initial_b - v
            hi_nan, lo_nan = hi_nan or a != a, lo_nan or c != c
            hi = a if a > hi else hi
            lo = c if c > lo else lo
        over[b] = np.nan if hi_nan else hi
        under[b] = np.nan if lo_nan else lo
        peak[b] = _argmax(sy)
    return over, under, peak


@njit(cache=True, error_model="numpy")
def deviation_peak(y, reference):  # pragma: no cover - compiled
    """Per row b: the index of the first maximum of |y - reference[b]| (or of its first NaN,
    as np.argmax) and that deviation."""
    n_rows, n = y.shape
    index = np.zeros(n_rows, dtype=np.intp)
    peak = np.empty(n_rows)
    dev = np.empty(n)
    for b in range(n_rows):
        for i in range(n):
            dev[i] = abs(y[b, i] - reference[b])
        index[b] = _argmax(dev)
        peak[b] = dev[index[b]]
    return index, peak


@njit(cache=True, error_model="numpy")
def _max_abs(y, b):  # pragma: no cover - compiled
    """max |y[b]|, NaN if the row holds a NaN (as np.max)."""
    m = -np.inf
    for i in range(y.shape[1]):
        a = abs(y[b, i])
        if a != a:
            return np.nan
        m = a if a > m else m
    return m


@njit(cache=True, error_model="numpy")
def _steps(t):  # pragma: no cover - compiled
    """t[k + 1] - t[k]: the grid's steps, formed once for every row of a scan."""
    dt = np.empty(t.shape[0] - 1)
    for k in range(t.shape[0] - 1):
        dt[k] = t[k + 1] - t[k]
    return dt


@njit(cache=True, error_model="numpy")
def error_terms(t, e, start):  # pragma: no cover - compiled
    """The terms of the trapezoidal sums of e^2, |e| and (t - start) |e| over each row of e
    (samples at t), as :func:`nlcx.metrics.rows.trapz` forms them, and max |e| per row. Summed by numpy
    (pairwise), they are the integrals of :func:`nlcx.metrics.error_integrals` to the last bit."""
    n_rows, n = e.shape
    squared, absolute, weighted = np.empty((n_rows, n - 1)), np.empty((n_rows, n - 1)), np.empty((n_rows, n - 1))
    max_abs = np.empty(n_rows)
    dt, elapsed = _steps(t), t - start
    for b in range(n_rows):
        for k in range(n - 1):
            e0, e1 = e[b, k], e[b, k + 1]
            a0, a1 = abs(e0), abs(e1)
            squared[b, k] = ((e1 * e1 + e0 * e0) * 0.5) * dt[k]
            absolute[b, k] = ((a1 + a0) * 0.5) * dt[k]
            weighted[b, k] = ((elapsed[k + 1] * a1 + elapsed[k] * a0) * 0.5) * dt[k]
        max_abs[b] = _max_abs(e, b)
    return squared, absolute, weighted, max_abs


@njit(cache=True, error_model="numpy")
def input_terms(t, u):  # pragma: no cover - compiled
    """The terms of the trapezoidal sum of u^2 and of the total variation sum |u_k - u_{k-1}|
    over each row of u, and max |u| per row (numpy sums them)."""
    n_rows, n = u.shape
    squared, steps = np.empty((n_rows, n - 1)), np.empty((n_rows, n - 1))
    peak = np.empty(n_rows)
    dt = _steps(t)
    for b in range(n_rows):
        for k in range(n - 1):
            u0, u1 = u[b, k], u[b, k + 1]
            squared[b, k] = ((u1 * u1 + u0 * u0) * 0.5) * dt[k]
            steps[b, k] = abs(u1 - u0)
        peak[b] = _max_abs(u, b)
    return squared, steps, peak

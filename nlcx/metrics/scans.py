"""The searches along one row of samples that the metrics are made of.

Each function reads one row ``y`` (a 1-D array: a signal's samples on the grid ``t``) from
sample ``first`` to its end, and stops as early as it can. Times are measured from an origin
``t0`` (tau = t - t0, formed sample by sample); crossing times are interpolated linearly
between samples (the signal is treated as piecewise linear), so they are not quantised to the
grid. Comparisons follow numpy's: a maximum is the first one, or the first NaN (np.argmax),
and :func:`np_maximum`/:func:`np_minimum` are np.maximum/np.minimum of two values.

The same functions run on the CPU, called by :mod:`nlcx.metrics.kernels`, and on the GPU,
compiled from this source as device functions (:class:`nlcx.kernel.device.Retarget`): they use
only scalar arithmetic and :mod:`math`. Only compiled code calls them: they are compiled without
the wrappers that would let Python call them (:func:`nlcx._numba_compat.inner_njit`).
"""

from __future__ import annotations

import math

from nlcx._numba_compat import inner_njit
from nlcx.kernel.signatures import FloatArray


@inner_njit(cache=True, error_model="numpy")
def clip01(x: float) -> float:  # pragma: no cover - compiled
    """np.clip(x, 0, 1): NaN stays NaN, -0.0 stays -0.0."""
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@inner_njit(cache=True, error_model="numpy")
def sign(x: float) -> float:  # pragma: no cover - compiled
    """np.sign(x): -1, 0 or 1, NaN for NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    if x == 0.0:
        return 0.0
    return math.nan


@inner_njit(cache=True, error_model="numpy")
def np_maximum(a: float, b: float) -> float:  # pragma: no cover - compiled
    """np.maximum(a, b): NaN if either is NaN, else a where a > b, else b (of two equal
    values, +0.0 and -0.0 among them, numpy returns the second)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a > b else b


@inner_njit(cache=True, error_model="numpy")
def np_minimum(a: float, b: float) -> float:  # pragma: no cover - compiled
    """np.minimum(a, b): NaN if either is NaN, else a where a < b, else b."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a < b else b


@inner_njit(cache=True, error_model="numpy")
def search_right(t: FloatArray, first: int, value: float) -> int:  # pragma: no cover - compiled
    """np.searchsorted(t, value, side="right") over t[first:], as an index of t: the first
    sample after ``value`` (len(t) if none), by bisection."""
    lo, hi = first, t.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if t[mid] <= value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@inner_njit(cache=True, error_model="numpy")
def first_crossing(
    t: FloatArray, y: FloatArray, first: int, t0: float, s: float, s_level: float
) -> tuple[float, int]:  # pragma: no cover - compiled
    """(time from t0, index from ``first``) of the first sample with s*y >= s_level (s: the
    sign of the step, so s*(y - level) >= 0): tau of ``first`` if that sample satisfies it,
    otherwise interpolated linearly between the last sample before and the first one that
    satisfies it; (NaN, 0) if it is never reached."""
    for i in range(first, y.shape[0]):
        if s * y[i] >= s_level:
            if i == first:
                tau0 = t[first] - t0
                return tau0 + 0.0 * (tau0 - tau0), 0
            prev = s * y[i - 1]
            frac = clip01((s_level - prev) / (s * y[i] - prev))
            tau_prev = t[i - 1] - t0
            return tau_prev + frac * ((t[i] - t0) - tau_prev), i - first
    return math.nan, 0


@inner_njit(cache=True, error_model="numpy")
def last_exit(
    t: FloatArray, y: FloatArray, first: int, t0: float, center: float, band: float
) -> float:  # pragma: no cover - compiled
    """Time from t0 of the last exit of the row from |y - center| <= band (the last-exit rule).

    With k the last sample where |y_k - center| > band: none gives 0, k the last sample gives
    NaN (not settled within the record), otherwise the time where the piecewise linear signal
    between samples k and k+1 meets the band's edge on the side of y_k,
    center + sign(y_k - center) band.
    """
    n = y.shape[0]
    k = n - 1
    while k >= first and not abs(y[k] - center) > band:
        k -= 1
    if k < first:
        return 0.0
    if k == n - 1:
        return math.nan
    d_k, d_k1 = y[k] - center, y[k + 1] - center
    edge = (1.0 if d_k > 0.0 else -1.0) * band
    tau_k = t[k] - t0
    return tau_k + clip01((d_k - edge) / (d_k - d_k1)) * ((t[k + 1] - t0) - tau_k)


@inner_njit(cache=True, error_model="numpy")
def extremes(
    y: FloatArray, first: int, s: float, s_final: float, s_initial: float
) -> tuple[float, float, int]:  # pragma: no cover - compiled
    """(max(s*y - s_final), max(s_initial - s*y), index of the first maximum of s*y) over the
    row from ``first``: each maximum NaN if a term is NaN (np.max), the index that of the first
    maximum or the first NaN (np.argmax)."""
    hi, lo, hi_nan, lo_nan = -math.inf, -math.inf, False, False
    best, at, found_nan = -math.inf, first, False
    for i in range(first, y.shape[0]):
        v = s * y[i]
        a, c = v - s_final, s_initial - v
        hi_nan = hi_nan or a != a
        lo_nan = lo_nan or c != c
        hi = a if a > hi else hi
        lo = c if c > lo else lo
        if not found_nan:
            if v != v:
                found_nan, at = True, i
            elif i == first or v > best:
                best, at = v, i
    return (math.nan if hi_nan else hi), (math.nan if lo_nan else lo), at


@inner_njit(cache=True, error_model="numpy")
def deviation_peak(y: FloatArray, first: int, center: float) -> int:  # pragma: no cover - compiled
    """The index of the first largest |y - center| from ``first``, or of the first NaN (np.argmax)."""
    best, at = abs(y[first] - center), first
    if best != best:
        return at
    for i in range(first + 1, y.shape[0]):
        d = abs(y[i] - center)
        if d != d:
            return i
        if d > best:
            best, at = d, i
    return at


@inner_njit(cache=True, error_model="numpy")
def max_abs(y: FloatArray, first: int) -> float:  # pragma: no cover - compiled
    """max |y| over the row from ``first``, NaN if it holds a NaN (np.max)."""
    m = -math.inf
    for i in range(first, y.shape[0]):
        a = abs(y[i])
        if a != a:
            return math.nan
        m = a if a > m else m
    return m

"""Time-domain performance metrics of simulated or measured responses (batched).

Every function takes a strictly increasing, not necessarily uniform, time grid ``t`` of
shape ``(T,)`` and a signal of shape ``(T,)`` or ``(B, T)``.  It returns a
``dict[str, np.ndarray]`` whose values have shape ``()`` for a 1-D signal and ``(B,)`` for
a 2-D one (:func:`step_info` returns floats for a 1-D signal).  The searches along a row
(crossings, last exits, extremes) and the terms of the trapezoidal sums are compiled row
scans, each one pass that stops as early as it can; the sums are numpy's (pairwise), so
every value is the numpy formulation's to the last bit (tests/test_metrics_scans.py).  The
batch axis is processed in blocks of rows (about ``_CHUNK_ELEMENTS`` samples each) so that
temporaries stay bounded when ``B * T`` is large.  Each row is computed by the same
row-wise operations whatever the block it falls in, so a batched call equals the
corresponding 1-D calls exactly.

Crossing times are interpolated linearly between samples (the signal is treated as
piecewise linear), so they are not quantised to the grid.  Peaks are sample values.
Integrals use the trapezoidal rule on the given grid.

See ``docs/metrics.md`` for the definitions and their relation to python-control's
``step_info`` and MATLAB's ``stepinfo``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "METRIC_UNITS",
    "STEP_INFO_UNITS",
    "error_integrals",
    "input_metrics",
    "regulation_metrics",
    "step_info",
    "step_response_metrics",
]

FloatArray = NDArray[np.float64]
MetricDict = dict[str, FloatArray]
#: What :func:`step_info` returns: floats for a 1-D signal, ``(B,)`` arrays for a batch.
StepInfo = dict[str, float] | dict[str, FloatArray]

#: Unit of every metric.  "signal" and "input" stand for the unit of the measured signal
#: (or error) and of the control input; the caller substitutes them (e.g. "rad", "N").
METRIC_UNITS: dict[str, str] = {
    # step_response_metrics
    "rise_time": "s",
    "settling_time": "s",
    "overshoot": "%",
    "undershoot": "%",
    "peak": "signal",
    "peak_time": "s",
    "steady_state_error": "signal",
    # regulation_metrics (also settling_time, peak_time, steady_state_error)
    "peak_deviation": "signal",
    # error_integrals
    "ise": "signal^2*s",
    "iae": "signal*s",
    "itae": "signal*s^2",
    "max_abs_error": "signal",
    "rms_error": "signal",
    # input_metrics
    "control_effort": "input^2*s",
    "peak_input": "input",
    "total_variation": "input",
}

STEP_METRICS: tuple[str, ...] = (
    "rise_time",
    "settling_time",
    "overshoot",
    "undershoot",
    "peak",
    "peak_time",
    "steady_state_error",
)
REGULATION_METRICS: tuple[str, ...] = (
    "peak_deviation",
    "peak_time",
    "settling_time",
    "steady_state_error",
)
STEP_INFO_METRICS: tuple[str, ...] = (
    "rise_time",
    "settling_time",
    "overshoot",
    "undershoot",
    "peak",
    "peak_time",
    "steady_state_value",
    "settling_min",
    "settling_max",
)
#: Unit of every :func:`step_info` value ("signal": the unit of the measured signal).
STEP_INFO_UNITS: dict[str, str] = {
    "rise_time": "s",
    "settling_time": "s",
    "overshoot": "%",
    "undershoot": "%",
    "peak": "signal",
    "peak_time": "s",
    "steady_state_value": "signal",
    "settling_min": "signal",
    "settling_max": "signal",
}
ERROR_METRICS: tuple[str, ...] = ("ise", "iae", "itae", "max_abs_error", "rms_error")
INPUT_METRICS: tuple[str, ...] = ("control_effort", "peak_input", "total_variation")

# Rows per block = max(1, _CHUNK_ELEMENTS // T): bounds the size of the temporaries. 2 MB
# blocks stay in cache and are reused by the allocator; much larger blocks are memory-bound,
# every temporary freshly mapped. Blocks never change a result.
_CHUNK_ELEMENTS = 1 << 18


# ----------------------------------------------------------------------------- helpers


def _prepare(t: ArrayLike, y: ArrayLike, name: str) -> tuple[FloatArray, FloatArray, bool]:
    """Validate ``t`` and ``y``; return ``t``, ``y`` as ``(B, T)`` and whether to squeeze."""
    t_arr = np.asarray(t, dtype=np.float64)
    if t_arr.ndim != 1 or t_arr.size < 2:
        raise ValueError(f"t must be a 1-D array of at least 2 samples, got shape {t_arr.shape}")
    if not np.all(np.diff(t_arr) > 0):
        raise ValueError("t must be strictly increasing")
    y_arr = np.asarray(y, dtype=np.float64)
    if y_arr.ndim == 1:
        y2, squeeze = y_arr[np.newaxis, :], True
    elif y_arr.ndim == 2:
        y2, squeeze = y_arr, False
    else:
        raise ValueError(f"{name} must have shape (T,) or (B, T), got {y_arr.shape}")
    if y2.shape[1] != t_arr.size:
        raise ValueError(f"{name} has {y2.shape[1]} samples along its last axis but t has {t_arr.size}")
    return t_arr, y2, squeeze


def _per_row(value: ArrayLike, n_rows: int, name: str) -> FloatArray:
    """A scalar or ``(B,)`` parameter as a ``(B,)`` float array."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.full(n_rows, float(arr))
    if arr.shape == (n_rows,):
        return arr
    raise ValueError(f"{name} must be a scalar or have shape ({n_rows},), got {arr.shape}")


def rows_per_block(n_samples: int) -> int:
    """How many rows of ``n_samples`` samples the functions here process together: a caller
    that forms the rows it passes (outputs gathered from states, errors) does so block by
    block, and its temporaries stay as small as these functions' own."""
    return max(1, _CHUNK_ELEMENTS // max(n_samples, 1))


def _run_batched(
    block: Callable[..., Mapping[str, FloatArray]],
    y: FloatArray,
    keys: tuple[str, ...],
    squeeze: bool,
    row_params: Mapping[str, FloatArray] | None = None,
) -> MetricDict:
    """Apply ``block(y_rows, **params_rows)`` to blocks of rows and assemble the result."""
    n_rows, n_cols = y.shape
    params = row_params or {}
    step = rows_per_block(n_cols)
    parts: dict[str, list[FloatArray]] = {k: [] for k in keys}
    for start in range(0, n_rows, step):
        rows = slice(start, start + step)
        out = block(y[rows], **{k: v[rows] for k, v in params.items()})
        for k in keys:
            parts[k].append(np.asarray(out[k], dtype=np.float64))
    result = {k: np.concatenate(v) if v else np.empty(0, dtype=np.float64) for k, v in parts.items()}
    if squeeze:
        result = {k: v.reshape(()) for k, v in result.items()}
    return result


def _trapz(t: FloatArray, y: FloatArray) -> FloatArray:
    """Trapezoidal integral of each row: sum_k (t_k - t_{k-1}) * (y_k + y_{k-1}) / 2."""
    dt = np.diff(t)
    s = np.add(y[:, 1:], y[:, :-1])  # in place from here: one temporary, the same arithmetic
    s *= 0.5
    s *= dt
    return np.sum(s, axis=-1)


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
def _first_crossing(tau, y, s, s_level):  # pragma: no cover - compiled
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
def _last_exit(tau, y, center, band_abs):  # pragma: no cover - compiled
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
def _extremes(y, s, s_final, s_initial):  # pragma: no cover - compiled
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
def _deviation_peak(y, reference):  # pragma: no cover - compiled
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
def _error_terms(t, e, start):  # pragma: no cover - compiled
    """The terms of the trapezoidal sums of e^2, |e| and (t - start) |e| over each row of e
    (samples at t), as :func:`_trapz` forms them, and max |e| per row. Summed by numpy
    (pairwise), they are the integrals of :func:`error_integrals` to the last bit."""
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
def _input_terms(t, u):  # pragma: no cover - compiled
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


def _window_mean(t: FloatArray, y: FloatArray, window: float) -> FloatArray:
    """Time-weighted (trapezoidal) mean of each row over ``[t[-1] - window, t[-1]]``.

    The window start is generally between samples; ``y`` there is interpolated linearly so
    the window has exactly the requested length.  If the record is shorter than the window
    the whole record ``[t[0], t[-1]]`` is used.
    """
    t_end = t[-1]
    w_start = t_end - window
    if w_start <= t[0]:
        return _trapz(t, y) / (t_end - t[0])
    j = int(np.searchsorted(t, w_start, side="right"))  # t[j-1] <= w_start < t[j]
    a = (w_start - t[j - 1]) / (t[j] - t[j - 1])
    y_start = y[:, j - 1] + a * (y[:, j] - y[:, j - 1])
    head = 0.5 * (t[j] - w_start) * (y_start + y[:, j])
    return (head + _trapz(t[j:], y[:, j:])) / window


def _check_window(ss_window: float) -> float:
    w = float(ss_window)
    if not (np.isfinite(w) and w > 0):
        raise ValueError(f"ss_window must be a positive number of seconds, got {ss_window!r}")
    return w


def _check_band(band: float) -> float:
    b = float(band)
    if not (np.isfinite(b) and b > 0):
        raise ValueError(f"band must be a positive fraction, got {band!r}")
    return b


def _check_rise_limits(rise_limits: tuple[float, float]) -> tuple[float, float]:
    lo, hi = (float(v) for v in rise_limits)
    if not lo < hi:
        raise ValueError(f"rise_limits must satisfy lo < hi, got {rise_limits!r}")
    return lo, hi


class _StepGrid(NamedTuple):
    """Where a step at ``t_step`` falls on the grid ``t``."""

    i0: int  # first considered sample: t[i0] >= t_step
    t_c: FloatArray  # t[i0:]
    tau: FloatArray  # t[i0:] - t_step
    j: int  # t[j] <= t_step < t[j+1]
    on_grid: bool  # t_step == t[j] (or j < 0, when y(t_step) is not needed)
    a: float  # weight of sample j+1 in y(t_step) when t_step is between samples


def _step_grid(t: FloatArray, t_step: float, need_initial: bool, initial_name: str = "initial") -> _StepGrid:
    """Locate ``t_step`` on ``t``; ``need_initial``: y(t_step) will be interpolated from ``y``."""
    ts = float(t_step)
    i0 = int(np.searchsorted(t, ts, side="left"))
    if t.size - i0 < 2:
        raise ValueError(f"need at least two samples at or after t_step = {ts}")
    if need_initial and ts < t[0]:
        raise ValueError(f"t_step is before t[0]; pass {initial_name} explicitly")
    t_c = t[i0:]
    j = int(np.searchsorted(t, ts, side="right")) - 1
    on_grid = j < 0 or t[j] == ts  # j < 0 only if the initial value was given (not used then)
    a = 0.0 if on_grid else (ts - t[j]) / (t[j + 1] - t[j])
    return _StepGrid(i0, t_c, t_c - ts, j, on_grid, a)


def _value_at_step(y: FloatArray, g: _StepGrid) -> FloatArray:
    """y(t_step) of each row, linearly interpolated between the samples around it."""
    j = g.j
    return y[:, j] if g.on_grid else y[:, j] + g.a * (y[:, j + 1] - y[:, j])


class _StepCore(NamedTuple):
    """The metrics both step functions share, and what the rest of each is computed from."""

    metrics: MetricDict  # rise_time, settling_time, overshoot, undershoot (NaN where delta == 0)
    peak_index: NDArray[np.intp]  # first maximum of s * y, s = sign(final - initial)
    valid: NDArray[np.bool_]  # delta != 0
    risen: NDArray[np.bool_]  # the upper rise level is reached (and delta != 0)
    hi_index: NDArray[np.intp]  # first sample at or past the upper rise level (where risen)


def _step_core(
    tau: FloatArray,
    yc: FloatArray,
    initial: FloatArray,
    final: FloatArray,
    limits: tuple[float, float],
    band: float,
) -> _StepCore:
    """Rise time, settling time, overshoot and undershoot of rows ``yc`` stepping initial -> final."""
    lo, hi = limits
    delta = final - initial
    s = np.sign(delta)
    mag = np.abs(delta)
    valid = delta != 0
    t_lo, _ = _first_crossing(tau, yc, s, s * (initial + lo * delta))
    t_hi, hi_index = _first_crossing(tau, yc, s, s * (initial + hi * delta))
    settling = _last_exit(tau, yc, final, band * mag)
    over, under, peak_index = _extremes(yc, s, s * final, s * initial)
    with np.errstate(divide="ignore", invalid="ignore"):
        overshoot = 100.0 * np.maximum(over, 0.0) / mag
        undershoot = 100.0 * np.maximum(under, 0.0) / mag
    nan = np.nan
    metrics = {
        "rise_time": np.where(valid, t_hi - t_lo, nan),
        "settling_time": np.where(valid, settling, nan),
        "overshoot": np.where(valid, overshoot, nan),
        "undershoot": np.where(valid, undershoot, nan),
    }
    return _StepCore(metrics, peak_index, valid, valid & ~np.isnan(t_hi), hi_index)


def _abs_peak(tau: FloatArray, yc: FloatArray) -> MetricDict:
    """python-control's ``Peak``: the largest ``|y|``, and the time of its first sample."""
    absy = np.abs(yc)
    ipk = np.argmax(absy, axis=1)
    return {"peak": absy[np.arange(yc.shape[0]), ipk], "peak_time": tau[ipk]}


def _settling_range(yc: FloatArray, final: FloatArray, core: _StepCore) -> MetricDict:
    """python-control's ``SettlingMin``/``SettlingMax``: the extremes of ``y`` from the first
    sample at or past the upper rise level on, and of the steady-state value."""
    after = np.arange(yc.shape[1]) >= core.hi_index[:, np.newaxis]
    y_min = np.minimum(np.min(np.where(after, yc, np.inf), axis=1), final)
    y_max = np.maximum(np.max(np.where(after, yc, -np.inf), axis=1), final)
    return {"settling_min": np.where(core.risen, y_min, np.nan), "settling_max": np.where(core.risen, y_max, np.nan)}


# ----------------------------------------------------------------------------- metrics


def step_response_metrics(
    t: ArrayLike,
    y: ArrayLike,
    *,
    t_step: float = 0.0,
    final: ArrayLike,
    initial: ArrayLike | None = None,
    band: float = 0.02,
    rise_limits: tuple[float, float] = (0.1, 0.9),
    ss_window: float = 1.0,
) -> MetricDict:
    """Metrics of ``y`` whose reference steps from ``initial`` to ``final`` at ``t_step``.

    Only samples with ``t >= t_step`` are considered, and every time is measured from
    ``t_step`` (tau = t - t_step).  ``initial`` and ``final`` are scalars or ``(B,)``;
    ``initial`` defaults to y(t_step), linearly interpolated on the grid.  With the step
    size Delta = final - initial and s = sign(Delta):

    - ``rise_time`` = t_hi - t_lo, where t_lo is the first time s*(y - L_lo) >= 0 with
      L_lo = initial + lo*Delta and t_hi the first time s*(y - L_hi) >= 0 (at or after t_lo)
      with L_hi = initial + hi*Delta, ``(lo, hi) = rise_limits``.  A crossing is
      interpolated linearly between the sample before and the first sample that satisfies
      the condition; if the first considered sample satisfies it, its time is used.  NaN if
      L_hi is never reached.
    - ``settling_time``: last exit from the band |y - final| <= band*|Delta|.  With k the last
      sample outside the band: none -> 0; k the last sample -> NaN (not settled); otherwise
      the interpolated time between samples k and k+1 at which y meets the band edge.
    - ``overshoot`` [%] = 100 * max(0, max s*(y - final)) / |Delta|.
    - ``undershoot`` [%] = 100 * max(0, max -s*(y - initial)) / |Delta| (inverse response).
    - ``peak`` = y at the (first) maximum of s*y; ``peak_time`` = its time.
    - ``steady_state_error`` = final - mean(y) over the last ``ss_window`` seconds, where
      mean(y) = (1/W) * integral of y dt (trapezoidal, window start interpolated); the whole
      considered record if it is shorter than ``ss_window``.

    If Delta == 0 the step metrics (all but ``steady_state_error``) are NaN.  Returns arrays
    of shape ``()`` for 1-D ``y`` and ``(B,)`` for 2-D ``y``.
    """
    t_arr, y2, squeeze = _prepare(t, y, "y")
    n_rows = y2.shape[0]
    limits = _check_rise_limits(rise_limits)
    b = _check_band(band)
    w = _check_window(ss_window)
    g = _step_grid(t_arr, t_step, need_initial=initial is None)
    params: dict[str, FloatArray] = {"final": _per_row(final, n_rows, "final")}
    if initial is not None:
        params["initial"] = _per_row(initial, n_rows, "initial")

    def block(yb: FloatArray, final: FloatArray, initial: FloatArray | None = None) -> MetricDict:
        if initial is None:
            initial = _value_at_step(yb, g)
        yc = yb[:, g.i0 :]
        core = _step_core(g.tau, yc, initial, final, limits, b)
        ipk = core.peak_index
        return {
            **core.metrics,
            "peak": np.where(core.valid, yc[np.arange(yc.shape[0]), ipk], np.nan),
            "peak_time": np.where(core.valid, g.tau[ipk], np.nan),
            "steady_state_error": final - _window_mean(g.t_c, yc, w),
        }

    return _run_batched(block, y2, STEP_METRICS, squeeze, params)


def step_info(
    t: ArrayLike,
    y: ArrayLike,
    *,
    reference: ArrayLike | None = None,
    t_step: float = 0.0,
    y_initial: ArrayLike | None = None,
    settling_band: float = 0.02,
    rise_limits: tuple[float, float] = (0.1, 0.9),
) -> StepInfo:
    """Step-response characteristics of ``y`` measured against its own final value.

    The counterpart of MATLAB's ``stepinfo(y, t, yfinal, yinit)`` and python-control's
    ``step_info(y, t, yfinal)`` for measured or simulated data, with interpolated crossings.

    Parameters
    ----------
    t : array_like, shape (T,)
        Strictly increasing (not necessarily uniform) sample times [s].
    y : array_like, shape (T,) or (B, T)
        The response, or B responses on the same grid.
    reference : float or array_like of shape (B,), optional
        Target value y_final; default: the last sample ``y[..., -1]`` (as ``stepinfo(y, t)``).
    t_step : float
        Time of the step; samples before it are ignored and times are measured from it.
    y_initial : float or array_like of shape (B,), optional
        Value y_init the step starts from; default y(t_step), interpolated.  MATLAB and
        python-control take 0: pass ``y_initial=0.0`` for their numbers on offset data.
    settling_band : float
        Half-width of the settling band as a fraction of ``|y_final - y_init|``.
    rise_limits : (float, float)
        Rise-time levels as fractions of the way from y_init to y_final.

    Returns
    -------
    dict
        Floats for 1-D ``y``, arrays of shape (B,) for 2-D ``y``.  With D = y_final - y_init,
        s = sign(D), tau = t - t_step and ``(lo, hi) = rise_limits``:

        - ``rise_time`` [s]: t_hi - t_lo, the first times s*(y - y_init - lo*D) >= 0 and
          s*(y - y_init - hi*D) >= 0, each interpolated linearly between the sample before and
          the first sample satisfying it; NaN if the upper level is never reached.
        - ``settling_time`` [s]: last exit from |y - y_final| <= settling_band*|D|,
          interpolated to the band edge; 0 if y never leaves it, NaN if not settled at the end.
        - ``overshoot`` [%]: 100 * max(0, max s*(y - y_final)) / |D|.
        - ``undershoot`` [%]: 100 * max(0, max -s*(y - y_init)) / |D|.
        - ``peak``: max |y|, python-control's and MATLAB's ``Peak``; ``peak_time`` [s]: tau of
          its first sample (not interpolated).
        - ``steady_state_value``: y_final.
        - ``settling_min``, ``settling_max``: min and max of y over the samples from the first
          one satisfying the upper rise condition, and of y_final (as python-control).

        All but ``peak``, ``peak_time`` and ``steady_state_value`` are NaN where D == 0.

    Notes
    -----
    python-control reports the sample at or after each crossing, so its rise and settling
    times are within one sample interval of these; the other values are the same samples.
    See ``docs/metrics.md``.

    Examples
    --------
    A first-order lag y = 1 - exp(-t) rises from 10 % to 90 % in ln 9 and enters the 2 % band
    at -ln 0.02, without overshoot:

    >>> import numpy as np
    >>> from nlcx import step_info
    >>> t = np.linspace(0.0, 10.0, 10001)
    >>> info = step_info(t, 1.0 - np.exp(-t), reference=1.0)
    >>> round(float(info["rise_time"]), 6), round(float(np.log(9.0)), 6)
    (2.197225, 2.197225)
    >>> round(float(info["settling_time"]), 6), round(float(-np.log(0.02)), 6)
    (3.912023, 3.912023)
    >>> float(info["overshoot"])
    0.0
    """
    t_arr, y2, squeeze = _prepare(t, y, "y")
    n_rows = y2.shape[0]
    limits = _check_rise_limits(rise_limits)
    b = _check_band(settling_band)
    g = _step_grid(t_arr, t_step, need_initial=y_initial is None, initial_name="y_initial")
    params: dict[str, FloatArray] = {}
    if reference is not None:
        params["reference"] = _per_row(reference, n_rows, "reference")
    if y_initial is not None:
        params["initial"] = _per_row(y_initial, n_rows, "y_initial")

    def block(yb: FloatArray, reference: FloatArray | None = None, initial: FloatArray | None = None) -> MetricDict:
        final = yb[:, -1] if reference is None else reference
        yc = yb[:, g.i0 :]
        core = _step_core(g.tau, yc, _value_at_step(yb, g) if initial is None else initial, final, limits, b)
        return {**core.metrics, **_abs_peak(g.tau, yc), "steady_state_value": final, **_settling_range(yc, final, core)}

    result = _run_batched(block, y2, STEP_INFO_METRICS, squeeze, params)
    return {k: float(v) for k, v in result.items()} if squeeze else result


def regulation_metrics(
    t: ArrayLike,
    y: ArrayLike,
    *,
    reference: ArrayLike = 0.0,
    band: float = 0.02,
    abs_tol: float = 0.0,
    ss_window: float = 1.0,
) -> MetricDict:
    """Metrics of ``y`` regulated to a constant ``reference`` (scalar or ``(B,)``), e.g. to 0.

    Times are measured from t[0] (tau = t - t[0]); the whole record is considered.

    - ``peak_deviation`` = max |y - reference| (in the signal's unit; M_p for an angle).
    - ``peak_time`` = time of the (first) sample attaining it.
    - ``settling_time``: last exit from the band |y - reference| <= band_abs with
      band_abs = max(band * peak_deviation, abs_tol).  With k the last sample outside the
      band: none -> 0 (in particular if peak_deviation == 0); k the last sample -> NaN;
      otherwise the interpolated time between samples k and k+1 at which y meets the edge.
    - ``steady_state_error`` = reference - mean(y) over the last ``ss_window`` seconds
      (trapezoidal, window start interpolated; whole record if shorter).
    """
    t_arr, y2, squeeze = _prepare(t, y, "y")
    b = _check_band(band)
    w = _check_window(ss_window)
    tol = float(abs_tol)
    if not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"abs_tol must be a non-negative number, got {abs_tol!r}")
    tau = t_arr - t_arr[0]
    params = {"reference": _per_row(reference, y2.shape[0], "reference")}

    def block(yb: FloatArray, reference: FloatArray) -> MetricDict:
        ipk, peak_dev = _deviation_peak(yb, reference)
        band_abs = np.maximum(b * peak_dev, tol)
        return {
            "peak_deviation": peak_dev,
            "peak_time": tau[ipk],
            "settling_time": _last_exit(tau, yb, reference, band_abs),
            "steady_state_error": reference - _window_mean(t_arr, yb, w),
        }

    return _run_batched(block, y2, REGULATION_METRICS, squeeze, params)


def error_integrals(t: ArrayLike, e: ArrayLike, *, t0: float = 0.0) -> MetricDict:
    """Integral error criteria of ``e`` over the samples with ``t >= t0`` (trapezoidal rule).

    - ``ise`` = integral of e^2 dt
    - ``iae`` = integral of |e| dt
    - ``itae`` = integral of (t - t0) |e| dt
    - ``max_abs_error`` = max |e|
    - ``rms_error`` = sqrt(ise / D), D = t_last - t_first over the considered samples.

    Integration starts at the first sample at or after ``t0`` (no interpolation); put ``t0``
    on the grid for an integral that starts exactly at ``t0``.
    """
    t_arr, e2, squeeze = _prepare(t, e, "e")
    start = float(t0)
    i0 = int(np.searchsorted(t_arr, start, side="left"))
    if t_arr.size - i0 < 2:
        raise ValueError(f"need at least two samples at or after t0 = {start}")
    t_c = t_arr[i0:]
    duration = t_c[-1] - t_c[0]

    def block(eb: FloatArray) -> MetricDict:
        squared, absolute, weighted, max_abs = _error_terms(t_c, eb[:, i0:], start)
        ise = np.sum(squared, axis=-1)
        return {
            "ise": ise,
            "iae": np.sum(absolute, axis=-1),
            "itae": np.sum(weighted, axis=-1),
            "max_abs_error": max_abs,
            "rms_error": np.sqrt(ise / duration),
        }

    return _run_batched(block, e2, ERROR_METRICS, squeeze)


def input_metrics(t: ArrayLike, u: ArrayLike) -> MetricDict:
    """Control-input metrics of ``u`` over the whole record.

    - ``control_effort`` = integral of u^2 dt (trapezoidal rule)
    - ``peak_input`` = max |u|
    - ``total_variation`` = sum_k |u_k - u_{k-1}| (the chattering measure; grid-dependent
      for a signal that switches at every sample).
    """
    t_arr, u2, squeeze = _prepare(t, u, "u")

    def block(ub: FloatArray) -> MetricDict:
        squared, steps, peak = _input_terms(t_arr, ub)
        return {
            "control_effort": np.sum(squared, axis=-1),
            "peak_input": peak,
            "total_variation": np.sum(steps, axis=-1),
        }

    return _run_batched(block, u2, INPUT_METRICS, squeeze)

"""Time-domain performance metrics of simulated or measured responses (pure numpy, batched).

Every function takes a strictly increasing, not necessarily uniform, time grid ``t`` of
shape ``(T,)`` and a signal of shape ``(T,)`` or ``(B, T)``.  It returns a
``dict[str, np.ndarray]`` whose values have shape ``()`` for a 1-D signal and ``(B,)`` for
a 2-D one (:func:`step_info` returns floats for a 1-D signal).  Nothing loops over the
time axis; the batch axis is processed in blocks of rows (about ``_CHUNK_ELEMENTS``
samples each) so that temporaries stay bounded when ``B * T`` is large.  Each row is
computed by the same row-wise operations whatever the block it falls in, so a batched
call equals the corresponding 1-D calls exactly.

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
# blocks stay in cache and are reused by the allocator; 32 MB blocks ran 3x slower
# (memory-bound, and every temporary freshly mapped). Blocks never change a result.
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
    step = max(1, _CHUNK_ELEMENTS // max(n_cols, 1))
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


def _first_crossing(tau: FloatArray, sy: FloatArray, s_level: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
    """First time each row of ``sy`` reaches ``s_level`` (i.e. ``sy >= s_level``), interpolated.

    ``sy`` is ``s * y`` and ``s_level`` is ``s * level``, so the condition is
    ``s * (y - level) >= 0``.  If the first sample already satisfies it the result is
    ``tau[0]``; otherwise the crossing is interpolated linearly between the last sample
    before and the first sample that satisfies it.  NaN if it is never reached.  Also
    returns the index of that first sample (meaningless where the time is NaN).
    """
    rows = np.arange(sy.shape[0])
    cond = sy >= s_level[:, np.newaxis]
    found = cond.any(axis=1)
    idx = np.argmax(cond, axis=1)
    prev = np.maximum(idx - 1, 0)
    sy_prev = sy[rows, prev]
    num = s_level - sy_prev
    den = sy[rows, idx] - sy_prev
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(idx > 0, num / den, 0.0)
    frac = np.clip(frac, 0.0, 1.0)
    t_cross = tau[prev] + frac * (tau[idx] - tau[prev])
    return np.where(found, t_cross, np.nan), idx


def _last_exit(tau: FloatArray, y: FloatArray, center: FloatArray, band_abs: FloatArray) -> FloatArray:
    """Time of the last exit of each row from ``|y - center| <= band_abs`` (last-exit rule).

    With k the last index where ``|y_k - center| > band_abs``: no such k gives 0, k the last
    sample gives NaN (not settled within the record), otherwise the time where the piecewise
    linear signal between samples k and k+1 meets the band edge on the side of ``y_k``,
    ``center + sign(y_k - center) * band_abs``.
    """
    n = y.shape[1]
    rows = np.arange(y.shape[0])
    dev = y - center[:, np.newaxis]
    outside = np.abs(dev) > band_abs[:, np.newaxis]
    any_out = outside.any(axis=1)
    k = (n - 1) - np.argmax(outside[:, ::-1], axis=1)
    k1 = np.minimum(k + 1, n - 1)
    d_k = dev[rows, k]
    d_k1 = dev[rows, k1]
    edge = np.sign(d_k) * band_abs
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.clip((d_k - edge) / (d_k - d_k1), 0.0, 1.0)
    t_exit = tau[k] + frac * (tau[k1] - tau[k])
    t_exit = np.where(k == n - 1, np.nan, t_exit)
    return np.where(any_out, t_exit, 0.0)


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
    sy: FloatArray  # s * y, s = sign(final - initial)
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
    sy = s[:, np.newaxis] * yc
    t_lo, _ = _first_crossing(tau, sy, s * (initial + lo * delta))
    t_hi, hi_index = _first_crossing(tau, sy, s * (initial + hi * delta))
    settling = _last_exit(tau, yc, final, band * mag)
    over = np.max(sy - (s * final)[:, np.newaxis], axis=1)
    under = np.max((s * initial)[:, np.newaxis] - sy, axis=1)
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
    return _StepCore(metrics, sy, valid, valid & ~np.isnan(t_hi), hi_index)


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
        ipk = np.argmax(core.sy, axis=1)
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
        rows = np.arange(yb.shape[0])
        absdev = np.abs(yb - reference[:, np.newaxis])
        ipk = np.argmax(absdev, axis=1)
        peak_dev = absdev[rows, ipk]
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
    weight = t_c - start
    duration = t_c[-1] - t_c[0]

    def block(eb: FloatArray) -> MetricDict:
        ec = eb[:, i0:]
        ae = np.abs(ec)
        ise = _trapz(t_c, ec * ec)
        return {
            "ise": ise,
            "iae": _trapz(t_c, ae),
            "itae": _trapz(t_c, weight * ae),
            "max_abs_error": np.max(ae, axis=1),
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
        return {
            "control_effort": _trapz(t_arr, ub * ub),
            "peak_input": np.max(np.abs(ub), axis=1),
            "total_variation": np.sum(np.abs(np.diff(ub, axis=1)), axis=1),
        }

    return _run_batched(block, u2, INPUT_METRICS, squeeze)

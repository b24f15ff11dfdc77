"""Metrics of a signal regulated to a constant, integral criteria of an error, and metrics of a control input."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from nlcx.metrics.batch import error_integral_rows, input_rows, regulation_rows
from nlcx.metrics.kernels import timing
from nlcx.metrics.names import ERROR_METRICS, INPUT_METRICS, REGULATION_METRICS
from nlcx.metrics.rows import MetricDict, by_name, check_band, check_window, per_row, prepare


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
    t_arr, y2, squeeze = prepare(t, y, "y")
    b = check_band(band)
    w = check_window(ss_window)
    tol = float(abs_tol)
    if not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"abs_tol must be a non-negative number, got {abs_tol!r}")
    g = timing(t_arr, t_arr[0], band=b, window=w, abs_tol=tol)
    out = np.empty((y2.shape[0], len(REGULATION_METRICS)))
    regulation_rows(t_arr, y2, g, per_row(reference, y2.shape[0], "reference"), out)
    return by_name(out, REGULATION_METRICS, squeeze)


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
    t_arr, e2, squeeze = prepare(t, e, "e")
    start = float(t0)
    i0 = int(np.searchsorted(t_arr, start, side="left"))
    if t_arr.size - i0 < 2:
        raise ValueError(f"need at least two samples at or after t0 = {start}")
    out = np.empty((e2.shape[0], len(ERROR_METRICS)))
    error_integral_rows(t_arr, e2, i0, start, out)
    return by_name(out, ERROR_METRICS, squeeze)


def input_metrics(t: ArrayLike, u: ArrayLike) -> MetricDict:
    """Control-input metrics of ``u`` over the whole record.

    - ``control_effort`` = integral of u^2 dt (trapezoidal rule)
    - ``peak_input`` = max |u|
    - ``total_variation`` = sum_k |u_k - u_{k-1}| (the chattering measure; grid-dependent
      for a signal that switches at every sample).
    """
    t_arr, u2, squeeze = prepare(t, u, "u")
    out = np.empty((u2.shape[0], len(INPUT_METRICS)))
    input_rows(t_arr, u2, out)
    return by_name(out, INPUT_METRICS, squeeze)

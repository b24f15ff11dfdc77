"""Metrics of a step response, measured against its reference's step or against its own final value.

:func:`step_response_metrics` measures a response against the step of its reference,
:func:`step_info` against the response's own final value, as MATLAB's ``stepinfo`` and
python-control's ``step_info`` do. Times are measured from the step (:func:`measured_from`
moves them to another origin); rise and settling times are crossings interpolated linearly
between samples, peaks are sample values. See ``docs/metrics.md``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from nlcx.metrics.batch import step_info_rows, step_response_rows
from nlcx.metrics.kernels import Timing, timing
from nlcx.metrics.names import EVENT_TIMES, STEP_INFO_METRICS, STEP_METRICS
from nlcx.metrics.rows import (
    FloatArray,
    MetricDict,
    by_name,
    check_band,
    check_rise_limits,
    check_window,
    per_row,
    prepare,
)

StepInfo = dict[str, float] | dict[str, FloatArray]
"""What :func:`step_info` returns: floats for a 1-D signal, ``(B,)`` arrays for a batch.

With D = y_final - y_init, s = sign(D), tau = t - t_step and ``(lo, hi) = rise_limits``:

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

All but ``peak``, ``peak_time`` and ``steady_state_value`` are NaN where D == 0."""


def _checked_timing(
    t: FloatArray, t_step: float, need_initial: bool, initial_name: str, band: float,
    rise_limits: tuple[float, float], window: float = 1.0,
) -> Timing:  # fmt: skip
    """The :class:`~nlcx.metrics.kernels.Timing` of a step at ``t_step`` on ``t``; ValueError if
    fewer than two samples are at or after it, or, when y(t_step) is needed, if it is before t[0]."""
    ts = float(t_step)
    g = timing(t, ts, band=band, rise_limits=rise_limits, window=window)
    if t.size - g.first < 2:
        raise ValueError(f"need at least two samples at or after t_step = {ts}")
    if need_initial and ts < t[0]:
        raise ValueError(f"t_step is before t[0]; pass {initial_name} explicitly")
    return g


def _optional_rows(value: ArrayLike | None, n_rows: int, name: str) -> tuple[FloatArray, bool]:
    """A per-row parameter that may be left out: ((B,) values or zeros, whether it was given)."""
    if value is None:
        return np.zeros(n_rows), False
    return per_row(value, n_rows, name), True


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
    t_arr, y2, squeeze = prepare(t, y, "y")
    n_rows = y2.shape[0]
    limits = check_rise_limits(rise_limits)
    g = _checked_timing(t_arr, t_step, initial is None, "initial", check_band(band), limits, check_window(ss_window))
    start, given = _optional_rows(initial, n_rows, "initial")
    out = np.empty((n_rows, len(STEP_METRICS)))
    step_response_rows(t_arr, y2, g, start, given, per_row(final, n_rows, "final"), out)
    return by_name(out, STEP_METRICS, squeeze)


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
        The values of ``STEP_INFO_METRICS``, floats for 1-D ``y`` and arrays of shape (B,) for
        2-D ``y``. With D = y_final - y_init and s = sign(D): the rise time between the
        interpolated first crossings of y_init + lo*D and y_init + hi*D; the settling time at
        the interpolated last exit from |y - y_final| <= settling_band*|D|; overshoot
        100 max(0, max s(y - y_final))/|D| and undershoot 100 max(0, max -s(y - y_init))/|D|
        [%]; the peak max |y| and its time; y_final; settling_min and settling_max as
        python-control. Each is defined in full at :data:`StepInfo`.

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
    out, squeeze = _step_info_table(t, y, reference, t_step, y_initial, settling_band, rise_limits)
    result = by_name(out, STEP_INFO_METRICS, squeeze)
    return {k: float(v) for k, v in result.items()} if squeeze else result


def _step_info_table(
    t: ArrayLike, y: ArrayLike, reference: ArrayLike | None, t_step: float, y_initial: ArrayLike | None,
    settling_band: float, rise_limits: tuple[float, float],
) -> tuple[np.ndarray, bool]:  # fmt: skip
    """:func:`step_info`'s arguments checked and measured: one row of :data:`STEP_INFO_METRICS`
    per response, and whether ``y`` was one response (1-D)."""
    t_arr, y2, squeeze = prepare(t, y, "y")
    n_rows = y2.shape[0]
    limits = check_rise_limits(rise_limits)
    g = _checked_timing(t_arr, t_step, y_initial is None, "y_initial", check_band(settling_band), limits)
    start, has_initial = _optional_rows(y_initial, n_rows, "y_initial")
    final, has_final = _optional_rows(reference, n_rows, "reference")
    out = np.empty((n_rows, len(STEP_INFO_METRICS)))
    step_info_rows(t_arr, y2, g, start, has_initial, final, has_final, out)
    return out, squeeze


def measured_from(values: MetricDict, t_step: float, origin: float) -> MetricDict:
    """Step metrics measured from their step at ``t_step`` with the event times measured from ``origin``.

    :func:`step_response_metrics` and :func:`step_info` measure every time from the step. With
    ``origin`` another time, e.g. 0 for the start of a run, each event time
    (:data:`~nlcx.metrics.names.EVENT_TIMES`: ``settling_time``, ``peak_time``) becomes
    tau + (t_step - origin); NaN stays NaN. ``rise_time`` is a duration and every other value is
    not a time: they are unchanged.

    Parameters
    ----------
    values : dict
        Metrics by name, as a step function returns them (arrays of shape ``()`` or ``(B,)``).
    t_step : float
        The time of the step they were measured from [s].
    origin : float
        The time the event times are to be measured from [s].

    Returns
    -------
    dict
        The metrics with their event times moved; ``values`` itself (not copied) when
        ``origin == t_step``.

    Examples
    --------
    >>> import numpy as np
    >>> values = {"settling_time": np.array(2.5), "rise_time": np.array(1.0)}
    >>> moved = measured_from(values, t_step=1.0, origin=0.0)
    >>> float(moved["settling_time"]), float(moved["rise_time"])
    (3.5, 1.0)
    """
    shift = float(t_step) - float(origin)
    if shift == 0.0:
        return values
    return {name: value + shift if name in EVENT_TIMES else value for name, value in values.items()}

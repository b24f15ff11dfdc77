"""Metrics of a step response, measured against its reference's step or against its own final value.

:func:`step_response_metrics` measures a response against the step of its reference,
:func:`step_info` against the response's own final value, as MATLAB's ``stepinfo`` and
python-control's ``step_info`` do. Times are measured from the step (:func:`measured_from`
moves them to another origin); rise and settling times are crossings interpolated linearly
between samples, peaks are sample values. See ``docs/metrics.md``.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from nlcx.metrics.names import EVENT_TIMES, STEP_INFO_METRICS, STEP_METRICS
from nlcx.metrics.rows import (
    FloatArray,
    MetricDict,
    check_band,
    check_rise_limits,
    check_window,
    per_row,
    prepare,
    run_batched,
    window_mean,
)
from nlcx.metrics.scans import extremes, first_crossing, last_exit

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
    t_lo, _ = first_crossing(tau, yc, s, s * (initial + lo * delta))
    t_hi, hi_index = first_crossing(tau, yc, s, s * (initial + hi * delta))
    settling = last_exit(tau, yc, final, band * mag)
    over, under, peak_index = extremes(yc, s, s * final, s * initial)
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


def _step_response_rows(
    g: _StepGrid,
    limits: tuple[float, float],
    band: float,
    window: float,
    yb: FloatArray,
    final: FloatArray,
    initial: FloatArray | None = None,
) -> MetricDict:
    """:func:`step_response_metrics` of the block of rows ``yb`` stepping from ``initial``
    (default: y(t_step)) to ``final`` at the step ``g``."""
    if initial is None:
        initial = _value_at_step(yb, g)
    yc = yb[:, g.i0 :]
    core = _step_core(g.tau, yc, initial, final, limits, band)
    ipk = core.peak_index
    return {
        **core.metrics,
        "peak": np.where(core.valid, yc[np.arange(yc.shape[0]), ipk], np.nan),
        "peak_time": np.where(core.valid, g.tau[ipk], np.nan),
        "steady_state_error": final - window_mean(g.t_c, yc, window),
    }


def _step_info_rows(
    g: _StepGrid,
    limits: tuple[float, float],
    band: float,
    yb: FloatArray,
    reference: FloatArray | None = None,
    initial: FloatArray | None = None,
) -> MetricDict:
    """:func:`step_info` of the block of rows ``yb`` stepping from ``initial`` (default:
    y(t_step)) at the step ``g``, against ``reference`` (default: each row's last sample)."""
    final = yb[:, -1] if reference is None else reference
    yc = yb[:, g.i0 :]
    core = _step_core(g.tau, yc, _value_at_step(yb, g) if initial is None else initial, final, limits, band)
    return {**core.metrics, **_abs_peak(g.tau, yc), "steady_state_value": final, **_settling_range(yc, final, core)}


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
    b = check_band(band)
    w = check_window(ss_window)
    g = _step_grid(t_arr, t_step, need_initial=initial is None)
    params: dict[str, FloatArray] = {"final": per_row(final, n_rows, "final")}
    if initial is not None:
        params["initial"] = per_row(initial, n_rows, "initial")
    return run_batched(functools.partial(_step_response_rows, g, limits, b, w), y2, STEP_METRICS, squeeze, params)


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
    t_arr, y2, squeeze = prepare(t, y, "y")
    n_rows = y2.shape[0]
    limits = check_rise_limits(rise_limits)
    b = check_band(settling_band)
    g = _step_grid(t_arr, t_step, need_initial=y_initial is None, initial_name="y_initial")
    params: dict[str, FloatArray] = {}
    if reference is not None:
        params["reference"] = per_row(reference, n_rows, "reference")
    if y_initial is not None:
        params["initial"] = per_row(y_initial, n_rows, "y_initial")
    result = run_batched(functools.partial(_step_info_rows, g, limits, b), y2, STEP_INFO_METRICS, squeeze, params)
    return {k: float(v) for k, v in result.items()} if squeeze else result


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

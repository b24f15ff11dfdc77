"""The metric kernels: one row of a signal in, its metric values out.

Every metric nlcx reports is computed by one of these functions, for one signal row at a
time, written into ``out[o:]`` in the order of :mod:`nlcx.metrics.names`:

- :func:`step_response` (:data:`~nlcx.metrics.names.STEP_METRICS`) and :func:`step_info`
  (:data:`~nlcx.metrics.names.STEP_INFO_METRICS`): a step from ``initial`` to ``final`` at
  ``t_step``, measured against the step's target or against the row's own final value;
- :func:`regulation` (:data:`~nlcx.metrics.names.REGULATION_METRICS`): a row held at a constant;
- :func:`error_integrals` (:data:`~nlcx.metrics.names.ERROR_METRICS`) of e = ref - y;
- :func:`input_effort` (:data:`~nlcx.metrics.names.INPUT_METRICS`) of a control input;

and :func:`measure` strings them together as a measured signal of a run needs them
(:class:`nlcx.engine.plan.MetricPlan`). The definitions are those of the public functions of
:mod:`nlcx.metrics`, whose docstrings give the formulas; the CPU calls these kernels over rows
(:mod:`nlcx.metrics.batch`), and the GPU runs the same source, one thread a run
(:mod:`nlcx.kernel.cuda_metrics`). Where a step falls on the grid is found once, on the host,
and handed over as a :class:`Timing`.

numba compiles a function once for each distinct set of argument types it is called with, and
a constant argument, such as a literal ``0``, has a type of its own (``Literal[int](0)``). The
kernels therefore pass sample indices and offsets as int64 values (``np.int64(0)`` where it is
zero), and their callers hand them C-contiguous, writable float64 rows
(:func:`nlcx.engine.measure.signal_values`): each kernel is compiled once. The kind of the
pairwise sums is passed as ``np.int64`` too; the sums compile each kind's block loop apart
(:mod:`nlcx.metrics.sums`).

numba compiles a function that another calls into a module of its own, optimises it and makes
its machine code, then links that module into its caller's and optimises and compiles it again.
The five kernels above are therefore inlined by numba (``inline="always"``) into each of their
callers, which call each of them once (:func:`measure`, itself inlined into its one caller,
:func:`nlcx.metrics.batch.measure_rows`; the per-kernel loops of :mod:`nlcx.metrics.batch`);
their helpers that two kernels call (:func:`window_mean`, :func:`_step_core`, the scans, the
pairwise sums) stay compiled functions of their own, typed once.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from nlcx._numba_compat import inner_njit
from nlcx.kernel.signatures import FloatArray, IntArray
from nlcx.metrics.scans import (
    deviation_peak,
    extremes,
    first_crossing,
    last_exit,
    max_abs,
    np_maximum,
    np_minimum,
    search_right,
    sign,
)
from nlcx.metrics.sums import ERRORS, INPUT, TRAPEZOID, pairwise_sums

#: What :func:`measure` computes for a signal: the kinds of a :class:`nlcx.engine.plan.MeasuredSignal`.
STEP, REGULATION, TRACKING, INFO, EFFORT = 0, 1, 2, 3, 4


class Timing(NamedTuple):
    """Where a signal's measurement starts on the grid t, and its settings.

    ``first``: the first sample at or after ``t_step`` (the considered samples; the start of
    the error integrals); ``j``: the sample at or before it, ``a`` the weight of sample j+1 in
    y(t_step) (0 when ``on_grid``); ``shift``: t_step - origin, added to the event times
    (0: times measured from the step); ``band``: the settling band (a fraction);
    ``rise_low``/``rise_high``: the rise limits; ``window``: the steady-state window [s];
    ``abs_tol``: the regulation band's floor."""

    first: int
    j: int
    a: float
    on_grid: bool
    t_step: float
    shift: float
    band: float
    rise_low: float
    rise_high: float
    window: float
    abs_tol: float


def timing(
    t: np.ndarray, t_step: float, *, origin: float | None = None, band: float = 0.02,
    rise_limits: tuple[float, float] = (0.1, 0.9), window: float = 1.0, abs_tol: float = 0.0,
) -> Timing:  # fmt: skip
    """The :class:`Timing` of a step at ``t_step`` on the grid ``t`` (np.searchsorted), event
    times measured from ``origin`` (default: the step)."""
    ts = float(t_step)
    first = int(np.searchsorted(t, ts, side="left"))
    j = int(np.searchsorted(t, ts, side="right")) - 1
    on_grid = j < 0 or bool(t[j] == ts)
    a = 0.0 if on_grid else float((ts - t[j]) / (t[j + 1] - t[j]))
    shift = 0.0 if origin is None else ts - float(origin)
    lo, hi = rise_limits
    return Timing(first, j, a, on_grid, ts, shift, float(band), float(lo), float(hi), float(window), float(abs_tol))


@inner_njit(cache=True, error_model="numpy")
def value_at_step(y: FloatArray, m: Timing) -> float:  # pragma: no cover - compiled
    """y(t_step): sample j, or interpolated linearly between samples j and j+1."""
    j = m.j
    return y[j] if m.on_grid else y[j] + m.a * (y[j + 1] - y[j])


@inner_njit(cache=True, error_model="numpy")
def window_mean(
    t: FloatArray, y: FloatArray, first: int, window: float, ranges: IntArray, partial: FloatArray
) -> float:  # pragma: no cover - compiled
    """Time-weighted (trapezoidal) mean of the row from ``first`` over [t_end - window, t_end],
    y interpolated linearly at the window's start; the whole considered record if it is shorter."""
    n = y.shape[0]
    t_end = t[n - 1]
    w_start = t_end - window
    if w_start <= t[first]:
        area, _, _ = pairwise_sums(np.int64(TRAPEZOID), t, y, y, 0.0, first, n - 1 - first, ranges, partial)
        return area / (t_end - t[first])
    j = search_right(t, first, w_start)  # t[j-1] <= w_start < t[j]
    a = (w_start - t[j - 1]) / (t[j] - t[j - 1])
    y_start = y[j - 1] + a * (y[j] - y[j - 1])
    head = 0.5 * (t[j] - w_start) * (y_start + y[j])
    area, _, _ = pairwise_sums(np.int64(TRAPEZOID), t, y, y, 0.0, j, n - 1 - j, ranges, partial)
    return (head + area) / window


@inner_njit(cache=True, error_model="numpy")
def _step_core(
    t: FloatArray, y: FloatArray, m: Timing, initial: float, final: float, out: FloatArray, o: int
) -> tuple[bool, float, int, int]:  # pragma: no cover - compiled
    """Rise time, settling time, overshoot and undershoot of a step initial -> final into
    out[o:o+4] (NaN where final == initial); returns (final != initial, the time and index of
    the upper rise level, the first peak of s*y)."""
    delta = final - initial
    s = sign(delta)
    mag = abs(delta)
    valid = delta != 0
    first, ts = m.first, m.t_step
    t_lo, _ = first_crossing(t, y, first, ts, s, s * (initial + m.rise_low * delta))
    t_hi, hi_index = first_crossing(t, y, first, ts, s, s * (initial + m.rise_high * delta))
    settling = last_exit(t, y, first, ts, final, m.band * mag)
    over, under, peak = extremes(y, first, s, s * final, s * initial)
    out[o] = t_hi - t_lo if valid else math.nan
    out[o + 1] = settling if valid else math.nan
    out[o + 2] = 100.0 * np_maximum(over, 0.0) / mag if valid else math.nan
    out[o + 3] = 100.0 * np_maximum(under, 0.0) / mag if valid else math.nan
    return valid, t_hi, hi_index, peak


@njit(cache=True, inline="always", error_model="numpy")
def step_response(
    t: FloatArray,
    y: FloatArray,
    m: Timing,
    initial: float,
    final: float,
    out: FloatArray,
    o: int,
    ranges: IntArray,
    partial: FloatArray,
) -> None:  # pragma: no cover - compiled
    """:func:`nlcx.metrics.step_response_metrics` of the row: rise time, settling time,
    overshoot, undershoot, peak, peak time (the step's metrics NaN where final == initial) and
    the steady-state error final - mean(y) over the window."""
    valid, _, _, peak = _step_core(t, y, m, initial, final, out, o)
    out[o + 4] = y[peak] if valid else math.nan
    out[o + 5] = t[peak] - m.t_step if valid else math.nan
    out[o + 6] = final - window_mean(t, y, m.first, m.window, ranges, partial)
    _shift_event_times(out, o + 1, o + 5, m.shift)


@njit(cache=True, inline="always", error_model="numpy")
def step_info(
    t: FloatArray, y: FloatArray, m: Timing, initial: float, final: float, out: FloatArray, o: int
) -> None:  # pragma: no cover - compiled
    """:func:`nlcx.metrics.step_info` of the row against ``final``: rise time, settling time,
    overshoot, undershoot, peak max |y| and its time, the steady-state value and the settling
    range (the extremes of y from the upper rise level on, and of final)."""
    valid, t_hi, hi_index, _ = _step_core(t, y, m, initial, final, out, o)
    at = deviation_peak(y, m.first, 0.0)  # the first largest |y|
    out[o + 4] = abs(y[at])
    out[o + 5] = t[at] - m.t_step
    out[o + 6] = final
    low, high = math.inf, -math.inf  # np.min and np.max from the upper rise level on
    for i in range(m.first + hi_index, y.shape[0]):
        low, high = np_minimum(low, y[i]), np_maximum(high, y[i])
        if low != low:
            break
    risen = valid and t_hi == t_hi
    out[o + 7] = np_minimum(low, final) if risen else math.nan
    out[o + 8] = np_maximum(high, final) if risen else math.nan
    _shift_event_times(out, o + 1, o + 5, m.shift)


@njit(cache=True, inline="always", error_model="numpy")
def _shift_event_times(
    out: FloatArray, settling: int, peak_time: int, shift: float
) -> None:  # pragma: no cover - compiled
    """The event times measured from the origin: tau + (t_step - origin) (:func:`nlcx.metrics.measured_from`)."""
    if shift != 0.0:
        out[settling] = out[settling] + shift
        out[peak_time] = out[peak_time] + shift


@njit(cache=True, inline="always", error_model="numpy")
def regulation(
    t: FloatArray,
    y: FloatArray,
    m: Timing,
    reference: float,
    out: FloatArray,
    o: int,
    ranges: IntArray,
    partial: FloatArray,
) -> None:  # pragma: no cover - compiled
    """:func:`nlcx.metrics.regulation_metrics` of the row held at ``reference``, over the whole
    record: peak deviation, its time, the settling time (band max(band * peak, abs_tol)) and
    the steady-state error."""
    whole = np.int64(0)  # the first sample, an int64 as m.first is (see the module docstring)
    at = deviation_peak(y, whole, reference)
    peak = abs(y[at] - reference)
    out[o] = peak
    out[o + 1] = t[at] - t[0]
    out[o + 2] = last_exit(t, y, whole, t[0], reference, np_maximum(m.band * peak, m.abs_tol))
    out[o + 3] = reference - window_mean(t, y, whole, m.window, ranges, partial)


@njit(cache=True, inline="always", error_model="numpy")
def error_integrals(
    t: FloatArray,
    y: FloatArray,
    ref: FloatArray,
    first: int,
    start: float,
    out: FloatArray,
    o: int,
    ranges: IntArray,
    partial: FloatArray,
) -> None:  # pragma: no cover - compiled
    """:func:`nlcx.metrics.error_integrals` of e = ref - y from sample ``first``: ISE, IAE,
    ITAE (time from ``start``), max |e| and the RMS error sqrt(ISE / duration)."""
    n = y.shape[0]
    ise, iae, itae = pairwise_sums(np.int64(ERRORS), t, y, ref, start, first, n - 1 - first, ranges, partial)
    peak = -math.inf
    for k in range(first, n):
        a = abs(ref[k] - y[k])
        if a != a:
            peak = math.nan
            break
        peak = a if a > peak else peak
    out[o] = ise
    out[o + 1] = iae
    out[o + 2] = itae
    out[o + 3] = peak
    out[o + 4] = math.sqrt(ise / (t[n - 1] - t[first]))


@njit(cache=True, inline="always", error_model="numpy")
def input_effort(
    t: FloatArray, u: FloatArray, out: FloatArray, o: int, ranges: IntArray, partial: FloatArray
) -> None:  # pragma: no cover - compiled
    """:func:`nlcx.metrics.input_metrics` of the row: the effort (integral of u^2), max |u| and
    the total variation sum |u_k - u_{k-1}|."""
    effort, variation, _ = pairwise_sums(np.int64(INPUT), t, u, u, 0.0, np.int64(0), u.shape[0] - 1, ranges, partial)
    out[o] = effort
    out[o + 1] = max_abs(u, 0)
    out[o + 2] = variation


@njit(cache=True, inline="always", error_model="numpy")
def measure(
    kind: int,
    t: FloatArray,
    y: FloatArray,
    ref: FloatArray,
    m: Timing,
    final: float,
    out: FloatArray,
    o: int,
    ranges: IntArray,
    partial: FloatArray,
) -> None:  # pragma: no cover - compiled
    """The metric values of one measured signal of a run (``kind``: :data:`STEP`, ...), in
    the order of :data:`nlcx.metrics.names.MEASURED`: a step response (from y(t_step) to
    ``final``) or a regulation to ``final``, each followed by the error integrals of
    ref - y from the step; the error integrals alone (tracking); the step characteristics
    against the row's last sample (an output no loop follows); an input's effort.

    Inlined into its one caller on the CPU, :func:`nlcx.metrics.batch.measure_rows`, with the
    kernels it calls (the module docstring). The GPU compiles it from its source."""
    if kind == STEP:
        step_response(t, y, m, value_at_step(y, m), final, out, o, ranges, partial)
        error_integrals(t, y, ref, m.first, m.t_step, out, o + 7, ranges, partial)
    elif kind == REGULATION:
        regulation(t, y, m, final, out, o, ranges, partial)
        error_integrals(t, y, ref, m.first, m.t_step, out, o + 4, ranges, partial)
    elif kind == TRACKING:
        error_integrals(t, y, ref, m.first, m.t_step, out, o, ranges, partial)
    elif kind == INFO:
        step_info(t, y, m, value_at_step(y, m), y[y.shape[0] - 1], out, o)
    else:
        input_effort(t, y, out, o, ranges, partial)

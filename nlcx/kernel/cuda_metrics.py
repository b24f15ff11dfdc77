"""The metrics of :mod:`nlcx.metrics` on the GPU, one thread a run, from records kept there.

A closed-loop launch (:func:`nlcx.kernel.cuda_loop.launch`) leaves each run's measured
signals on the GPU, time-major (K+1, signals, B). :func:`metrics_kernel` computes, per run, the
values :func:`nlcx.engine.measure_runs` reports for a run that finished, in its order, from a
list of :class:`Block` (one a measured signal):

- ``step``: :func:`nlcx.metrics.step_response_metrics` (rise and settling time, overshoot,
  undershoot, peak and its time, steady-state error; event times moved by
  :func:`nlcx.metrics.measured_from`), then :func:`nlcx.metrics.error_integrals` of r - y;
- ``regulation``: :func:`nlcx.metrics.regulation_metrics`, then the error integrals;
- ``tracking``: the error integrals;
- ``info``: :func:`nlcx.metrics.step_info` against the run's own last sample (an output no
  loop follows, after a step on an input), event times moved as for ``step``;
- ``input``: :func:`nlcx.metrics.input_metrics`.

The definitions are those functions' (their docstrings give the formulas); where they locate
a time on the grid (the step, the start of the steady-state window, the start of the
integrals), the index is found on the host by the same ``searchsorted`` and baked into the
block. Sums run sample by sample here, pairwise in numpy: the two agree to rounding
(tests/test_gpu.py holds them within 1e-9 relative).
"""

from __future__ import annotations

import functools
import hashlib
import math
from typing import Any, Literal, NamedTuple

import numpy as np

from nlcx.kernel.device import cuda, device_function, kept
from nlcx.metrics.names import ERROR_METRICS, INPUT_METRICS, REGULATION_METRICS, STEP_INFO_METRICS, STEP_METRICS
from nlcx.metrics.scans import _clip01

#: Values a block writes, by kind.
BLOCK_NAMES = {
    "step": STEP_METRICS + ERROR_METRICS,
    "regulation": REGULATION_METRICS + ERROR_METRICS,
    "tracking": ERROR_METRICS,
    "info": STEP_INFO_METRICS,
    "input": INPUT_METRICS,
}


class Block(NamedTuple):
    """One measured signal of a run: its kind (:data:`BLOCK_NAMES`), where its samples are in
    the records (``signal``), its reference (row ``ref_row`` of the reference table; -1: none)
    and the constants of its definitions (step time and target, band, rise limits, window,
    time origin, tolerance)."""

    kind: str
    signal: int
    ref_row: int
    t_step: float = 0.0
    final: float = 0.0
    band: float = 0.02
    rise_low: float = 0.1
    rise_high: float = 0.9
    window: float = 1.0
    origin: float = 0.0
    abs_tol: float = 0.0


# ----------------------------------------------------------------------------- scans (device)


@functools.cache
def _scans() -> dict[str, Any]:
    """The device functions the blocks are made of (compiled on first use)."""
    scans = {**_arithmetic(), "errors": _errors()}
    scans |= _searches(scans["clip01"])
    return {**scans, "step_core": _step_core(scans)}


def _arithmetic() -> dict[str, Any]:
    """clip01, sign, trapz and window_mean on the GPU (:mod:`nlcx.metrics.rows`)."""
    jit = cuda().jit(device=True)

    clip01 = device_function(_clip01)  # the CPU's np.clip(x, 0, 1), from its source

    @jit
    def sign(x):  # pragma: no cover - device
        if x > 0.0:
            return 1.0
        if x < 0.0:
            return -1.0
        if x == 0.0:
            return 0.0
        return math.nan

    @jit
    def trapz(t, y, start, n):  # pragma: no cover - device
        acc = 0.0
        for k in range(start + 1, n):
            acc += ((y[k] + y[k - 1]) * 0.5) * (t[k] - t[k - 1])
        return acc

    @jit
    def window_mean(t, y, first, n, window):  # pragma: no cover - device
        """nlcx.metrics.rows.window_mean of the samples first..n-1."""
        t_end = t[n - 1]
        w_start = t_end - window
        if w_start <= t[first]:
            return trapz(t, y, first, n) / (t_end - t[first])
        j = first
        while j < n and t[j] <= w_start:  # searchsorted(side="right")
            j += 1
        a = (w_start - t[j - 1]) / (t[j] - t[j - 1])
        y_start = y[j - 1] + a * (y[j] - y[j - 1])
        head = 0.5 * (t[j] - w_start) * (y_start + y[j])
        return (head + trapz(t, y, j, n)) / window

    return {"clip01": clip01, "sign": sign, "trapz": trapz, "window_mean": window_mean}


def _searches(clip01: Any) -> dict[str, Any]:
    """first_crossing, last_exit and extremes of one run on the GPU (:mod:`nlcx.metrics.scans`)."""
    jit = cuda().jit(device=True)

    @jit
    def first_crossing(t, y, first, n, t0, s, s_level):  # pragma: no cover - device
        """nlcx.metrics.scans: (time from t0, index from first) where s*y first reaches s_level."""
        for i in range(first, n):
            if s * y[i] >= s_level:
                if i == first:
                    tau0 = t[first] - t0
                    return tau0 + 0.0 * (tau0 - tau0), 0
                prev = s * y[i - 1]
                frac = clip01((s_level - prev) / (s * y[i] - prev))
                return (t[i - 1] - t0) + frac * ((t[i] - t0) - (t[i - 1] - t0)), i - first
        return math.nan, 0

    @jit
    def last_exit(t, y, first, n, t0, center, band):  # pragma: no cover - device
        k = n - 1
        while k >= first and not abs(y[k] - center) > band:
            k -= 1
        if k < first:
            return 0.0
        if k == n - 1:
            return math.nan
        d_k, d_k1 = y[k] - center, y[k + 1] - center
        edge = (1.0 if d_k > 0.0 else -1.0) * band
        return (t[k] - t0) + clip01((d_k - edge) / (d_k - d_k1)) * ((t[k + 1] - t0) - (t[k] - t0))

    @jit
    def extremes(y, first, n, s, s_final, s_initial):  # pragma: no cover - device
        hi, lo, hi_nan, lo_nan = -math.inf, -math.inf, False, False
        best, at, found_nan = -math.inf, first, False
        for i in range(first, n):
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

    @jit
    def deviation_peak(y, first, n, center):  # pragma: no cover - device
        """The first sample from ``first`` of largest |y - center|, or the first NaN (np.argmax)."""
        best, at = abs(y[first] - center), first
        if best != best:
            return at
        for i in range(first + 1, n):
            d = abs(y[i] - center)
            if d != d:
                return i
            if d > best:
                best, at = d, i
        return at

    return {
        "first_crossing": first_crossing, "last_exit": last_exit, "extremes": extremes,
        "deviation_peak": deviation_peak,
    }  # fmt: skip


def _step_core(f: dict[str, Any]) -> Any:
    """What a step response and a step's characteristics share (nlcx.metrics.step._step_core):
    rise time, settling time, overshoot and undershoot written to out[o:o + 4]; returns whether
    the step is not zero, the time and index (from ``first``) of the upper rise level, and the
    first peak of s*y."""
    sign, first_crossing, last_exit, extremes = f["sign"], f["first_crossing"], f["last_exit"], f["extremes"]

    @cuda().jit(device=True)
    def core(t, y, first, n, t_step, initial, final, lo, hi, band, shift, out, o):  # pragma: no cover - device
        delta = final - initial
        s = sign(delta)
        mag = abs(delta)
        valid = delta != 0
        t_lo, _ = first_crossing(t, y, first, n, t_step, s, s * (initial + lo * delta))
        t_hi, hi_index = first_crossing(t, y, first, n, t_step, s, s * (initial + hi * delta))
        settling = last_exit(t, y, first, n, t_step, final, band * mag)
        over, under, ipk = extremes(y, first, n, s, s * final, s * initial)
        o_max = over if (over != over or over > 0.0) else 0.0
        u_max = under if (under != under or under > 0.0) else 0.0
        out[o] = t_hi - t_lo if valid else math.nan
        out[o + 1] = (settling + shift if shift != 0.0 else settling) if valid else math.nan
        out[o + 2] = 100.0 * o_max / mag if valid else math.nan
        out[o + 3] = 100.0 * u_max / mag if valid else math.nan
        return valid, t_hi, hi_index, ipk

    return core


def _errors() -> Any:
    """The error integrals of one run on the GPU (:func:`nlcx.metrics.error_integrals`)."""
    jit = cuda().jit(device=True)

    @jit
    def errors(t, y, ref, first, n, start, out, o):  # pragma: no cover - device
        """nlcx.metrics.error_integrals of e = ref - y from sample ``first``: ise, iae, itae, max |e|, rms."""
        ise, iae, itae, peak, nan = 0.0, 0.0, 0.0, -math.inf, False
        e0 = ref[first] - y[first]
        a0 = abs(e0)
        nan = a0 != a0
        peak = a0 if a0 > peak else peak
        for k in range(first + 1, n):
            e1 = ref[k] - y[k]
            a1 = abs(e1)
            dt = t[k] - t[k - 1]
            ise += ((e1 * e1 + e0 * e0) * 0.5) * dt
            iae += ((a1 + a0) * 0.5) * dt
            itae += (((t[k] - start) * a1 + (t[k - 1] - start) * a0) * 0.5) * dt
            nan = nan or a1 != a1
            peak = a1 if a1 > peak else peak
            e0, a0 = e1, a1
        out[o] = ise
        out[o + 1] = iae
        out[o + 2] = itae
        out[o + 3] = math.nan if nan else peak
        out[o + 4] = math.sqrt(ise / (t[n - 1] - t[first]))

    return errors


def _search(t: np.ndarray, value: float, side: Literal["left", "right"]) -> int:
    return int(np.searchsorted(t, value, side=side))


def _step_at(t: np.ndarray, t_step: float) -> tuple[int, int, bool, float]:
    """Where a step at ``t_step`` lies on ``t`` (nlcx.metrics.step._step_grid): the first sample
    at or after it, the sample j at or before it, whether it is on the grid, and the weight of
    sample j + 1 in y(t_step)."""
    i0 = _search(t, t_step, "left")
    j = _search(t, t_step, "right") - 1
    on_grid = j < 0 or t[j] == t_step
    return i0, j, on_grid, 0.0 if on_grid else (t_step - t[j]) / (t[j + 1] - t[j])


def _step_block(f: dict[str, Any], b: Block, t: np.ndarray) -> Any:
    """The device function of a ``step`` block (see :func:`nlcx.metrics.step_response_metrics`)."""
    ts, final, lo, hi, band, window = b.t_step, b.final, b.rise_low, b.rise_high, b.band, b.window
    i0, j, on_grid, a = _step_at(t, ts)
    shift = float(ts) - float(b.origin)
    q, ref_row, core, window_mean, errors = b.signal, b.ref_row, f["step_core"], f["window_mean"], f["errors"]

    @cuda().jit(device=True)
    def block(t, REC, REF, out, o, v):  # pragma: no cover - device
        y = REC[:, q, v]
        n = y.shape[0]
        initial = y[j] if on_grid else y[j] + a * (y[j + 1] - y[j])
        valid, _, _, ipk = core(t, y, i0, n, ts, initial, final, lo, hi, band, shift, out, o)
        out[o + 4] = y[ipk] if valid else math.nan
        peak_time = t[ipk] - ts
        out[o + 5] = (peak_time + shift if shift != 0.0 else peak_time) if valid else math.nan
        out[o + 6] = final - window_mean(t, y, i0, n, window)
        errors(t, y, REF[ref_row], i0, n, ts, out, o + 7)

    return block


def _info_block(f: dict[str, Any], b: Block, t: np.ndarray) -> Any:
    """The device function of an ``info`` block (see :func:`nlcx.metrics.step_info`, against
    the run's last sample, from y(t_step))."""
    ts, lo, hi, band, q = b.t_step, b.rise_low, b.rise_high, b.band, b.signal
    i0, j, on_grid, a = _step_at(t, ts)
    shift = float(ts) - float(b.origin)
    core, deviation_peak = f["step_core"], f["deviation_peak"]

    @cuda().jit(device=True)
    def block(t, REC, REF, out, o, v):  # pragma: no cover - device
        y = REC[:, q, v]
        n = y.shape[0]
        final = y[n - 1]
        initial = y[j] if on_grid else y[j] + a * (y[j + 1] - y[j])
        valid, t_hi, hi_index, _ = core(t, y, i0, n, ts, initial, final, lo, hi, band, shift, out, o)
        at = deviation_peak(y, i0, n, 0.0)  # the first largest |y|
        out[o + 4] = abs(y[at])
        out[o + 5] = (t[at] - ts) + shift if shift != 0.0 else t[at] - ts
        out[o + 6] = final
        low, high, nan = math.inf, -math.inf, False
        for i in range(i0 + hi_index, n):
            nan = nan or y[i] != y[i]
            low = y[i] if y[i] < low else low
            high = y[i] if y[i] > high else high
        risen = valid and t_hi == t_hi
        out[o + 7] = (math.nan if nan else min(low, final)) if risen else math.nan
        out[o + 8] = (math.nan if nan else max(high, final)) if risen else math.nan

    return block


def _regulation_block(f: dict[str, Any], b: Block, t: np.ndarray) -> Any:
    """The device function of a ``regulation`` block (see :func:`nlcx.metrics.regulation_metrics`)."""
    reference, band, tol, window, q, ref_row = b.final, b.band, b.abs_tol, b.window, b.signal, b.ref_row
    e0, ts = _search(t, b.t_step, "left"), b.t_step
    last_exit, window_mean, errors, deviation_peak = f["last_exit"], f["window_mean"], f["errors"], f["deviation_peak"]

    @cuda().jit(device=True)
    def block(t, REC, REF, out, o, v):  # pragma: no cover - device
        y = REC[:, q, v]
        n = y.shape[0]
        at = deviation_peak(y, 0, n, reference)
        peak = abs(y[at] - reference)
        band_abs = band * peak
        band_abs = band_abs if (band_abs != band_abs or band_abs > tol) else tol
        out[o] = peak
        out[o + 1] = t[at] - t[0]
        out[o + 2] = last_exit(t, y, 0, n, t[0], reference, band_abs)
        out[o + 3] = reference - window_mean(t, y, 0, n, window)
        errors(t, y, REF[ref_row], e0, n, ts, out, o + 4)

    return block


def _tracking_block(f: dict[str, Any], b: Block, t: np.ndarray) -> Any:
    e0, ts, q, ref_row, errors = _search(t, b.t_step, "left"), b.t_step, b.signal, b.ref_row, f["errors"]

    @cuda().jit(device=True)
    def block(t, REC, REF, out, o, v):  # pragma: no cover - device
        y = REC[:, q, v]
        errors(t, y, REF[ref_row], e0, y.shape[0], ts, out, o)

    return block


def _input_block(f: dict[str, Any], b: Block, t: np.ndarray) -> Any:
    q = b.signal

    @cuda().jit(device=True)
    def block(t, REC, REF, out, o, v):  # pragma: no cover - device
        u = REC[:, q, v]
        effort, variation, peak, nan = 0.0, 0.0, abs(u[0]), u[0] != u[0]
        for k in range(1, u.shape[0]):
            u0, u1 = u[k - 1], u[k]
            effort += ((u1 * u1 + u0 * u0) * 0.5) * (t[k] - t[k - 1])
            variation += abs(u1 - u0)
            a1 = abs(u1)
            nan = nan or a1 != a1
            peak = a1 if a1 > peak else peak
        out[o] = effort
        out[o + 1] = math.nan if nan else peak
        out[o + 2] = variation

    return block


_MAKERS = {
    "step": _step_block,
    "regulation": _regulation_block,
    "tracking": _tracking_block,
    "info": _info_block,
    "input": _input_block,
}


def _link(block: Any, width: int, rest: Any) -> Any:
    @cuda().jit(device=True)
    def link(t, REC, REF, out, o, v):  # pragma: no cover - device
        block(t, REC, REF, out, o, v)
        rest(t, REC, REF, out, o + width, v)

    return link


#: numba's CUDA module as a global of this module (where numba's simulator replaces it).
cuda_module: Any = None


_KERNELS: dict[tuple[tuple[Block, ...], bytes], Any] = {}


def metrics_kernel(blocks: tuple[Block, ...], t: np.ndarray) -> Any:
    """A kernel ``kernel(t, REC, REF, OUT, first)`` writing the values of the runs first,
    first + 1, ... of the records (OUT row v, the blocks' :data:`BLOCK_NAMES` one after the
    other) from their records (REC[:, :, first + v]) and the references REF (rows
    ``ref_row``); compiled once per blocks and time grid in a process."""
    key = (blocks, np.ascontiguousarray(t).tobytes())
    if key not in _KERNELS:
        grid = hashlib.sha256(key[1]).hexdigest()
        _KERNELS[key] = kept(_metrics_kernel(blocks, t), metrics_kernel, blocks, grid)
    return _KERNELS[key]


def _metrics_kernel(blocks: tuple[Block, ...], t: np.ndarray) -> Any:
    global cuda_module
    gpu = cuda_module = cuda()
    f = _scans()

    @gpu.jit(device=True)
    def done(t, REC, REF, out, o, v):  # pragma: no cover - device
        return

    chain = done
    for b in reversed(blocks):
        chain = _link(_MAKERS[b.kind](f, b, t), len(BLOCK_NAMES[b.kind]), chain)

    @gpu.jit
    def kernel(t, REC, REF, OUT, first):  # pragma: no cover - device
        v = cuda_module.grid(1)
        if v >= OUT.shape[0]:
            return
        chain(t, REC, REF, OUT[v], 0, first + v)

    return kernel

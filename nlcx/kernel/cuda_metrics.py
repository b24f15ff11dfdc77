"""The metric kernels on the GPU: one thread a run, from records kept there.

A closed-loop launch (:func:`nlcx.kernel.cuda_loop.launch`) leaves each run's measured signals
on the GPU, time-major (K+1, signals, B). :func:`metrics_kernel` measures them with the CPU's
own kernel, :func:`nlcx.metrics.kernels.measure`, compiled from its source for the GPU
(:class:`nlcx.kernel.device.Retarget`): per run, one call per :class:`MeasuredRecord`, each
writing its values after the previous one's, in the order of the loop's
:class:`~nlcx.engine.plan.LoopPlan`. The sums are added in the same order on both, so the
values are the CPU's bit for bit (functions of libdevice aside: docs/guide/gpu.md).
"""

from __future__ import annotations

import functools
import hashlib
from typing import Any, NamedTuple

import numpy as np

from nlcx.kernel.device import Retarget, cuda, kept
from nlcx.kernel.signatures import DeviceFunction, FloatArray, IntArray
from nlcx.metrics.kernels import Timing
from nlcx.metrics.sums import DEPTH


class MeasuredRecord(NamedTuple):
    """A measured signal as the metric kernel reads it: its kernel (``kind``), its record in
    the launch's records (``signal``), its row of the reference table (``ref_row``; -1: none),
    the constant it steps or is held to, where its step falls on the grid, and the number of
    values it writes (:class:`~nlcx.engine.plan.MeasuredSignal`)."""

    kind: int
    signal: int
    ref_row: int
    final: float
    timing: Timing
    width: int


@functools.cache
def _measure() -> DeviceFunction:
    """:func:`nlcx.metrics.kernels.measure` as a device function (compiled on first use)."""
    from nlcx.metrics.kernels import measure

    return Retarget().device(measure)


def _link(measure: DeviceFunction, record: MeasuredRecord, rest: DeviceFunction) -> DeviceFunction:
    """A device function measuring ``record`` into out[o:] and handing on to ``rest``."""
    kind, q, final, width, row = record.kind, record.signal, record.final, record.width, max(record.ref_row, 0)
    first, j, a, on_grid, t_step, shift, band, rise_low, rise_high, window, abs_tol = record.timing

    @cuda().jit(device=True)
    def link(
        t: FloatArray,
        REC: FloatArray,
        REF: FloatArray,
        out: FloatArray,
        o: int,
        v: int,
        ranges: IntArray,
        partial: FloatArray,
    ) -> None:  # pragma: no cover - device
        at = Timing(first, j, a, on_grid, t_step, shift, band, rise_low, rise_high, window, abs_tol)
        measure(kind, t, REC[:, q, v], REF[row], at, final, out, o, ranges, partial)
        rest(t, REC, REF, out, o + width, v, ranges, partial)

    return link


#: numba's CUDA module as a global of this module (where numba's simulator replaces it).
cuda_module: Any = None

_KERNELS: dict[tuple[tuple[MeasuredRecord, ...], bytes], DeviceFunction] = {}


def metrics_kernel(records: tuple[MeasuredRecord, ...], t: np.ndarray) -> DeviceFunction:
    """A kernel ``kernel(t, REC, REF, OUT, first)`` writing the values of the runs first,
    first + 1, ... of the records (OUT row v: each record's values one after the other) from
    their records (REC[:, :, first + v]) and the references REF (rows ``ref_row``); compiled
    once per records and time grid in a process."""
    key = (records, np.ascontiguousarray(t).tobytes())
    if key not in _KERNELS:
        grid = hashlib.sha256(key[1]).hexdigest()
        _KERNELS[key] = kept(_metrics_kernel(records), metrics_kernel, records, grid)
    return _KERNELS[key]


def _metrics_kernel(records: tuple[MeasuredRecord, ...]) -> DeviceFunction:
    global cuda_module
    gpu = cuda_module = cuda()
    from numba import float64, int64

    @gpu.jit(device=True)
    def done(
        t: FloatArray,
        REC: FloatArray,
        REF: FloatArray,
        out: FloatArray,
        o: int,
        v: int,
        ranges: IntArray,
        partial: FloatArray,
    ) -> None:  # pragma: no cover - device
        return

    chain, measure = done, _measure()
    for record in reversed(records):
        chain = _link(measure, record, chain)

    @gpu.jit
    def kernel(
        t: FloatArray, REC: FloatArray, REF: FloatArray, OUT: FloatArray, first: int
    ) -> None:  # pragma: no cover - device
        v = cuda_module.grid(1)
        if v >= OUT.shape[0]:
            return
        ranges = cuda_module.local.array((DEPTH, 3), int64)
        partial = cuda_module.local.array((DEPTH, 3), float64)
        chain(t, REC, REF, OUT[v], 0, first + v, ranges, partial)

    return kernel

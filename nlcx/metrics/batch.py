"""The metric kernels over the rows of a batch, on the CPU.

Each function calls one kernel of :mod:`nlcx.metrics.kernels` for every row of ``Y`` (a 2-D
array, rows on the grid ``t``, any strides) and writes row b's values to ``out[b]``. Per-row
arguments are arrays of one value a row; ``has_*`` says whether an optional one was given.
The work space of the pairwise sums is made once per call. Each row's values start at offset
``np.int64(0)`` of its output row, an int64 as the offsets :func:`~nlcx.metrics.kernels.measure`
computes (a literal 0 would compile the kernel once more: :mod:`nlcx.metrics.kernels`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from nlcx.kernel.signatures import FloatArray, IntArray
from nlcx.metrics.kernels import (
    error_integrals,
    input_effort,
    measure,
    regulation,
    step_info,
    step_response,
    value_at_step,
)
from nlcx.metrics.sums import DEPTH

if TYPE_CHECKING:
    from nlcx.metrics.kernels import Timing


@njit(cache=True, inline="always", error_model="numpy")
def _stack() -> tuple[IntArray, FloatArray]:  # pragma: no cover - compiled
    """The pairwise sums' work space (:func:`nlcx.metrics.sums.stack`)."""
    return np.zeros((DEPTH, 3), dtype=np.int64), np.zeros((DEPTH, 3))


@njit(cache=True, error_model="numpy")
def step_response_rows(
    t: FloatArray,
    Y: FloatArray,
    m: Timing,
    initial: FloatArray,
    has_initial: bool,
    final: FloatArray,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled
    """:func:`~nlcx.metrics.kernels.step_response` of every row (initial: y(t_step) unless given)."""
    ranges, partial = _stack()
    for b in range(Y.shape[0]):
        y = Y[b]
        start = initial[b] if has_initial else value_at_step(y, m)
        step_response(t, y, m, start, final[b], out[b], np.int64(0), ranges, partial)


@njit(cache=True, error_model="numpy")
def step_info_rows(
    t: FloatArray,
    Y: FloatArray,
    m: Timing,
    initial: FloatArray,
    has_initial: bool,
    final: FloatArray,
    has_final: bool,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled
    """:func:`~nlcx.metrics.kernels.step_info` of every row (initial: y(t_step), final: the
    row's last sample, unless given)."""
    for b in range(Y.shape[0]):
        y = Y[b]
        start = initial[b] if has_initial else value_at_step(y, m)
        target = final[b] if has_final else y[y.shape[0] - 1]
        step_info(t, y, m, start, target, out[b], np.int64(0))


@njit(cache=True, error_model="numpy")
def regulation_rows(
    t: FloatArray, Y: FloatArray, m: Timing, reference: FloatArray, out: FloatArray
) -> None:  # pragma: no cover - compiled
    """:func:`~nlcx.metrics.kernels.regulation` of every row."""
    ranges, partial = _stack()
    for b in range(Y.shape[0]):
        regulation(t, Y[b], m, reference[b], out[b], np.int64(0), ranges, partial)


@njit(cache=True, error_model="numpy")
def error_integral_rows(
    t: FloatArray, E: FloatArray, first: int, start: float, out: FloatArray
) -> None:  # pragma: no cover - compiled
    """:func:`~nlcx.metrics.kernels.error_integrals` of every row of errors E (e = E - 0, the
    same bits)."""
    ranges, partial = _stack()
    zero = np.zeros(E.shape[1])
    for b in range(E.shape[0]):
        error_integrals(t, zero, E[b], first, start, out[b], np.int64(0), ranges, partial)


@njit(cache=True, error_model="numpy")
def input_rows(t: FloatArray, U: FloatArray, out: FloatArray) -> None:  # pragma: no cover - compiled
    """:func:`~nlcx.metrics.kernels.input_effort` of every row."""
    ranges, partial = _stack()
    for b in range(U.shape[0]):
        input_effort(t, U[b], out[b], np.int64(0), ranges, partial)


@njit(cache=True, error_model="numpy")
def measure_rows(
    kind: int,
    t: FloatArray,
    Y: FloatArray,
    R: FloatArray,
    rows: IntArray,
    m: Timing,
    final: float,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled
    """:func:`~nlcx.metrics.kernels.measure` of the rows ``rows`` of Y (row rows[k] into
    out[k]) against the reference rows R (one row shared by all, or one a row of Y)."""
    ranges, partial = _stack()
    shared = R.shape[0] == 1
    for k in range(rows.shape[0]):
        b = rows[k]
        measure(kind, t, Y[b], R[0] if shared else R[b], m, final, out[k], np.int64(0), ranges, partial)

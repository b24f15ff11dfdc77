"""What every metric function shares: its inputs checked, its rows processed in blocks, time averages.

A signal of shape ``(T,)`` is one row, ``(B, T)`` is B rows on the grid ``t``. The rows are
processed in blocks of about ``_CHUNK_ELEMENTS`` samples (:func:`rows_per_block`) so that
temporaries stay bounded when ``B * T`` is large; each row is computed by the same row-wise
operations whatever the block it falls in, so a batched call equals the corresponding 1-D
calls exactly. Integrals use the trapezoidal rule on the given grid.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
MetricDict = dict[str, FloatArray]


# Rows per block = max(1, _CHUNK_ELEMENTS // T): bounds the size of the temporaries. 2 MB
# blocks stay in cache and are reused by the allocator; much larger blocks are memory-bound,
# every temporary freshly mapped. Blocks never change a result.
_CHUNK_ELEMENTS = 1 << 18


def prepare(t: ArrayLike, y: ArrayLike, name: str) -> tuple[FloatArray, FloatArray, bool]:
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


def per_row(value: ArrayLike, n_rows: int, name: str) -> FloatArray:
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


def run_batched(
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


def trapz(t: FloatArray, y: FloatArray) -> FloatArray:
    """Trapezoidal integral of each row: sum_k (t_k - t_{k-1}) * (y_k + y_{k-1}) / 2."""
    dt = np.diff(t)
    s = np.add(y[:, 1:], y[:, :-1])  # in place from here: one temporary, the same arithmetic
    s *= 0.5
    s *= dt
    return np.sum(s, axis=-1)


def window_mean(t: FloatArray, y: FloatArray, window: float) -> FloatArray:
    """Time-weighted (trapezoidal) mean of each row over ``[t[-1] - window, t[-1]]``.

    The window start is generally between samples; ``y`` there is interpolated linearly so
    the window has exactly the requested length.  If the record is shorter than the window
    the whole record ``[t[0], t[-1]]`` is used.
    """
    t_end = t[-1]
    w_start = t_end - window
    if w_start <= t[0]:
        return trapz(t, y) / (t_end - t[0])
    j = int(np.searchsorted(t, w_start, side="right"))  # t[j-1] <= w_start < t[j]
    a = (w_start - t[j - 1]) / (t[j] - t[j - 1])
    y_start = y[:, j - 1] + a * (y[:, j] - y[:, j - 1])
    head = 0.5 * (t[j] - w_start) * (y_start + y[:, j])
    return (head + trapz(t[j:], y[:, j:])) / window


def check_window(ss_window: float) -> float:
    """The steady-state window as a positive number of seconds; ValueError otherwise."""
    w = float(ss_window)
    if not (np.isfinite(w) and w > 0):
        raise ValueError(f"ss_window must be a positive number of seconds, got {ss_window!r}")
    return w


def check_band(band: float) -> float:
    """The settling band as a positive fraction; ValueError otherwise."""
    b = float(band)
    if not (np.isfinite(b) and b > 0):
        raise ValueError(f"band must be a positive fraction, got {band!r}")
    return b


def check_rise_limits(rise_limits: tuple[float, float]) -> tuple[float, float]:
    """The rise limits as an ordered pair (low < high); ValueError otherwise."""
    lo, hi = (float(v) for v in rise_limits)
    if not lo < hi:
        raise ValueError(f"rise_limits must satisfy lo < hi, got {rise_limits!r}")
    return lo, hi

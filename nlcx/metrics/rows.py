"""What every public metric function shares: its inputs checked, and its results by name.

A signal of shape ``(T,)`` is one row, ``(B, T)`` is B rows on the grid ``t``; each row is
measured by the same kernel (:mod:`nlcx.metrics.kernels`), so a batched call equals the
corresponding 1-D calls exactly.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
MetricDict = dict[str, FloatArray]


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


def by_name(values: FloatArray, names: tuple[str, ...], squeeze: bool) -> MetricDict:
    """The columns of ``values`` (B, len(names)), one a metric, by name; of shape () each when
    ``squeeze`` (a 1-D signal's)."""
    result = {name: np.ascontiguousarray(values[:, i]) for i, name in enumerate(names)}
    return {k: v.reshape(()) for k, v in result.items()} if squeeze else result


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

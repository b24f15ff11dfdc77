"""Time-domain performance metrics of simulated or measured responses (batched).

Every function takes a strictly increasing, not necessarily uniform, time grid ``t`` of
shape ``(T,)`` and a signal of shape ``(T,)`` or ``(B, T)``.  It returns a
``dict[str, np.ndarray]`` whose values have shape ``()`` for a 1-D signal and ``(B,)`` for
a 2-D one (:func:`step_info` returns floats for a 1-D signal).  The searches along a row
(crossings, last exits, extremes) and the terms of the trapezoidal sums are compiled row
scans (:mod:`nlcx.metrics.scans`), each one pass that stops as early as it can; the sums are
numpy's (pairwise), so every value is the numpy formulation's to the last bit
(tests/test_metrics_scans.py).  The batch axis is processed in blocks of rows
(:func:`rows_per_block`, :mod:`nlcx.metrics.rows`) so that temporaries stay bounded when
``B * T`` is large.  Each row is computed by the same row-wise operations whatever the block
it falls in, so a batched call equals the corresponding 1-D calls exactly.

Crossing times are interpolated linearly between samples (the signal is treated as
piecewise linear), so they are not quantised to the grid.  Peaks are sample values.
Integrals use the trapezoidal rule on the given grid.

The functions live by what they measure: a step response in :mod:`nlcx.metrics.step`
(:func:`step_response_metrics`, :func:`step_info`, their event times moved to another
origin by :func:`measured_from`), a regulated signal, an error and a
control input in :mod:`nlcx.metrics.regulation` (:func:`regulation_metrics`,
:func:`error_integrals`, :func:`input_metrics`); their names and units in
:mod:`nlcx.metrics.names`.

See ``docs/metrics.md`` for the definitions and their relation to python-control's
``step_info`` and MATLAB's ``stepinfo``.
"""

from __future__ import annotations

from nlcx.metrics.names import (
    ERROR_METRICS,
    EVENT_TIMES,
    INPUT_METRICS,
    METRIC_UNITS,
    REGULATION_METRICS,
    STEP_INFO_METRICS,
    STEP_INFO_UNITS,
    STEP_METRICS,
)
from nlcx.metrics.regulation import error_integrals, input_metrics, regulation_metrics
from nlcx.metrics.rows import FloatArray, MetricDict, rows_per_block
from nlcx.metrics.step import StepInfo, measured_from, step_info, step_response_metrics

__all__ = [
    "ERROR_METRICS",
    "EVENT_TIMES",
    "INPUT_METRICS",
    "METRIC_UNITS",
    "REGULATION_METRICS",
    "STEP_INFO_METRICS",
    "STEP_INFO_UNITS",
    "STEP_METRICS",
    "FloatArray",
    "MetricDict",
    "StepInfo",
    "error_integrals",
    "input_metrics",
    "measured_from",
    "regulation_metrics",
    "rows_per_block",
    "step_info",
    "step_response_metrics",
]

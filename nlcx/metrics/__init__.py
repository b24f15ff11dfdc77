"""Time-domain performance metrics of simulated or measured responses (batched).

Every function takes a strictly increasing, not necessarily uniform, time grid ``t`` of
shape ``(T,)`` and a signal of shape ``(T,)`` or ``(B, T)``.  It returns a
``dict[str, np.ndarray]`` whose values have shape ``()`` for a 1-D signal and ``(B,)`` for
a 2-D one (:func:`step_info` returns floats for a 1-D signal).  Each row is measured by the
compiled kernels of :mod:`nlcx.metrics.kernels`, the one implementation of every metric on
the CPU and the GPU: searches along the row (:mod:`nlcx.metrics.scans`) that stop as early
as they can, and trapezoidal sums added in numpy's pairwise order (:mod:`nlcx.metrics.sums`),
so every value is the numpy formulation's to the last bit (tests/test_metrics_kernels.py),
and a batched call equals the corresponding 1-D calls exactly.

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
from nlcx.metrics.rows import FloatArray, MetricDict
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
    "step_info",
    "step_response_metrics",
]

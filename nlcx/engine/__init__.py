"""From validated experiments to closed-loop trajectories and metrics: the one pipeline.

:func:`evaluate` takes experiments (or prepared ones) through prepare -> simulate ->
measure. It assembles the numeric arrays the compiled kernel (:mod:`nlcx.kernel`) reads,
runs every closed loop of every experiment on one time grid through it (loops sharing
their equations and controller step go through one batched call) and measures all runs
together (:mod:`nlcx.metrics`). ``nlcx run``, sweeps, the calibration, the reproduction and
the tuners (through :class:`LoopSimulator`) all use it.

The package by job; this module names what the rest of nlcx uses:

- :mod:`nlcx.engine.pipeline`: :func:`evaluate`, :func:`prepare`, :func:`remeasure`,
  :func:`run_experiment`, and :class:`LoopSimulator`, the tuners' way back into the pipeline;
- :mod:`nlcx.engine.prepared`: a prepared experiment's parts (time grid, references,
  perturbations, memory checks) and its closed loops (:func:`items_of`);
- :mod:`nlcx.engine.batching`: which loops share a kernel call;
- :mod:`nlcx.engine.simulate`: the kernel's arguments, its calls, their runs;
- :mod:`nlcx.engine.measure`: the metric rows of the runs;
- :mod:`nlcx.engine.prewarm`: the kernel loaded on demand, the rest compiled ahead;
- :mod:`nlcx.engine.results`: :class:`Run`, :class:`ExperimentResult` and the metric tables.
"""

from __future__ import annotations

from nlcx.engine.measure import measure_runs
from nlcx.engine.pipeline import LoopSimulator, evaluate, prepare, remeasure, run_experiment
from nlcx.engine.prepared import (
    TABLEAUS,
    Item,
    Prepared,
    Reference,
    ReferenceCache,
    Tableau,
    TimeGrid,
    check_sweep_memory,
    items_of,
    reference_array,
    time_grid,
)
from nlcx.engine.prewarm import load_kernel, prewarm
from nlcx.engine.results import METRIC_COLUMNS, ExperimentResult, MetricBlock, MetricTable, Run, shared_metrics
from nlcx.engine.simulate import simulate_items

__all__ = [
    "METRIC_COLUMNS",
    "TABLEAUS",
    "ExperimentResult",
    "Item",
    "LoopSimulator",
    "MetricBlock",
    "MetricTable",
    "Prepared",
    "Reference",
    "ReferenceCache",
    "Run",
    "Tableau",
    "TimeGrid",
    "check_sweep_memory",
    "evaluate",
    "items_of",
    "load_kernel",
    "measure_runs",
    "prepare",
    "prewarm",
    "reference_array",
    "remeasure",
    "run_experiment",
    "shared_metrics",
    "simulate_items",
    "time_grid",
]

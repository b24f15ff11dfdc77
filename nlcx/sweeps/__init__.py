"""Sweeps: many variants of one experiment, batched through the kernel, resumable.

A ``sweep:`` section varies any dotted config key::

    sweep:
      seed: 0
      grid: {uncertainty.friction.model: [simple, exponential]}        # cartesian product
      zip: {plant.params.M: [0.8, 1.2], plant.params.m: [0.08, 0.12]}  # paired lists
      random:                                                          # n seeded samples
        n: 1000
        params:
          plant.params.l: {dist: uniform, relative: 0.2}               # +-20 % of the base value
          plant.params.g: {dist: normal, mean: 9.8, std: 0.01}
      batch_size: 64          # variants per kernel call (and per result file)
      timeseries: false       # per-variant timeseries.csv only on request

The variants are the product grid x zip x random. Each variant's ``seed`` is spawned with
``numpy.random.SeedSequence`` from the sweep seed. Results are written per batch into
``parts/`` as they complete; a rerun skips every variant whose config hash already has a
complete result (``--force`` recomputes), so an interrupted sweep loses nothing finished.
The run directory gets ``sweep.csv`` (variant, varied values, seed, config hash, status,
wall time) and one long ``metrics.csv`` for all variants.

The directory is written whole (:mod:`nlcx.rundir`): the parts go into the sweep's staging
directory beside it, ``.<name>.nlcx-partial`` (:func:`nlcx.rundir.partial_dir`), which is
kept when the sweep is interrupted and resumed from by a rerun; a rerun into a finished
sweep resumes from that sweep's parts of the same variants (hard links, not copies). When
every batch is done, sweep.csv, metrics.csv, config.yaml, manifest.json and the report are
written beside the parts and the whole staging directory is renamed into place.

The steps live in their own modules: the plan (:mod:`nlcx.sweeps.planning`: the section, its
variants and their hashes), the batches a worker runs (:mod:`nlcx.sweeps.batches`), resuming
(:mod:`nlcx.sweeps.resuming`), the outputs assembled from the part files
(:mod:`nlcx.sweeps.assembly`) and the run over the executors (:mod:`nlcx.sweeps.runner`).
"""

from __future__ import annotations

from nlcx.sweeps.assembly import assemble
from nlcx.sweeps.batches import Batch, BatchResult, run_batch
from nlcx.sweeps.planning import (
    Distribution,
    RandomSpec,
    SweepSection,
    Variant,
    config_hash,
    expand,
    load,
    plan,
    variant_hash,
)
from nlcx.sweeps.resuming import completed
from nlcx.sweeps.runner import SweepOutcome, make_executor, run

__all__ = [
    "Batch",
    "BatchResult",
    "Distribution",
    "RandomSpec",
    "SweepOutcome",
    "SweepSection",
    "Variant",
    "assemble",
    "completed",
    "config_hash",
    "expand",
    "load",
    "make_executor",
    "plan",
    "run",
    "run_batch",
    "variant_hash",
]

"""The identification's fits on the GPU: every hypothesis's GA stepped a generation at a time, side by side.

With ``device: cuda`` (:mod:`nlcx.thesis.identify`), the hypotheses to fit are not handed to
worker processes one each. Their GAs (:func:`nlcx.tuning.optimise.evolution`) are stepped
together in this process, and each generation's populations, packed into every hypothesis's
train tables (:mod:`nlcx.thesis.packed_cells`), go to the GPU in one call
(:func:`nlcx.engine.gpu.simulate_measure_all`): the loops of all hypotheses that compile to the
same closed-loop kernel run as the rows of one launch, so a generation is a few launches of
thousands of loops instead of one launch of tens of loops per hypothesis, table and structure.
The train tables' experiments are read once for all of them.

Each GA draws from its own seeded random state and each loop is its own GPU thread, so every
fit is the one its hypothesis gets when fitted alone. The fitted loops are then measured on
every table, :data:`MEASURED_TOGETHER` hypotheses to a pipeline call. A fit's ``wall_s`` is the
lockstep's time until it was measured.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from nlcx.engine.gpu import ensembles_metrics
from nlcx.thesis import hypotheses
from nlcx.thesis.fitting import FitObjective, Search, TableRuns, fitted, fitted_values, measure_fits, search
from nlcx.tuning.optimise import GASettings, OptimResult, evolution

#: Fitted hypotheses measured on every table in one pipeline call (their trajectories come back
#: from the GPU to be measured, so this bounds the host memory they take).
MEASURED_TOGETHER = 16


def fits(
    free: dict[str, tuple[float, float]], settings: GASettings, root: Path, todo: list[hypotheses.Hypothesis],
    cells: pd.DataFrame, start: dict[str, float] | None, device: str = "cuda",
) -> Iterator[tuple[dict[str, Any], pd.DataFrame]]:  # fmt: skip
    """The fit of each hypothesis of ``todo`` (summary, fit table), in ``todo``'s order: the GA
    ``settings`` over the conventional gains ``free`` and the hypothesis's freed parameters, the
    first population seeded with ``start`` (as :func:`nlcx.thesis.identify.fit_hypothesis`), its
    loops on ``device``."""
    if not todo:
        return
    t0 = time.perf_counter()
    runs = TableRuns(root, list(dict.fromkeys(cells.table)), device=device)
    searches = [search(root, hyp, free, cells, device, start, runs) for hyp in todo]
    results = evolve_together(searches, settings)
    for first in range(0, len(todo), MEASURED_TOGETHER):
        chunk = range(first, min(first + MEASURED_TOGETHER, len(todo)))
        values = [fitted_values(searches[k].objective, results[k]) for k in chunk]
        ours = measure_fits(runs, [(todo[k], v) for k, v in zip(chunk, values, strict=True)], cells)
        for k, v, o in zip(chunk, values, ours, strict=True):
            yield fitted(todo[k], cells, v, results[k], o, time.perf_counter() - t0)


def evolve_together(searches: list[Search], settings: GASettings) -> list[OptimResult]:
    """The GA of each search (:func:`nlcx.tuning.optimise.evolution`), stepped side by side, every
    generation's populations evaluated together (:func:`generation_losses`)."""
    generations = [evolution(s.lower, s.upper, settings, start=s.start) for s in searches]
    asked = {k: next(g) for k, g in enumerate(generations)}
    results: dict[int, OptimResult] = {}
    while asked:
        active = list(asked)
        losses = generation_losses([searches[k].objective for k in active], [asked[k] for k in active])
        for k, f in zip(active, losses, strict=True):
            try:
                asked[k] = generations[k].send(f)
            except StopIteration as done:
                results[k] = done.value
                del asked[k]
    return [results[k] for k in range(len(searches))]


def generation_losses(objectives: list[FitObjective], populations: list[np.ndarray]) -> list[np.ndarray]:
    """The train loss of each population under its objective, every packed table's ensemble of
    every population simulated and measured in one call (on the GPU: together)."""
    ensembles = [o.ensembles(X) for o, X in zip(objectives, populations, strict=True)]
    measured = iter(ensembles_metrics([e for mine in ensembles for e in mine.values()]))
    return [
        o.losses(X, {table: next(measured) for table in mine})
        for o, X, mine in zip(objectives, populations, ensembles, strict=True)
    ]

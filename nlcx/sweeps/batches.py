"""A sweep's batches: the variants simulated together in one task, in a worker or in the sweep's process.

:func:`run_batch` is what a process pool's worker runs (pickled by its module path): it builds
and prepares each variant, simulates them in one pipeline call and writes the batch's part
files, the metrics and the index, then their seal (:mod:`nlcx.sweeps.seals`), which marks the
batch complete.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
import pandas as pd

import nlcx.sweeps.seals as seals
from nlcx import config as cfg
from nlcx import plugins, runtime
from nlcx.sweeps.planning import Variant

if TYPE_CHECKING:
    from nlcx.engine.prepared import Prepared


@dataclass
class Batch:
    """Variants simulated together in one task."""

    base_raw: dict[str, object]
    variants: list[Variant]
    hashes: list[str]
    out_dir: Path
    timeseries: bool
    #: The metrics to keep (``sweep.metrics``); None: every metric.
    metrics: tuple[str, ...] | None = None


@dataclass
class BatchResult:
    """What a batch reports: its part's name, its number of variants and their statuses (status ->
    count); a per-variant batch also its rows of sweep.csv and its metrics (unless left out)."""

    index: list[dict[str, object]] = field(default_factory=list)
    metrics: pd.DataFrame | None = None
    part: str = ""
    variants: int = 0
    statuses: dict[str, int] = field(default_factory=dict)


def _cell(value: object) -> object:
    """A varied value as a sweep.csv cell: a mapping or list (e.g. a whole section) as JSON."""
    return json.dumps(value, sort_keys=True) if isinstance(value, dict | list) else value


def run_batch(batch: Batch, return_metrics: bool = True) -> BatchResult:
    """Simulate a batch of variants and write its part files (the metrics, the index, their seal).

    ``return_metrics=False`` leaves the metrics out of the result (a pool worker's result
    travels back pickled; the sweep reads the metrics from the part files). After the batch
    a command's or a worker's heap is settled (:func:`nlcx.runtime.settle_heap`)."""
    try:
        return _run_batch(batch, return_metrics)
    finally:
        runtime.settle_heap()


def _run_batch(batch: Batch, return_metrics: bool) -> BatchResult:
    from nlcx import engine, report

    rows: list[dict[str, object]] = []
    prepared_of: dict[int, Prepared] = {}
    # a worker that did not fork from the sweep's process; the entries as load_config_imports resolved them
    plugins.load(cast("list[str]", batch.base_raw.get(plugins.IMPORTS, [])))
    interpolated = cfg.Interpolated.of(batch.base_raw, allow_env=True)  # checked by planning.load
    base = cfg.build(interpolated.resolved)  # valid: sweep.load built it
    for pos, (variant, digest) in enumerate(zip(batch.variants, batch.hashes, strict=True)):
        row: dict[str, object] = {"variant": variant.index, "seed": variant.seed, "config_hash": digest}
        row.update({f"value:{k}": _cell(v) for k, v in variant.values.items()})
        try:
            prepared_of[pos] = engine.prepare(cfg.build(variant.resolve(interpolated), like=base))
            row.update(status="ok", message="")
        except Exception as exc:  # a bad variant is recorded; the others go on
            row.update(status="failed", message=str(exc).splitlines()[0])
        rows.append(row)
    # one pipeline call: variants on the same time grid go through the kernel together
    members = list(prepared_of)
    results = engine.evaluate([prepared_of[pos] for pos in members], record_logs=batch.timeseries)
    written: list[Path] = []
    for pos, result in zip(members, results, strict=True):
        row = rows[pos]
        unstable = [run for run in result.runs if run.status != "ok"]
        if unstable:
            row.update(status="unstable", message=f"{unstable[0].label}: {unstable[0].reason}")
        if batch.timeseries:
            stem = batch.out_dir / "timeseries" / f"variant_{batch.variants[pos].index:06d}"
            fmt = result.prepared.experiment.section.outputs.timeseries_format
            written.append(report.write_timeseries(stem, report.timeseries_columns(result), fmt))
    metrics = engine.shared_metrics(results)
    if batch.metrics is not None:
        metrics = metrics[metrics.metric.isin(batch.metrics)].reset_index(drop=True)
    index_of = np.array([batch.variants[pos].index for pos in members], dtype=int)
    metrics.insert(0, "variant", index_of[metrics.pop("experiment").to_numpy(dtype=int)])
    digest = hashlib.sha256("".join(batch.hashes).encode()).hexdigest()[:10]
    part = f"{batch.variants[0].index:06d}-{digest}"
    # an empty text (a metric's note when it has none) as a missing value, which is how
    # assemble reads it back: the file's rows are then metrics.csv's rows, byte for byte, and
    # assemble can join the files of a sweep computed in one go (nlcx.sweeps.assembly)
    parts = batch.out_dir / "parts"
    report.write_csv(parts / f"{part}.metrics.csv", metrics, empty_as_missing=True)
    report.write_csv(parts / f"{part}.index.csv", pd.DataFrame(rows))
    seals.seal(batch.out_dir, part, [parts / f"{part}.metrics.csv", parts / f"{part}.index.csv", *written])  # last
    statuses = pd.Series([row["status"] for row in rows]).value_counts().to_dict()
    return BatchResult(
        rows, metrics if return_metrics else None, part, len(rows), {str(k): int(v) for k, v in statuses.items()}
    )

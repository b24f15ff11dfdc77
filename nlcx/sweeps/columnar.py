"""Columnar sweeps: a plan of numbers packed straight into the kernel's arrays.

When every varied value is a number that lands, as itself, in the arrays the kernel reads
(plant parameters, gains, schedule ranges, initial states, bounds, uncertainty amplitudes),
the variants need no config of their own. :func:`packing` finds out, once per sweep, by
probing: it prepares the first variant (the template), then each key at its column's
extremes, and compares the kernel's arrays (:func:`nlcx.engine.ensembles.changed_positions`).
A key qualifies when the entries it changes hold the value itself, and the loops' structure
(compiled functions, shapes, metric plans) stays the same. Every corner of the box the
columns span is then prepared and validated, and its arrays must equal the template's with the
corner's values written in: the columns are validated once, as intervals, instead of one
config per variant (a field's bounds and the linear checks between fields hold on the whole
box when they hold at its corners). Anything else, a varied text or section, a key that
changes the loop structure or enters the arrays transformed, a tuned controller, uncertainties
drawing from the variant's seed, or a corner that fails validation, keeps the sweep on the
per-variant path (:mod:`nlcx.sweeps.batches`), which validates and prepares each variant.

:func:`run_column_batch` is a worker's task: it packs its variants from the columns, simulates
them (:func:`nlcx.engine.ensembles.simulate_ensemble`), measures them as columns and writes the
batch's part files in Parquet: the metrics, then the index (sweep.csv's rows), which marks the
batch complete.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

import nlcx.sweeps.seals as seals
from nlcx import config as cfg
from nlcx import plugins
from nlcx.errors import NlcxError
from nlcx.sweeps.planning import ColumnPlan, SweepSection, Variant, variant_hash

if TYPE_CHECKING:
    import pyarrow as pa

    from nlcx.engine.ensembles import LoopRows, Slot, Template
    from nlcx.engine.metric_rows import MetricColumns
    from nlcx.sweeps.batches import BatchResult

#: Up to this many varied keys every corner of their box is probed; above it, the two corners
#: of all lows and all highs.
MAX_CORNER_KEYS = 6
#: The records of one batch (states and inputs of every loop at every sample) stay below this.
BATCH_RECORD_BYTES = 64 * 2**20
#: At most this many variants a batch: the kernel steps a batch's variants together, and beyond
#: a few thousand their states no longer stay in cache (the kernel's time per step grows).
MAX_BATCH_VARIANTS = 2000
#: A plan is cut into about this many batches (fewer when a batch would be smaller than the
#: sweep's batch_size), whatever the number of workers, so that the outputs do not depend on it.
TARGET_BATCHES = 64
#: Variants per batch of a sweep on the GPU: its metrics and index come back batch by batch,
#: and the GPU runs each in as few chunks as its memory allows.
GPU_BATCH_VARIANTS = 250_000


@dataclass(frozen=True)
class Packing:
    """Where each varied key lands in the template's arrays (:class:`nlcx.engine.ensembles.Slot`)."""

    slots: dict[str, tuple[Slot, ...]]
    #: The bytes of one variant's records (every loop's states and inputs at every sample).
    record_bytes: int


class _Probe:
    """Templates of the sweep's base config with some values and a seed set."""

    def __init__(self, base_raw: dict[str, object]) -> None:
        # a worker that did not fork from the sweep's process; the entries as load_config_imports resolved them
        plugins.load(cast("list[str]", base_raw.get(plugins.IMPORTS, [])))
        self.interpolated = cfg.Interpolated.of(base_raw, allow_env=True)  # checked by planning.load
        self.base = cfg.build(self.interpolated.resolved)

    def template(self, values: Mapping[str, float], seed: int) -> Template:
        from nlcx import engine
        from nlcx.engine.ensembles import Template

        settings = Variant(0, values, seed).settings()
        return Template.of(engine.prepare(cfg.build(self.interpolated.resolve(settings), like=self.base)))


def _probe_values(column: np.ndarray, first: float) -> list[float]:
    """The column's extremes other than the template's own value (as Python numbers)."""
    return [v for v in dict.fromkeys([column.min().item(), column.max().item()]) if v != first]


def _corners(columns: dict[str, np.ndarray]) -> list[dict[str, float]]:
    """The corners of the box the columns span (:data:`MAX_CORNER_KEYS`)."""
    ranges = {k: (c.min().item(), c.max().item()) for k, c in columns.items()}
    if len(ranges) <= MAX_CORNER_KEYS:
        return [dict(zip(ranges, corner, strict=True)) for corner in itertools.product(*ranges.values())]
    return [{k: r[0] for k, r in ranges.items()}, {k: r[1] for k, r in ranges.items()}]


def packing(base_raw: dict[str, object], spec: SweepSection, plan: ColumnPlan | None) -> Packing | str:
    """The sweep's :class:`Packing`, or why its variants need configs of their own (a text)."""
    from nlcx.engine.ensembles import corner_agrees, probed_slots, same_arrays

    if spec.timeseries:
        return "the sweep keeps time series"
    if plan is None:
        return "a varied value is not a number"
    probe = _Probe(base_raw)
    first, seed = plan.values(0), int(plan.seeds[0])
    try:
        template = probe.template(first, seed)
        if template.prepared.tuning:
            return "a controller is tuned"
        other_seed = probe.template(first, (seed + 1) % 2**32)
        if not same_arrays(template.arrays(), other_seed.arrays()):
            return "the uncertainties draw from the variant's seed"
        probes = {key: _probe_values(column, first[key]) for key, column in plan.columns.items()}
        slots = probed_slots(template, lambda key, value: probe.template({**first, key: value}, seed), first, probes)
        if isinstance(slots, str):
            return slots
        for corner in _corners(plan.columns):
            values = {**first, **corner}
            if not corner_agrees(template, probe.template(values, seed), slots, values):
                return "the varied values act on the loops together, not each as itself"
    except NlcxError as exc:
        return f"a corner of the varied values is not valid ({str(exc).splitlines()[0]})"
    prepared = template.prepared
    width = len(prepared.plant.states) + len(prepared.plant.inputs)
    return Packing(slots, len(template.items) * prepared.grid.t.size * width * 8)


def batch_size(spec: SweepSection, n_variants: int, record_bytes: int, device: str = "cpu") -> int:
    """Variants per columnar batch: about :data:`TARGET_BATCHES` batches, at least the sweep's
    ``batch_size``, at most :data:`MAX_BATCH_VARIANTS` and what keeps a batch's records under
    :data:`BATCH_RECORD_BYTES` (``record_bytes``: one variant's). Independent of the number of workers.
    On the GPU (``device="cuda"``), where records stay on the device, :data:`GPU_BATCH_VARIANTS`
    (a batch larger than the GPU's memory holds runs in chunks there)."""
    if device == "cuda":
        return max(1, min(n_variants, GPU_BATCH_VARIANTS))
    size = max(spec.batch_size, -(-n_variants // TARGET_BATCHES))
    return max(1, min(size, MAX_BATCH_VARIANTS, BATCH_RECORD_BYTES // max(record_bytes, 1)))


@dataclass
class ColumnBatch:
    """Variants ``first`` .. ``first + n - 1`` of a columnar plan: their values and seeds."""

    base_raw: dict[str, object]
    first: int
    columns: dict[str, np.ndarray]
    seeds: np.ndarray
    #: The template's values and seed (the plan's first variant), from which a worker prepares it.
    template: tuple[dict[str, float], int]
    packing: Packing
    base_digest: str
    out_dir: Path
    metrics: tuple[str, ...] | None = None
    part: str = field(default="")

    def __post_init__(self) -> None:
        digest = hashlib.sha256(self.base_digest.encode())
        for key, column in self.columns.items():
            digest.update(key.encode())
            digest.update(np.ascontiguousarray(column).tobytes())
        digest.update(np.ascontiguousarray(self.seeds).tobytes())
        self.part = f"{self.first:09d}-{digest.hexdigest()[:10]}"

    @property
    def n(self) -> int:
        return int(self.seeds.size)


def column_batches(
    base_raw: dict[str, object], plan: ColumnPlan, found: Packing, digest: str, out: Path, size: int,
    metrics: tuple[str, ...] | None,
) -> list[ColumnBatch]:  # fmt: skip
    """The plan cut into batches of ``size`` variants."""
    template = (plan.values(0), int(plan.seeds[0]))
    return [
        ColumnBatch(base_raw, k, {key: c[k : k + size] for key, c in plan.columns.items()}, plan.seeds[k : k + size],
                    template, found, digest, out, metrics)
        for k in range(0, plan.n, size)
    ]  # fmt: skip


_TEMPLATES: dict[str, Template] = {}


def _template(batch: ColumnBatch) -> Template:
    """The batch's template, prepared once per process (kept for the batches that follow)."""
    values, seed = batch.template
    key = variant_hash(batch.base_digest, Variant(0, values, seed))
    if key not in _TEMPLATES:
        _TEMPLATES.clear()
        _TEMPLATES[key] = _Probe(batch.base_raw).template(values, seed)
    return _TEMPLATES[key]


def _statuses(template: Template, rows: list[LoopRows], n: int) -> tuple[np.ndarray, list[str | None]]:
    """Each variant's status ("ok", or "unstable" when a loop stopped) and message (the first
    stopped loop's label and reason), as :func:`nlcx.sweeps.batches.run_batch` records them."""
    unstable = np.zeros(n, dtype=bool)
    message: list[str | None] = [None] * n
    for i, loop in enumerate(rows):
        for e, reason in zip(loop.stopped, loop.reasons, strict=True):
            if not unstable[e]:
                message[e] = f"{template.items[i].controller.label}: {reason}"
        unstable[loop.stopped] = True
    return np.where(unstable, "unstable", "ok"), message


def _text(values: Sequence[str | None]) -> pa.Array:
    import pyarrow as pa

    return pa.array(values, pa.string())


def _coded(codes: np.ndarray, categories: list[str]) -> pa.DictionaryArray:
    """A text column from int32 codes into ``categories`` (-1: missing), dictionary-encoded."""
    import pyarrow as pa

    missing = codes < 0
    indices = pa.array(codes, pa.int32(), mask=missing if missing.any() else None)
    return pa.DictionaryArray.from_arrays(indices, _text(categories))


def _floats(values: np.ndarray) -> pa.Array:
    """Floats with NaN as a missing value (as metrics.csv writes them)."""
    import pyarrow as pa

    return pa.array(values, pa.float64(), mask=np.isnan(values))


def variant_hashes(batch: ColumnBatch) -> list[str]:
    """Each variant's config hash in a columnar sweep: sha256 (its first 16 hex digits) of the
    base config's digest and the varied keys, then the variant's values (in key order, each as
    its 8 little-endian bytes: float64, or int64 for an integer column) and its seed. It
    identifies a variant's result by its inputs, whatever its batch or index, as
    :func:`~nlcx.sweeps.planning.variant_hash` does on the per-variant path (which hashes the
    values' JSON text, a few microseconds more a variant)."""
    keys = sorted(batch.columns)
    head = json.dumps({"base": batch.base_digest, "keys": keys}).encode()
    layout = [(k, "<i8" if batch.columns[k].dtype.kind in "iu" else "<f8") for k in keys] + [("seed", "<i8")]
    rows = np.empty(batch.n, dtype=layout)
    for key in keys:
        rows[key] = batch.columns[key]
    rows["seed"] = batch.seeds
    data, width = rows.tobytes(), rows.dtype.itemsize
    return [hashlib.sha256(head + data[j * width : (j + 1) * width]).hexdigest()[:16] for j in range(batch.n)]


def _index_table(batch: ColumnBatch, status: np.ndarray, message: list[str | None]) -> pa.Table:
    """The batch's rows of sweep.csv: variant, seed, config hash, the values, status, message."""
    import pyarrow as pa

    variants = np.arange(batch.first, batch.first + batch.n, dtype=np.int64)
    columns = {
        "variant": pa.array(variants),
        "seed": pa.array(batch.seeds.astype(np.int64)),
        "config_hash": _text(variant_hashes(batch)),
    }
    for key, column in batch.columns.items():
        columns[f"value:{key}"] = _floats(column) if column.dtype.kind == "f" else pa.array(column)
    columns["status"] = _text(status.tolist())
    columns["message"] = _text(message)
    return pa.table(columns)


def _metrics_table(batch: ColumnBatch, measured: MetricColumns) -> pa.Table:
    """The batch's rows of metrics.csv (those of ``batch.metrics`` when it names some)."""
    import pyarrow as pa

    variant, value, codes = measured.variant, measured.value, measured.codes
    if batch.metrics is not None:
        names = measured.categories["metric"]
        keep = np.isin(codes["metric"], [k for k, name in enumerate(names) if name in batch.metrics])
        variant, value, codes = variant[keep], value[keep], {k: c[keep] for k, c in codes.items()}
    cats = measured.categories
    return pa.table({
        "variant": pa.array(variant + batch.first, pa.int64()),
        **{name: _coded(codes[name], cats[name]) for name in ("controller", "signal", "metric")},
        "value": _floats(value),
        **{name: _coded(codes[name], cats[name]) for name in ("unit", "status", "note")},
    })  # fmt: skip


def write_parquet_table(path: Path, table: pa.Table) -> None:
    """``table`` as a Parquet file, written atomically: snappy-compressed (half zstd's time, a
    fifth more bytes), its repeated texts dictionary-encoded, min/max statistics for ``variant``
    only (a reader selecting variants skips parts by them; the others cost a third of the write)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from nlcx.drawing import atomic_write

    text = [f.name for f in table.schema if pa.types.is_dictionary(f.type) or pa.types.is_string(f.type)]
    text = [name for name in text if name != "config_hash"]  # every one distinct: no dictionary
    options = {"compression": "snappy", "use_dictionary": text, "write_statistics": ["variant"]}
    atomic_write(path, lambda tmp: pq.write_table(table, str(tmp), **options))


def run_column_batch(batch: ColumnBatch) -> BatchResult:
    """Simulate and measure a columnar batch; write its part files (the metrics, the index, then
    their seal, which marks the batch complete). Returns the batch's
    :class:`~nlcx.sweeps.batches.BatchResult`."""
    from nlcx import runtime
    from nlcx.engine.gpu import ensemble_metrics
    from nlcx.sweeps.batches import BatchResult

    try:
        template = _template(batch)
        rows, measured = ensemble_metrics(template, batch.packing.slots, batch.columns, batch.n)
        status, message = _statuses(template, rows, batch.n)
        metrics = _metrics_table(batch, measured)
        parts = batch.out_dir / "parts"
        files = (parts / f"{batch.part}.metrics.parquet", parts / f"{batch.part}.index.parquet")
        write_parquet_table(files[0], metrics)
        write_parquet_table(files[1], _index_table(batch, status, message))
        seals.seal(batch.out_dir, batch.part, files)
        counts = dict(zip(*np.unique(status, return_counts=True), strict=True))
        return BatchResult(part=batch.part, variants=batch.n, statuses={str(k): int(v) for k, v in counts.items()})
    finally:
        runtime.settle_heap()

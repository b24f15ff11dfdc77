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
"""

from __future__ import annotations

import copy
import functools
import gc
import hashlib
import itertools
import json
import math
import os
import time
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, model_validator

from nlcx import config as cfg
from nlcx.errors import ConfigError, NlcxError
from nlcx.validation import validate_model

if TYPE_CHECKING:
    from nlcx import engine

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


class Distribution(BaseModel):
    """A random parameter: uniform [low, high] or +-relative x base, normal, log-uniform, choice."""

    model_config = ConfigDict(extra="forbid")
    dist: Literal["uniform", "normal", "loguniform", "choice"]
    low: float | None = None
    high: float | None = None
    #: For uniform: draw from [base (1 - relative), base (1 + relative)] around the config's value.
    relative: float | None = Field(None, gt=0)
    mean: float | None = None
    std: float | None = Field(None, gt=0)
    values: list[Any] | None = None

    @model_validator(mode="after")
    def _complete(self) -> Distribution:
        need = {
            "uniform": self.relative is not None or (self.low is not None and self.high is not None),
            "loguniform": self.low is not None and self.high is not None and 0 < self.low < self.high,
            "normal": self.mean is not None and self.std is not None,
            "choice": bool(self.values),
        }
        if not need[self.dist]:
            hints = {
                "uniform": "low and high, or relative",
                "loguniform": "0 < low < high",
                "normal": "mean and std",
                "choice": "a non-empty list of values",
            }
            raise ValueError(f"a {self.dist} distribution needs {hints[self.dist]}")
        return self


class RandomSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    n: int = Field(ge=1)
    params: dict[str, Distribution] = Field(min_length=1)


class SweepSection(BaseModel):
    model_config = ConfigDict(extra="forbid")
    seed: int = Field(0, ge=0)
    grid: dict[str, list[Any]] = Field(default_factory=dict)
    zip: dict[str, list[Any]] = Field(default_factory=dict)
    random: RandomSpec | None = None
    batch_size: int = Field(64, ge=1)
    timeseries: bool = False

    @model_validator(mode="after")
    def _zip_lengths(self) -> SweepSection:
        lengths = {len(v) for v in self.zip.values()}
        if len(lengths) > 1:
            raise ValueError(f"zip lists must have the same length, got {sorted(lengths)}")
        for key, values in self.grid.items():
            if not values:
                raise ValueError(f"grid list of {key} is empty")
        return self


@dataclass(frozen=True)
class Variant:
    """One point of a sweep: its index, the values it sets and its spawned seed."""

    index: int
    values: dict[str, Any]
    seed: int

    def overrides(self) -> list[str]:
        """The variant as ``key=value`` overrides (what ``--dry-run`` prints)."""
        return [f"{key}={json.dumps(value)}" for key, value in self.values.items()] + [f"seed={self.seed}"]

    def settings(self) -> list[tuple[list[str], Any]]:
        """The variant as (key path, value) pairs for :func:`nlcx.config.set_values`."""
        return [(key.split("."), value) for key, value in self.values.items()] + [(["seed"], self.seed)]

    def resolve(self, base: cfg.Interpolated) -> dict[str, Any]:
        """The variant's raw config: the base with its values and seed set, interpolated (the
        base interpolated once, :class:`nlcx.config.Interpolated`)."""
        return base.resolve(self.settings())


def _lookup(raw: dict[str, Any], key: str) -> Any:
    node: Any = raw
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ConfigError(
                f"sweep.random.params.{key}", None, "relative needs the key to have a value in the config"
            )
        node = node[part]
    return node


def _draw(dist: Distribution, base: Any, n: int, rng: np.random.Generator) -> list[Any]:
    if dist.dist == "uniform":
        if dist.relative is not None:
            lo, hi = float(base) * (1 - dist.relative), float(base) * (1 + dist.relative)
        else:
            lo, hi = float(dist.low), float(dist.high)  # type: ignore[arg-type]
        return [float(v) for v in rng.uniform(min(lo, hi), max(lo, hi), n)]
    if dist.dist == "loguniform":
        return [float(v) for v in np.exp(rng.uniform(math.log(dist.low), math.log(dist.high), n))]  # type: ignore[arg-type]
    if dist.dist == "normal":
        return [float(v) for v in rng.normal(dist.mean, dist.std, n)]
    values = dist.values or []
    return [values[i] for i in rng.integers(0, len(values), n)]


def expand(spec: SweepSection, base_raw: dict[str, Any]) -> list[Variant]:
    """The variants of ``spec``: grid x zip x random, each with a spawned seed."""
    grid_keys = list(spec.grid)
    grid_points = [dict(zip(grid_keys, combo, strict=True)) for combo in itertools.product(*spec.grid.values())]
    zip_keys = list(spec.zip)
    n_zip = len(next(iter(spec.zip.values()))) if spec.zip else 1
    zip_points = [{k: spec.zip[k][i] for k in zip_keys} for i in range(n_zip)]
    if spec.random is not None:
        root = np.random.SeedSequence(spec.seed)
        rng = np.random.default_rng(root.spawn(1)[0])
        draws = {}
        for key, dist in spec.random.params.items():
            base = _lookup(base_raw, key) if dist.relative is not None else None
            draws[key] = _draw(dist, base, spec.random.n, rng)
        random_points = [{k: draws[k][i] for k in draws} for i in range(spec.random.n)]
    else:
        random_points = [{}]
    combos = [{**g, **z, **r} for g in grid_points for z in zip_points for r in random_points]
    children = np.random.SeedSequence(spec.seed).spawn(len(combos) + 1)[1:]
    return [
        Variant(index=i, values=values, seed=int(child.generate_state(1)[0]))
        for i, (values, child) in enumerate(zip(combos, children, strict=True))
    ]


def config_hash(raw: Any) -> str:
    """A stable hash of a config (canonical JSON)."""
    text = json.dumps(raw, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def variant_hash(base_digest: str, variant: Variant) -> str:
    """What identifies a variant's result for resuming: the hash of its base config (before
    interpolation, so a change anywhere in it counts) with the values and seed it sets; the
    variant's resolved config is a function of exactly these."""
    return config_hash({"base": base_digest, "values": variant.values, "seed": variant.seed})


@dataclass
class Batch:
    """Variants simulated together in one task."""

    base_raw: dict[str, Any]
    variants: list[Variant]
    hashes: list[str]
    out_dir: Path
    timeseries: bool


@dataclass
class BatchResult:
    index: list[dict[str, Any]] = field(default_factory=list)
    metrics: pd.DataFrame | None = None
    part: str = ""


def _set_threads() -> None:
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"


@functools.cache
def _records() -> engine.RecordArena:
    """This process's :class:`~nlcx.engine.RecordArena`: a worker's batches write their
    trajectories into the same memory, one batch after the other."""
    from nlcx import engine

    return engine.RecordArena()


def _settle_heap() -> None:
    """Collect, then freeze what survives (imported modules, loaded kernels, caches).

    A worker's later collections then scan only the objects of the batch in hand instead of
    numba's and pandas' object graphs again and again (about 15 % of a batch's time)."""
    gc.collect()
    gc.freeze()


def _cell(value: Any) -> Any:
    """A varied value as a sweep.csv cell: a mapping or list (e.g. a whole section) as JSON."""
    return json.dumps(value, sort_keys=True) if isinstance(value, dict | list) else value


def run_batch(batch: Batch, return_metrics: bool = True) -> BatchResult:
    """Simulate a batch of variants and write its part files (the metrics, then the index).

    ``return_metrics=False`` leaves the metrics out of the result (a pool worker's result
    travels back pickled; the sweep reads the metrics from the part files). The garbage
    collector waits for the end of the batch (:func:`_settle_heap`): its collections while the
    batch built its configs showed in a sweep's profile under ``perf``."""
    _set_threads()
    collecting = gc.isenabled()
    gc.disable()
    try:
        return _run_batch(batch, return_metrics)
    finally:
        _records().release()  # no run of this batch is read again: the next batch writes into its records
        _settle_heap()
        if collecting:
            gc.enable()


def _run_batch(batch: Batch, return_metrics: bool) -> BatchResult:
    from nlcx import engine, report

    rows: list[dict[str, Any]] = []
    prepared_of: dict[int, Any] = {}
    interpolated = cfg.Interpolated.of(batch.base_raw)
    base = cfg.build(interpolated.resolved)  # valid: sweep.load built it
    for pos, (variant, digest) in enumerate(zip(batch.variants, batch.hashes, strict=True)):
        start = time.perf_counter()
        row: dict[str, Any] = {"variant": variant.index, "seed": variant.seed, "config_hash": digest}
        row.update({f"value:{k}": _cell(v) for k, v in variant.values.items()})
        try:
            prepared_of[pos] = engine.prepare(cfg.build(variant.resolve(interpolated), like=base))
            row.update(status="ok", message="")
        except Exception as exc:  # a bad variant is recorded; the others go on
            row.update(status="failed", message=str(exc).splitlines()[0])
        row["wall_s"] = time.perf_counter() - start
        rows.append(row)
    # one pipeline call: variants on the same time grid go through the kernel together
    members = list(prepared_of)
    results = engine.evaluate([prepared_of[pos] for pos in members], record_logs=batch.timeseries, arena=_records())
    for pos, result in zip(members, results, strict=True):
        row = rows[pos]
        row["wall_s"] += result.timings["simulate"] + result.timings["metrics"]
        unstable = [run for run in result.runs if run.status != "ok"]
        if unstable:
            row.update(status="unstable", message=f"{unstable[0].label}: {unstable[0].reason}")
        if batch.timeseries:
            stem = batch.out_dir / "timeseries" / f"variant_{batch.variants[pos].index:06d}"
            fmt = result.prepared.experiment.section.outputs.timeseries_format
            report.write_timeseries(stem, report.timeseries_columns(result), fmt)
    metrics = engine.shared_metrics(results)
    index_of = np.array([batch.variants[pos].index for pos in members], dtype=int)
    metrics.insert(0, "variant", index_of[metrics.pop("experiment").to_numpy(dtype=int)])
    digest = hashlib.sha256("".join(batch.hashes).encode()).hexdigest()[:10]
    part = f"{batch.variants[0].index:06d}-{digest}"
    # an empty text (a metric's note when it has none) as a missing value, which is how
    # assemble reads it back: the file's rows are then metrics.csv's rows, byte for byte, and
    # assemble can join the files of a sweep computed in one go (_joined_metrics)
    report.write_csv(batch.out_dir / "parts" / f"{part}.metrics.csv", metrics, empty_as_missing=True)
    report.write_csv(batch.out_dir / "parts" / f"{part}.index.csv", pd.DataFrame(rows))  # last: marks it complete
    return BatchResult(index=rows, metrics=metrics if return_metrics else None, part=part)


def load(
    path: str | Path | Mapping[str, Any], overrides: list[str] | None = None
) -> tuple[dict[str, Any], SweepSection, Any]:
    """(base raw config without ``sweep``, the sweep spec, the validated base experiment) of a
    config file, or of a raw config mapping as a file holds it (:func:`nlcx.sweep`)."""
    raw_config = copy.deepcopy(dict(path)) if isinstance(path, Mapping) else cfg.read_config(path)
    raw = cfg.apply_overrides(raw_config, overrides or [])
    sweep_raw = raw.pop("sweep", None)
    if sweep_raw is None:
        raise ConfigError("sweep", None, "this config has no sweep section (use `nlcx run` for a single experiment)")
    spec = validate_model(SweepSection, sweep_raw, "sweep")
    base = cfg.build(cfg.interpolate(raw))
    return raw, spec, base


def plan(base_raw: dict[str, Any], spec: SweepSection) -> tuple[list[Variant], list[str]]:
    """The variants and the hash of each one's resolved config."""
    variants = expand(spec, cfg.interpolate(base_raw))
    base_digest = config_hash(base_raw)
    return variants, [variant_hash(base_digest, v) for v in variants]


def completed(out_dir: Path) -> set[str]:
    """Config hashes of every variant with a complete result (status ok or unstable)."""
    done: set[str] = set()
    for path in sorted((out_dir / "parts").glob("*.index.csv")):
        index = pd.read_csv(path, dtype={"config_hash": str})
        done.update(index.config_hash[index.status.isin(["ok", "unstable"])])
    return done


def make_executor(kind: str, jobs: int, scheduler: str | None) -> tuple[Executor | None, Callable[[], None]]:
    """(executor, close) for "serial", "process" or "dask"."""
    for name in THREAD_VARIABLES:  # one BLAS/OpenMP thread per worker
        os.environ.setdefault(name, "1")
    if kind == "serial":
        return None, lambda: None
    if kind == "process":
        pool = ProcessPoolExecutor(max_workers=jobs, initializer=_set_threads)
        return pool, lambda: pool.shutdown(wait=True, cancel_futures=True)
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise NlcxError("--executor dask needs the optional extra: pip install 'nlcx[dask]'") from None
    if scheduler:
        client = Client(scheduler)
        return client.get_executor(), client.close
    cluster = LocalCluster(
        n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None, host="127.0.0.1"
    )
    client = Client(cluster)

    def close() -> None:
        client.close()
        cluster.close()

    return client.get_executor(), close


@dataclass
class SweepOutcome:
    out_dir: Path
    index: pd.DataFrame
    computed: int
    skipped: int
    wall: float
    #: The sweep's report.html, when one was written.
    report: Path | None = None


def _carry_parts(finished: Path, staging: Path, want: Mapping[str, int]) -> None:
    """Link into ``staging`` the part files of the finished sweep ``finished`` that hold a
    variant of this plan (``want``: config hash -> variant index) and are not there yet, each
    part's metrics before its index (which marks it complete); and the time series of those
    variants whose index in this plan is the one they were written under."""
    from nlcx import rundir

    series: dict[str, list[Path]] = {}
    if (finished / "timeseries").is_dir():
        for path in (finished / "timeseries").iterdir():
            series.setdefault(path.name.partition(".")[0], []).append(path)
    for path in sorted((finished / "parts").glob("*.index.csv")):
        part = path.name.removesuffix(".index.csv")
        if (staging / "parts" / path.name).exists():
            continue
        index = pd.read_csv(path, dtype={"config_hash": str})
        planned = index.config_hash.map(want)
        if planned.isna().all():
            continue
        rundir.link_or_copy(finished / "parts" / f"{part}.metrics.csv", staging / "parts" / f"{part}.metrics.csv")
        rundir.link_or_copy(path, staging / "parts" / path.name)
        for variant in index.variant[planned.to_numpy() == index.variant.to_numpy()]:
            for source in series.get(f"variant_{int(variant):06d}", []):
                if not (staging / "timeseries" / source.name).exists():
                    rundir.link_or_copy(source, staging / "timeseries" / source.name)


def _staging(out_dir: Path, variants: list[Variant], hashes: list[str], force: bool) -> Path:
    """The staging directory of a sweep into ``out_dir`` (:func:`nlcx.rundir.open_partial`) with
    the finished batches it resumes from: an interrupted run's, already there, and the finished
    sweep's in ``out_dir`` of this plan's variants (:func:`_carry_parts`); ``force``: none."""
    from nlcx import rundir

    staging = rundir.open_partial(out_dir, keep=("parts", "timeseries"), fresh=force)
    if not force and (out_dir / "parts").is_dir():
        _carry_parts(out_dir, staging, {h: v.index for v, h in zip(variants, hashes, strict=True)})
    return staging


def _run_batches(
    batches: list[Batch],
    executor: str,
    jobs: int,
    scheduler: str | None,
    on_batch: Callable[[BatchResult], None],
) -> None:
    """Simulate ``batches`` on ``executor`` (:func:`make_executor`), handing each result to
    ``on_batch`` as it completes. The kernel must be loaded already (:func:`nlcx.engine.load_kernel`):
    the process pool's workers fork from this process and inherit it."""
    frozen = bool(batches) and executor == "process"
    if frozen:
        # the workers fork with this heap frozen: their first collection (_settle_heap) then
        # skips what they inherit (imports, the kernel) in each worker's first batch;
        # a list splice, nothing collected, free here (docs/performance.md)
        gc.freeze()
    pool, close = make_executor(executor, jobs, scheduler) if batches else (None, lambda: None)
    try:
        results: Iterable[BatchResult]
        if pool is None:
            results = (run_batch(b) for b in batches)
        else:
            futures: list[Future[BatchResult]] = [pool.submit(run_batch, b, False) for b in batches]
            results = (f.result() for f in as_completed(futures))
        for result in results:
            on_batch(result)
    finally:
        close()
        if frozen:
            gc.unfreeze()
        _records.cache_clear()  # the records of batches run in this process (serial executor)


def run(
    path: str | Path | Mapping[str, Any],
    overrides: list[str] | None = None,
    out_dir: Path | None = None,
    executor: str = "process",
    jobs: int = 2,
    scheduler: str | None = None,
    force: bool = False,
    progress: Callable[[int, int, int], None] | None = None,
    with_report: bool = True,
) -> SweepOutcome:
    """Run (or resume) a sweep; write sweep.csv, metrics.csv, config.yaml, manifest.json and,
    ``with_report``, the report, and rename the whole directory into place (module docstring).
    ``out_dir`` is claimed (:func:`nlcx.rundir.claim`) before any variant is computed."""
    from nlcx import engine, rundir

    start = time.perf_counter()
    base_raw, spec, base = load(path, overrides)
    out_dir = Path(out_dir or base.section.outputs.dir or Path("results") / base.name)
    variants, hashes = plan(base_raw, spec)
    workers = 1 if executor == "serial" else jobs
    engine.check_sweep_memory(base, min(spec.batch_size, len(variants)) * workers)
    with rundir.claim(out_dir):
        staging = _staging(out_dir, variants, hashes, force)
        done = completed(staging)
        todo = [i for i, h in enumerate(hashes) if h not in done]
        batches = [
            Batch(base_raw, [variants[i] for i in todo[k : k + spec.batch_size]],
                  [hashes[i] for i in todo[k : k + spec.batch_size]], staging, spec.timeseries)
            for k in range(0, len(todo), spec.batch_size)
        ]  # fmt: skip
        finished, failures = len(variants) - len(todo), 0
        written: set[str] = set()  # the part files of this run's batches

        def on_batch(result: BatchResult) -> None:
            nonlocal finished, failures
            written.add(result.part)
            finished += len(result.index)
            failures += sum(r["status"] == "failed" for r in result.index)
            if progress is not None:
                progress(finished, len(variants), failures)

        if progress is not None:
            progress(finished, len(variants), failures)
        if batches:
            engine.load_kernel()  # here, once, before the workers fork (_run_batches)
        planned = time.perf_counter()
        _run_batches(batches, executor, jobs, scheduler, on_batch)
        simulated = time.perf_counter()
        index = assemble(staging, variants, hashes, base_raw, spec, written)
        end = time.perf_counter()
        timings = {"plan": planned - start, "batches": simulated - planned, "assemble": end - simulated}
        timings["wall"] = end - start
        _write_manifest(
            staging, index, spec, timings, name=base.name, variants=len(variants), computed=len(todo),
            executor=executor, jobs=jobs, overrides=overrides or [], started=start,
        )  # fmt: skip
        page = _write_report(staging) if with_report and not index.empty else None
        rundir.install(staging, out_dir)
    report = out_dir / page.name if page is not None else None
    return SweepOutcome(out_dir, index, len(todo), len(variants) - len(todo), end - start, report)


def _write_report(directory: Path) -> Path:
    """``directory``'s report.html and report.md (:func:`nlcx.pages.render.write_report`); the page."""
    from nlcx.pages.render import write_report

    return write_report(directory)[0]


def _write_manifest(
    out_dir: Path,
    index: pd.DataFrame,
    spec: SweepSection,
    timings: dict[str, float],
    *,
    name: str,
    variants: int,
    computed: int,
    executor: str,
    jobs: int,
    overrides: Sequence[str] = (),
    started: float | None = None,
) -> None:
    """manifest.json: the run (name, kind ``nlcx_output``: sweep, command line, ``overrides``,
    start and duration from ``started``, variants computed and skipped, statuses, seed,
    executor), the wall time of each phase (reading, planning and loading the kernel; the
    batches; assembling sweep.csv and metrics.csv), the host, the platform, the package
    versions and the git commit (:func:`nlcx.report.provenance`, :func:`nlcx.report.environment`)."""
    from nlcx import report

    info = {
        "name": name,
        "nlcx_output": "sweep",
        **report.provenance(overrides, started),
        "variants": variants,
        "computed": computed,
        "skipped": variants - computed,
        "status": index.status.value_counts().to_dict(),
        "seed": spec.seed,
        "executor": executor,
        "jobs": jobs,
        "wall_s": round(timings["wall"], 3),
        "timings_s": {phase: round(seconds, 3) for phase, seconds in timings.items()},
        **report.environment(),
    }
    report.write_text(out_dir / "manifest.json", json.dumps(info, indent=2, default=str) + "\n")


def _in_plan_order(rows: pd.DataFrame, want: dict[str, int]) -> bool:
    """Whether the part files' rows (concatenated in file order) are each a variant of the plan
    once, under its own index, in ascending order: then metrics.csv is the parts' rows as they
    stand (no retry to supersede, nothing to renumber or reorder)."""
    plan_index = rows.config_hash.map(want)
    return bool(
        plan_index.notna().all()
        and (plan_index.to_numpy() == rows.variant.to_numpy()).all()
        and (np.diff(rows.variant.to_numpy()) > 0).all()
    )


def _joined_metrics(parts_dir: Path, parts: list[str]) -> bytes | None:
    """metrics.csv as the parts' metrics files joined: one header, then each file's rows.

    Only for parts in plan order (:func:`_in_plan_order`) written by this run, whose rows are
    metrics.csv's rows (:func:`run_batch` writes an empty text as a missing value); None when
    the files' headers differ or no file has a row (then the merge decides the columns)."""
    texts = [(parts_dir / f"{part}.metrics.csv").read_bytes() for part in parts]
    header = texts[0].partition(b"\n")[0] + b"\n"
    if not all(text.startswith(header) and text.endswith(b"\n") for text in texts):
        return None
    body = b"".join(text[len(header) :] for text in texts)
    return header + body if body else None


def _missing_as_null(frame: pd.DataFrame) -> pd.DataFrame:
    """Part tables concatenated, a missing text as a missing value again: a part whose column
    is all empty reads it as numbers (NaN), another as text, and their concatenation holds
    both, which :func:`nlcx.report.write_csv` would write as the text "nan" (a note or
    message of a variant without one)."""
    mixed = [c for c in frame.columns if frame[c].dtype == object]
    return frame.assign(**{c: frame[c].where(frame[c].notna(), None) for c in mixed}) if mixed else frame


def _merged_metrics(parts_dir: Path, parts: list[str], chosen: pd.DataFrame) -> pd.DataFrame:
    """The metrics of the ``chosen`` part rows, read from the part files, renumbered to the
    plan's variant indices and in variant order (a retried variant's last result)."""
    metrics = _missing_as_null(
        pd.concat(
            [
                pd.read_csv(parts_dir / f"{part}.metrics.csv", keep_default_na=False, na_values=[""]).assign(
                    _part=part_no
                )
                for part_no, part in enumerate(parts)
            ],
            ignore_index=True,
        )
    )
    if metrics.empty:
        return metrics.drop(columns="_part")
    link = chosen[["_part", "variant", "new_variant"]]
    metrics = metrics.merge(link, on=["_part", "variant"], how="inner", sort=False)
    metrics = metrics.assign(variant=metrics.new_variant).drop(columns=["_part", "new_variant"])
    metrics = metrics.drop_duplicates(subset=["variant", "controller", "signal", "metric"], keep="last")
    return metrics.sort_values("variant", kind="stable").reset_index(drop=True)


def _member_of(hashes: pd.Series, wanted: Collection[str]) -> np.ndarray:
    """``hashes.isin(wanted)`` by set lookups: pandas' ``isin`` on Arrow-backed strings loops
    in Python, a noticeable part of assembling a large sweep."""
    return np.fromiter((h in wanted for h in hashes.to_numpy(dtype=object)), dtype=bool, count=len(hashes))


def assemble(
    out_dir: Path,
    variants: list[Variant],
    hashes: list[str],
    base_raw: dict[str, Any],
    spec: SweepSection,
    written: Collection[str] = (),
) -> pd.DataFrame:
    """sweep.csv and metrics.csv from the part files, in variant order (deterministic).

    ``written`` names the parts this process's run wrote (:func:`run`): when they are all
    the parts and hold exactly the plan's variants, in order, metrics.csv is their files
    joined (:func:`_joined_metrics`), the same bytes as reading, merging and writing them."""
    import yaml

    from nlcx import report

    want = {h: v.index for v, h in zip(variants, hashes, strict=True)}
    parts = [path.name.removesuffix(".index.csv") for path in sorted((out_dir / "parts").glob("*.index.csv"))]
    indexes = [
        pd.read_csv(out_dir / "parts" / f"{part}.index.csv", dtype={"config_hash": str}).assign(_part=part_no)
        for part_no, part in enumerate(parts)
    ]
    if not indexes:
        report.write_csv(out_dir / "sweep.csv", pd.DataFrame())
        report.write_csv(out_dir / "metrics.csv", pd.DataFrame())
        return pd.DataFrame()
    rows = _missing_as_null(pd.concat(indexes, ignore_index=True))
    in_plan_order = set(parts) <= set(written) and _in_plan_order(rows, want)
    rows = rows[_member_of(rows.config_hash, want)]
    # per variant: its first complete result, else its last failure (a retry supersedes a failure)
    complete = rows[rows.status != "failed"].drop_duplicates("config_hash", keep="first")
    failed = rows[(rows.status == "failed") & ~_member_of(rows.config_hash, set(complete.config_hash))]
    chosen = pd.concat([complete, failed.drop_duplicates("config_hash", keep="last")])
    chosen = chosen.assign(new_variant=chosen.config_hash.map(want))
    index = chosen.assign(variant=chosen.new_variant).drop(columns=["_part", "new_variant"])
    index = index.sort_values("variant", kind="stable").reset_index(drop=True)
    report.write_csv(out_dir / "sweep.csv", index)
    joined = _joined_metrics(out_dir / "parts", parts) if in_plan_order else None
    if joined is not None:
        report.write_bytes(out_dir / "metrics.csv", joined)
    else:
        report.write_csv(out_dir / "metrics.csv", _merged_metrics(out_dir / "parts", parts, chosen))
    resolved = {**cfg.interpolate(base_raw), "sweep": spec.model_dump()}
    report.write_text(out_dir / "config.yaml", yaml.safe_dump(resolved, sort_keys=False, allow_unicode=True))
    return index

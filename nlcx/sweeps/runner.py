"""Running a sweep: the executors (serial, process pool, Dask), the loop over the batches, and :func:`run`."""

from __future__ import annotations

import gc
import os
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from nlcx.errors import NlcxError
from nlcx.sweeps.assembly import assemble, write_manifest, write_report
from nlcx.sweeps.batches import THREAD_VARIABLES, Batch, BatchResult, run_batch, set_threads
from nlcx.sweeps.cluster import ClusterSpec
from nlcx.sweeps.cluster import make as make_cluster
from nlcx.sweeps.planning import SweepSection, Variant, load, plan
from nlcx.sweeps.resuming import completed, open_staging
from nlcx.sweeps.sizing import check as check_plan_size


def make_executor(
    kind: str, jobs: int, scheduler: str | None, cluster: ClusterSpec | None = None
) -> tuple[Executor | None, Callable[[], None]]:
    """(executor, close) for "serial", "process" or "dask" (on ``scheduler``'s cluster, on
    the cluster a cluster file describes (:mod:`nlcx.sweeps.cluster`), or on a local one)."""
    for name in THREAD_VARIABLES:  # one BLAS/OpenMP thread per worker
        os.environ.setdefault(name, "1")
    if kind == "serial":
        return None, lambda: None
    if kind == "process":
        pool = ProcessPoolExecutor(max_workers=jobs, initializer=set_threads)
        return pool, lambda: pool.shutdown(wait=True, cancel_futures=True)
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise NlcxError("--executor dask needs the optional extra: pip install 'nlcx[dask]'") from None
    if scheduler:
        client = Client(scheduler)
        return client.get_executor(), client.close
    if cluster is not None:
        workers = make_cluster(cluster)
    else:
        workers = LocalCluster(
            n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None, host="127.0.0.1"
        )
    client = Client(workers)

    def close() -> None:
        client.close()
        workers.close()

    return client.get_executor(), close


@dataclass
class SweepOutcome:
    """What :func:`run` returns: the run directory, sweep.csv's rows, how many variants were
    computed and how many were already done, and the wall time in seconds."""

    out_dir: Path
    index: pd.DataFrame
    computed: int
    skipped: int
    wall: float
    #: The sweep's report.html, when one was written.
    report: Path | None = None
    #: Seconds spent writing the report (0 without one).
    report_s: float = 0.0


def _run_batches(
    batches: list[Batch],
    executor: str,
    jobs: int,
    scheduler: str | None,
    on_batch: Callable[[BatchResult], None],
    cluster: ClusterSpec | None = None,
) -> None:
    """Simulate ``batches`` on ``executor`` (:func:`make_executor`), handing each result to
    ``on_batch`` as it completes. The kernel must be loaded already (:func:`nlcx.engine.load_kernel`):
    the process pool's workers fork from this process and inherit it."""
    # nothing of the caller's is frozen: whatever this sweep freezes is thawed at its end, so the
    # caller's collector is as it was (serial batches settle their heap here, too)
    thawed = gc.get_freeze_count() == 0
    if thawed and batches and executor == "process":
        # the workers fork with this heap frozen: their first collection (_settle_heap) then
        # skips what they inherit (imports, the kernel) in each worker's first batch;
        # a list splice, nothing collected, free here (docs/performance.md)
        gc.freeze()
    pool, close = make_executor(executor, jobs, scheduler, cluster) if batches else (None, lambda: None)
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
        if thawed:
            gc.unfreeze()


def _batches(
    base_raw: dict[str, Any], spec: SweepSection, variants: list[Variant], hashes: list[str], todo: list[int], out: Path
) -> list[Batch]:
    """The variants at the plan positions ``todo`` in batches of ``spec.batch_size``, their part files into ``out``."""
    size = spec.batch_size
    return [
        Batch(base_raw, [variants[i] for i in todo[k : k + size]], [hashes[i] for i in todo[k : k + size]], out,
              spec.timeseries, tuple(spec.metrics) if spec.metrics is not None else None)
        for k in range(0, len(todo), size)
    ]  # fmt: skip


@dataclass
class _Tally:
    """The variants finished (computed or already done) and failed so far, reported to ``progress``
    (finished, total, failed) after each batch; and the part files this run wrote."""

    total: int
    finished: int
    progress: Callable[[int, int, int], None] | None
    failures: int = 0
    written: set[str] = field(default_factory=set)

    def report(self) -> None:
        if self.progress is not None:
            self.progress(self.finished, self.total, self.failures)

    def add(self, result: BatchResult) -> None:
        """Count a finished batch, then report."""
        self.written.add(result.part)
        self.finished += len(result.index)
        self.failures += sum(r["status"] == "failed" for r in result.index)
        self.report()


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
    cluster: ClusterSpec | None = None,
) -> SweepOutcome:
    """Run (or resume) a sweep; write sweep.csv, metrics.csv, config.yaml, manifest.json and,
    ``with_report``, the report, and rename the whole directory into place (:mod:`nlcx.sweeps`).
    ``out_dir`` is claimed (:func:`nlcx.rundir.claim`) before any variant is computed;
    ``progress(finished, total, failed)`` is called before the first batch and after each;
    ``cluster`` (with ``executor="dask"``): where the workers run (:mod:`nlcx.sweeps.cluster`)."""
    from nlcx import engine, rundir

    start = time.perf_counter()
    base_raw, spec, base = load(path, overrides)
    out_dir = Path(out_dir or base.section.outputs.dir or Path("results") / base.name)
    check_plan_size(spec, base, out_dir)  # before anything is expanded
    variants, hashes = plan(base_raw, spec)
    workers = 1 if executor == "serial" else jobs
    engine.check_sweep_memory(base, min(spec.batch_size, len(variants)) * workers)
    with rundir.claim(out_dir):
        staging = open_staging(out_dir, variants, hashes, force)
        done = completed(staging)
        todo = [i for i, h in enumerate(hashes) if h not in done]
        batches = _batches(base_raw, spec, variants, hashes, todo, staging)
        tally = _Tally(len(variants), len(variants) - len(todo), progress)
        tally.report()
        if batches:
            engine.load_kernel()  # here, once, before the workers fork (_run_batches)
        planned = time.perf_counter()
        _run_batches(batches, executor, jobs, scheduler, tally.add, cluster)
        simulated = time.perf_counter()
        index = assemble(staging, variants, hashes, base_raw, spec, tally.written)
        end = time.perf_counter()
        timings = {"plan": planned - start, "batches": simulated - planned, "assemble": end - simulated}
        timings["wall"] = end - start
        write_manifest(
            staging, index, spec, timings, name=base.name, variants=len(variants), computed=len(todo),
            executor=executor, jobs=jobs, overrides=overrides or [], started=start,
        )  # fmt: skip
        page = write_report(staging) if with_report and not index.empty else None
        reported = time.perf_counter()
        rundir.install(staging, out_dir)
    report = out_dir / page.name if page is not None else None
    skipped = len(variants) - len(todo)
    return SweepOutcome(out_dir, index, len(todo), skipped, end - start, report, reported - end if page else 0.0)

"""Running a sweep: the executors (serial, process pool, Dask), the loop over the batches, and :func:`run`."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import pandas as pd

import nlcx.sweeps.columnar as columnar
import nlcx.sweeps.seals as seals
from nlcx import runtime
from nlcx.errors import NlcxError
from nlcx.sweeps.assembly import assemble, assemble_columns, write_manifest
from nlcx.sweeps.batches import Batch, BatchResult, run_batch
from nlcx.sweeps.cluster import ClusterSpec
from nlcx.sweeps.cluster import make as make_cluster
from nlcx.sweeps.planning import (
    ColumnPlan,
    SweepSection,
    Variant,
    base_digest,
    expand_columns,
    load,
    numeric,
    plan,
)
from nlcx.sweeps.resuming import completed, open_column_staging, open_staging
from nlcx.sweeps.sizing import check as check_plan_size

if TYPE_CHECKING:
    from distributed import Client, Worker

    from nlcx.config import Experiment

#: A batch of either path: :class:`~nlcx.sweeps.batches.Batch` or :class:`~nlcx.sweeps.columnar.ColumnBatch`.
BatchT = TypeVar("BatchT")


def make_executor(
    kind: str, jobs: int, scheduler: str | None, cluster: ClusterSpec | None = None
) -> tuple[Executor | None, Callable[[], None]]:
    """(executor, close) for "serial", "process" or "dask" (on ``scheduler``'s cluster, on
    the cluster a cluster file describes (:mod:`nlcx.sweeps.cluster`), or on a local one); and
    for "gpu", two threads of this process: one batch runs on the GPU while the one before it is
    laid out and written (:func:`nlcx.engine.gpu.simulate_measure` lets one call at a time on the GPU).

    Every worker process enters :func:`nlcx.runtime.worker` (one BLAS, OpenMP and numba thread,
    among others); this process's environment is left as it is."""
    if kind == "serial":
        return None, lambda: None
    if kind == "gpu":
        threads = ThreadPoolExecutor(max_workers=2)
        return threads, lambda: threads.shutdown(wait=True, cancel_futures=True)
    if kind == "process":
        pool = ProcessPoolExecutor(max_workers=jobs, initializer=runtime.worker)
        return pool, lambda: pool.shutdown(wait=True, cancel_futures=True)
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise NlcxError("--executor dask needs the optional extra: pip install 'nlcx[dask]'") from None
    if scheduler:
        client = Client(scheduler)
        _enter_workers(client)
        return client.get_executor(), client.close
    if cluster is not None:
        workers = make_cluster(cluster)
    else:
        workers = LocalCluster(
            n_workers=jobs,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            host="127.0.0.1",
            env=runtime.thread_variables(),
        )
    client = Client(workers)
    _enter_workers(client)

    def close() -> None:
        client.close()
        workers.close()

    return client.get_executor(), close


def _enter_workers(client: Client) -> None:
    """Have every worker of ``client``'s cluster, present and to come, enter
    :func:`nlcx.runtime.worker` (a Dask worker plugin)."""
    from distributed import WorkerPlugin

    class EnterRuntime(WorkerPlugin):
        name = "nlcx-runtime"

        def setup(self, worker: Worker) -> None:
            runtime.worker()

    client.register_plugin(EnterRuntime())


@dataclass
class SweepOutcome:
    """What :func:`run` returns: the run directory, how many variants were computed and how many
    were already done, the count of each status, the wall time in seconds, and (read from the
    run directory when first asked for) the table sweep, one row a variant."""

    out_dir: Path
    computed: int
    skipped: int
    wall: float
    statuses: dict[str, int]
    #: The sweep's report.html, when one was written.
    report: Path | None = None
    #: Seconds spent writing the report (0 without one).
    report_s: float = 0.0
    #: How the variants were run: "columnar" or "per-variant" (and why, for the latter).
    path: str = ""
    _index: pd.DataFrame | None = field(default=None, repr=False)

    @property
    def index(self) -> pd.DataFrame:
        """The table sweep: one row a variant (index, seed, config hash, values, status, message)."""
        if self._index is None:
            from nlcx.results import read_output_table

            self._index = read_output_table(self.out_dir, "sweep")
        return self._index


def _run_batches(
    batches: Sequence[BatchT],
    executor: str,
    jobs: int,
    scheduler: str | None,
    on_batch: Callable[[BatchResult], None],
    task: Callable[[BatchT], BatchResult],
    cluster: ClusterSpec | None = None,
) -> None:
    """Run ``task`` on each of ``batches`` on ``executor`` (:func:`make_executor`), handing each
    result to ``on_batch`` as it completes (``task``: :func:`~nlcx.sweeps.batches.run_batch`,
    or :func:`~nlcx.sweeps.columnar.run_column_batch`). The kernel must be loaded already
    (:func:`nlcx.engine.load_kernel`): the process pool's workers fork from this process and
    inherit it. A command's workers fork with its heap frozen (:func:`nlcx.runtime.frozen_for_fork`):
    their first collection then skips what they inherit (imports, the kernel)."""
    with runtime.frozen_for_fork(bool(batches) and executor == "process"):
        pool, close = make_executor(executor, jobs, scheduler, cluster) if batches else (None, lambda: None)
        try:
            results: Iterable[BatchResult]
            if pool is None:
                results = (task(b) for b in batches)
            else:
                futures: list[Future[BatchResult]] = [pool.submit(task, b) for b in batches]
                results = (f.result() for f in as_completed(futures))
            for result in results:
                on_batch(result)
        finally:
            close()


def _batches(
    base_raw: dict[str, object],
    spec: SweepSection,
    variants: list[Variant],
    hashes: list[str],
    todo: list[int],
    out: Path,
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
    #: Each written part's statuses (status -> count).
    statuses: dict[str, dict[str, int]] = field(default_factory=dict)

    def report(self) -> None:
        if self.progress is not None:
            self.progress(self.finished, self.total, self.failures)

    def add(self, result: BatchResult) -> None:
        """Count a finished batch, then report."""
        self.written.add(result.part)
        self.statuses[result.part] = result.statuses
        self.finished += result.variants
        self.failures += result.statuses.get("failed", 0)
        self.report()


def run(
    path: str | Path | Mapping[str, object],
    overrides: list[str] | None = None,
    out_dir: Path | None = None,
    executor: str = "process",
    jobs: int = 2,
    scheduler: str | None = None,
    force: bool = False,
    progress: Callable[[int, int, int], None] | None = None,
    with_report: bool = True,
    cluster: ClusterSpec | None = None,
    allow_env: bool = False,
) -> SweepOutcome:
    """Run (or resume) a sweep; write the tables sweep and metrics (``sweep.format``),
    config.yaml, manifest.json and, ``with_report``, the report, and rename the whole directory
    into place (:mod:`nlcx.sweeps`). The variants run from columns where they can
    (:mod:`nlcx.sweeps.columnar`), else config by config.
    ``out_dir`` is claimed (:func:`nlcx.rundir.claim`) before any variant is computed;
    ``progress(finished, total, failed)`` is called before the first batch and after each;
    ``cluster`` (with ``executor="dask"``): where the workers run (:mod:`nlcx.sweeps.cluster`);
    ``allow_env``: the config may call every OmegaConf resolver (:func:`nlcx.config.interpolate`)."""
    from nlcx import config as cfg

    start = time.perf_counter()
    base_raw, spec, base = load(path, overrides, allow_env=allow_env)
    out_dir = Path(out_dir or base.section.outputs.dir or Path("results") / base.name)
    as_columns = spec.columnar and numeric(spec)
    check_plan_size(spec, base, out_dir, columnar=as_columns)  # before anything is expanded
    columns = expand_columns(spec, cfg.interpolate(base_raw, allow_env=True)) if as_columns else None  # checked by load
    found = columnar.packing(base_raw, spec, columns) if spec.columnar else "sweep.columnar is false"
    job = _Job(
        base_raw, spec, base, out_dir, executor, jobs, scheduler, force, progress, cluster, overrides or [], start
    )
    if isinstance(found, columnar.Packing) and columns is not None:
        return job.columnar(columns, found, with_report)
    return job.per_variant(with_report, f"per-variant: {found}")


@dataclass
class _Job:
    """A sweep's run, on one of its two paths (:meth:`columnar`, :meth:`per_variant`)."""

    base_raw: dict[str, object]
    spec: SweepSection
    base: Experiment
    out_dir: Path
    executor: str
    jobs: int
    scheduler: str | None
    force: bool
    progress: Callable[[int, int, int], None] | None
    cluster: ClusterSpec | None
    overrides: list[str]
    start: float

    @property
    def workers(self) -> int:
        return 1 if self.executor == "serial" else self.jobs

    def _run(
        self, batches: Sequence[BatchT], tally: _Tally, task: Callable[[BatchT], BatchResult], overlap: bool = False
    ) -> float:
        """Run the batches (the kernel loaded first, once, before the workers fork); the time they
        started. On the GPU, batches whose task lets one at a time on the device (``overlap``:
        :func:`~nlcx.sweeps.columnar.run_column_batch`) run two at once, the others one after another."""
        from nlcx import engine

        tally.report()
        if batches:
            engine.load_kernel()
        planned = time.perf_counter()
        executor = self.executor
        if self.base.section.simulation.device == "cuda":  # one process holds the GPU
            executor = "gpu" if overlap else "serial"
        _run_batches(batches, executor, self.jobs, self.scheduler, tally.add, task, self.cluster)
        return planned

    def _finish(self, staging: Path, statuses: dict[str, int], timings: dict[str, float], variants: int,
                computed: int, how: str, with_report: bool) -> SweepOutcome:  # fmt: skip
        """manifest.json, the report (its failure recorded, the results installed all the same),
        the directory renamed into place."""
        from nlcx import atomic_install, rundir

        end = time.perf_counter()
        timings["wall"] = end - self.start
        write_manifest(
            staging, statuses, self.spec, timings, name=self.base.name, variants=variants, computed=computed,
            executor=self.executor, jobs=self.jobs, overrides=self.overrides, started=self.start, path=how,
            allow_env=self.base.allow_env,
        )  # fmt: skip
        failure = rundir.write_pages(staging) if with_report and variants else None
        reported = time.perf_counter()
        atomic_install.install(staging, self.out_dir)
        if failure is not None:
            raise rundir.ReportError(self.out_dir, failure)
        report = self.out_dir / "report.html" if with_report and variants else None
        return SweepOutcome(self.out_dir, computed, variants - computed, end - self.start, statuses, report,
                            reported - end if report else 0.0, how)  # fmt: skip

    def columnar(self, plan: ColumnPlan, found: columnar.Packing, with_report: bool) -> SweepOutcome:
        """The variants packed from columns, in batches of :func:`~nlcx.sweeps.columnar.batch_size`."""
        from nlcx import engine, rundir

        device = self.base.section.simulation.device
        size = columnar.batch_size(self.spec, plan.n, found.record_bytes, device)
        if device == "cpu":  # on the GPU the records stay there, chunked to its memory
            engine.check_sweep_memory(self.base, min(size, plan.n) * self.workers)
        metrics = tuple(self.spec.metrics) if self.spec.metrics is not None else None
        with rundir.claim(self.out_dir):
            staging = open_column_staging(self.out_dir, self.force)
            batches = columnar.column_batches(
                self.base_raw, plan, found, base_digest(self.base_raw, self.spec), staging, size, metrics
            )
            finished = set(seals.sealed(staging))
            todo = [b for b in batches if b.part not in finished]
            tally = _Tally(plan.n, plan.n - sum(b.n for b in todo), self.progress)
            planned = self._run(todo, tally, columnar.run_column_batch, overlap=True)
            simulated = time.perf_counter()
            parts = [(b.first, b.part) for b in batches]
            statuses = assemble_columns(staging, parts, self.base_raw, self.spec, tally.statuses)
            timings = {"plan": planned - self.start, "batches": simulated - planned}
            timings["assemble"] = time.perf_counter() - simulated
            computed = sum(b.n for b in todo)
            return self._finish(staging, statuses, timings, plan.n, computed, "columnar", with_report)

    def per_variant(self, with_report: bool, how: str) -> SweepOutcome:
        """The variants one config each (:func:`~nlcx.sweeps.batches.run_batch`)."""
        from nlcx import engine, rundir

        check_plan_size(self.spec, self.base, self.out_dir)  # as variants, before they are expanded
        variants, hashes = plan(self.base_raw, self.spec)
        engine.check_sweep_memory(self.base, min(self.spec.batch_size, len(variants)) * self.workers)
        with rundir.claim(self.out_dir):
            staging = open_staging(self.out_dir, variants, hashes, self.force)
            done = completed(staging)
            todo = [i for i, h in enumerate(hashes) if h not in done]
            batches = _batches(self.base_raw, self.spec, variants, hashes, todo, staging)
            tally = _Tally(len(variants), len(variants) - len(todo), self.progress)
            task = run_batch if self.executor == "serial" else functools.partial(run_batch, return_metrics=False)
            planned = self._run(batches, tally, task)
            simulated = time.perf_counter()
            index = assemble(staging, variants, hashes, self.base_raw, self.spec, tally.written)
            statuses = {str(k): int(v) for k, v in index.status.value_counts().to_dict().items()} if len(index) else {}
            timings = {"plan": planned - self.start, "batches": simulated - planned}
            timings["assemble"] = time.perf_counter() - simulated
            outcome = self._finish(staging, statuses, timings, len(variants), len(todo), how, with_report)
            outcome._index = index
            return outcome

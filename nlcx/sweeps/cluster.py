"""Where a sweep's Dask workers come from: this machine, or a SLURM or PBS batch queue
through dask-jobqueue.

A cluster file (``nlcx sweep CONFIG --cluster FILE``) describes the machine, not the
experiment, so it lives apart from the experiment's config::

    kind: slurm            # local | slurm | pbs
    jobs: 4                # batch jobs to submit; each runs `cores` single-threaded workers
    cores: 16              # per job
    memory: 64GB           # per job
    walltime: "02:00:00"   # per job
    queue: compute         # partition (SLURM) or queue (PBS)
    account: myproject     # optional
    prologue:              # shell lines each job runs before its workers start
      - source ~/venvs/nlcx/bin/activate

Each worker is a process with one thread (the kernel is single-threaded and numba releases
nothing to share). The batches write their part files straight into the sweep's staging
directory, so on a cluster the output directory must be on a file system every node sees.
:func:`job_script` renders the script dask-jobqueue submits (``nlcx sweep --cluster FILE
--dry-run`` prints it).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Literal

from pydantic import BaseModel, ConfigDict, Field

from nlcx import safe_yaml
from nlcx.errors import NlcxError
from nlcx.validation import validate_model

if TYPE_CHECKING:
    from collections.abc import Callable

    from dask_jobqueue.core import JobQueueCluster
    from distributed.deploy.spec import SpecCluster


class ClusterSpec(BaseModel):
    """A cluster file: where the sweep's Dask workers run (see the module's docstring)."""

    model_config = ConfigDict(extra="forbid")
    #: local: a LocalCluster on this machine; slurm, pbs: batch jobs through dask-jobqueue.
    kind: Literal["local", "slurm", "pbs"]
    #: Batch jobs to submit (local: ignored beyond jobs × cores workers).
    jobs: int = Field(1, ge=1)
    #: Worker processes per job, one thread each.
    cores: int = Field(1, ge=1)
    #: Memory per job, e.g. 16GB.
    memory: str = "4GB"
    #: Wall-clock limit per job, HH:MM:SS.
    walltime: str = Field("01:00:00", pattern=r"^\d+:\d{2}:\d{2}$")
    #: SLURM partition or PBS queue.
    queue: str | None = None
    #: Account (project) to charge.
    account: str | None = None
    #: Shell lines each job runs before its workers start (modules, a virtual environment).
    prologue: list[str] = Field(default_factory=list)
    #: Further scheduler directives, verbatim (e.g. "--constraint=avx512").
    directives: list[str] = Field(default_factory=list)
    #: The network interface the workers and the scheduler talk on (e.g. ib0), if not the default.
    interface: str | None = None
    #: The Python the workers run (default: the one running nlcx; a path every node sees).
    python: str | None = None

    @property
    def workers(self) -> int:
        return self.jobs * self.cores


def load(path: Path) -> ClusterSpec:
    """The cluster file ``path``, validated (one-line errors naming the key)."""
    if not path.is_file():
        raise NlcxError(f"--cluster: no such file: {path}")
    return validate_model(ClusterSpec, safe_yaml.load_file(path) or {}, "cluster")


def _jobqueue_class(kind: str) -> Callable[..., JobQueueCluster]:
    try:
        import dask_jobqueue
    except ImportError:
        raise NlcxError(f"a {kind} cluster needs the optional extra: pip install 'nlcx[dask]'") from None
    return {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster}[kind]


def _jobqueue_cluster(spec: ClusterSpec) -> JobQueueCluster:
    """A dask-jobqueue cluster of ``spec`` (no job submitted yet)."""
    return _jobqueue_class(spec.kind)(
        queue=spec.queue,
        account=spec.account,
        cores=spec.cores,
        processes=spec.cores,
        memory=spec.memory,
        walltime=spec.walltime,
        job_script_prologue=spec.prologue,
        job_extra_directives=spec.directives,
        interface=spec.interface,
        scheduler_options={"dashboard_address": None},
        **({"python": spec.python} if spec.python else {}),
    )


def make(spec: ClusterSpec) -> SpecCluster:
    """The Dask cluster of ``spec``; a batch-queue cluster has its ``jobs`` submitted."""
    if spec.kind == "local":
        from distributed import LocalCluster

        return LocalCluster(n_workers=spec.workers, threads_per_worker=1, processes=True,
                            dashboard_address=None, host="127.0.0.1")  # fmt: skip
    cluster = _jobqueue_cluster(spec)
    cluster.scale(jobs=spec.jobs)
    return cluster


def job_script(spec: ClusterSpec) -> str:
    """The batch script one job of ``spec`` is submitted with (``local``: a comment)."""
    if spec.kind == "local":
        return f"# a LocalCluster of {spec.workers} single-threaded worker processes on this machine\n"
    cluster = _jobqueue_cluster(spec)
    try:
        return str(cluster.job_script())
    finally:
        cluster.close()

"""Can the thesis's printed columns hold together?

The identification fits one loop to several tables. This study asks of each printed column on
its own (one controller's cells of one table; a table that repeats another's cells, plant and
scenario prints the same column): does *any* loop of the families examined give it, and if
not, which printed numbers cannot hold together? Per column, a diagnostic (never a profile):

- **the most generous fit**: each hypothesis's free values refitted by the seeded GA on that
  column alone: its own parameters and, in a conventional column, the conventional gains its
  experiment reads (the literal loop's fit seeding the others); a proposed column keeps its
  printed AGS ranges and rates (a hypothesis with nothing free is one loop);
- **a cloud of random loops**: random hypotheses with random free values in a wide box,
  measured under each definition of t_r and t_s (:data:`nlcx.thesis.fitting.DEFINITIONS`).

A hypothesis is examined on a column when each of its options changes the column's experiment.
A loop *hits* a cell inside the interval its printed text covers (:func:`printed_interval`); a
column is reproduced when one loop hits all its cells. The sets of cells no loop hits together,
while every smaller set is hit (*minimal unreachable sets*), cannot hold together within the
families examined, which every output names.

Outputs (``nlcx identify configs/identify/consistency.yaml``): ``columns.csv``, ``cells.csv``,
``subsets.csv``, ``summary.json``, ``consistency.png``; every loop in ``fits/`` and ``loops/`` (resumable).

The spec and the printed columns are :mod:`nlcx.thesis.consistency.spec`'s; each column's
loops (fitted, drawn at random, stored) :mod:`nlcx.thesis.consistency.loops`'; what they say
:mod:`nlcx.thesis.consistency.analysis`'; the figure :mod:`nlcx.thesis.consistency.figure`'s.
Here: the study run as tasks in a process pool, resuming the finished ones (:func:`consistency`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import pandas as pd

from nlcx import runtime
from nlcx.thesis import hypotheses
from nlcx.thesis.consistency.analysis import analyse
from nlcx.thesis.consistency.loops import ColumnRuns, Store, fit_column, random_loops
from nlcx.thesis.consistency.spec import Column, ConsistencySpec, Family, digest, load_spec
from nlcx.thesis.fitting import study_digest, write_study
from nlcx.thesis.pages import tolerances

Task = tuple[str, str, str, str]  # (fit or cloud, table, controller, hypothesis; "" for a cloud)


def consistency(
    path: Path, out_dir: Path, jobs: int = 1, root: Path | None = None, progress: Callable[..., None] | None = None
) -> pd.DataFrame:
    """Run the study of spec ``path`` (resuming finished tasks) and write its analysis."""
    spec = load_spec(path)
    root = root or Path("configs") / "thesis"
    store = Store(out_dir, study_digest(digest(spec), root))
    family = spec.family()
    columns: list[Column] = [(t, c) for t in spec.tables for c in spec.controllers]
    families = {col: ColumnRuns(root, *col).examined(family) for col in columns}
    literal = family[0].name
    t0 = time.perf_counter()
    first: list[Task] = [("fit", *col, literal) for col in families if not store.has_fit(col, literal)]
    first += [("cloud", *col, "") for col in families if not all(store.has_cloud(col, d) for d in spec.definitions)]
    rest: list[Task] = [
        ("fit", *col, h.name) for col, hs in families.items() for h in hs[1:] if not store.has_fit(col, h.name)
    ]
    total, done = len(first) + len(rest), 0
    for phase in (first, rest):
        for task, result in _run(spec, root, store, phase, jobs, families):
            done += 1
            if task[0] == "fit":
                store.save_fit(*result)
            else:
                for definition, loops in result.items():
                    store.save_cloud(task[1:3], definition, loops)
            if progress is not None:
                progress(done, total, f"{task[1]} {task[2]} {task[3] or 'random loops'}")
    write_study(out_dir, total, done, jobs, time.perf_counter() - t0, path)
    return analyse(spec, store, families, tolerances.load(root / "tolerances.yaml"))


def _task(spec: ConsistencySpec, root: Path, task: Task, start: dict[str, float] | None, family: Family) -> Any:
    """One task in a worker: a column's cloud, or a hypothesis's fit."""
    kind, table, controller, name = task
    if kind == "cloud":
        return random_loops(spec, root, (table, controller), family)
    return fit_column(spec, root, (table, controller), next(h for h in family if h.name == name), start)


def _run(
    spec: ConsistencySpec, root: Path, store: Store, tasks: list[Task], jobs: int, families: dict[Column, Any]
) -> Iterator[tuple[Task, Any]]:
    """Each task's result as it finishes (fits other than the literal one start from the
    column's literal fit)."""

    def start(task: Task) -> dict[str, float] | None:
        literal = hypotheses.Hypothesis().name
        return None if task[0] == "cloud" or task[3] == literal else store.fit(task[1:3], literal)["values"]

    if jobs <= 1:
        for task in tasks:
            yield task, _task(spec, root, task, start(task), families[task[1:3]])
        return
    with ProcessPoolExecutor(max_workers=jobs, initializer=runtime.worker) as pool:
        futures = {pool.submit(_task, spec, root, t, start(t), families[t[1:3]]): t for t in tasks}
        for future in as_completed(futures):
            yield futures[future], future.result()

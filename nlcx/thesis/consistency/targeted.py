"""The targeted consistency search: can a set of printed cells be hit together after all?

The consistency study (:mod:`nlcx.thesis.consistency`) names minimal sets of printed cells that
none of its loops hits together. Its loops were fitted to whole columns or drawn at random, so a
set they miss may still be reachable. This search minimises each candidate set's own largest
relative miss directly, with CMA-ES (the ``cma`` package, seeded) inside each hypothesis's box:

- every searched loop is simulated once and measured under every definition of t_r and t_s of
  the consistency spec; the objective is the set's largest miss under the definition that
  gives the smallest, so the search looks for a hit under any definition;
- the hypotheses searched per set (:func:`candidates`): the spec's list (the literal loop, the
  identification's rank-1 combination, the step at 1 s with the derivative on the
  measurement, ...), the ``nearest`` hypotheses of the consistency study (those whose loops
  came nearest the set) alone and combined with the spec's ``combine_with``, and on a
  proposed column the AGS-structure options alone and combined;
- a hypothesis with one free parameter gets an even grid of the same budget instead (CMA-ES
  needs two dimensions);
- a hypothesis's search stops at its first loop that hits the set (every cell inside the
  interval its printed text covers) or after ``budget.loops`` loops; a set's search stops at
  its first hit.

A set is *reachable* when a loop hits it, *unreachable* when its smallest miss stays at or above
``margin`` × ``tolerance`` after every hypothesis's full budget, and *undecided* otherwise.
Outputs (``nlcx identify configs/identify/targeted.yaml``): ``sets/<set>.json`` and ``.loops.csv``
per set (resumable), ``targeted.csv``, one row per set.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nlcx import report, runtime, safe_yaml
from nlcx.errors import ConfigError
from nlcx.thesis import hypotheses
from nlcx.thesis.consistency.analysis import inside, relative_miss, twins
from nlcx.thesis.consistency.loops import ColumnRuns, Store, slug, used_box
from nlcx.thesis.consistency.spec import Column, ConsistencySpec, column_cells, digest, load_spec, with_intervals
from nlcx.thesis.fitting import study_digest, write_study
from nlcx.thesis.pages import tolerances
from nlcx.validation import validate_model

#: The option families that change only the proposed (AGS) controller's loop.
AGS_STRUCTURE = ("ordering", "integral", "ags_error", "ags_argument", "form", "units", "z_schedule")


class Budget(BaseModel):
    """CMA-ES per (set, hypothesis): at most ``per_parameter`` x (n + 1) loops for n free
    parameters, and never more than ``loops``; ``popsize`` a generation, a first step ``sigma``
    (a share of the box, which the search sees as [0, 1] per parameter)."""

    model_config = ConfigDict(extra="forbid")
    loops: int = Field(600, ge=1)
    per_parameter: int = Field(80, ge=1)
    popsize: int = Field(12, ge=4)
    sigma: float = Field(0.25, gt=0, le=1)
    seed: int = Field(1, ge=0)


class SetChoice(BaseModel):
    """Which of the consistency study's minimal unreachable sets are searched: ``first``, then
    those whose nearest miss is at least ``least_miss`` under every definition, the smallest
    miss first, ``cap`` sets in all."""

    model_config = ConfigDict(extra="forbid")
    least_miss: float = Field(0.2, ge=0)
    cap: int = Field(40, ge=1)
    #: Sets searched before the others, as "<table> <controller>: <cells>" (subsets.csv's labels).
    first: list[str] = Field(default_factory=list)


class TargetedSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    kind: Literal["targeted"]
    #: The consistency spec (relative to this file) whose box, cells and definitions are used.
    consistency: str
    #: Its results (relative to the working directory): subsets.csv and the loops.
    study: str
    sets: SetChoice = SetChoice()
    #: Hypotheses searched on every set (where each of their options changes its column).
    hypotheses: list[str] = Field(default_factory=lambda: ["literal"])
    #: The consistency study's hypotheses whose loops came nearest each set, searched too ...
    nearest: int = Field(3, ge=0)
    #: ... alone and combined with this hypothesis (its values replaced where both set a family).
    combine_with: str | None = None
    #: On a proposed column also these options (AGS structure), alone and combined.
    proposed: list[str] = Field(default_factory=list)
    budget: Budget = Budget()
    #: A set counts as unreachable only when its smallest miss is at least margin x tolerance.
    tolerance: float = Field(0.2, gt=0)
    margin: float = Field(1.5, ge=1)

    @field_validator("hypotheses", "proposed")
    @classmethod
    def _names(cls, names: list[str]) -> list[str]:
        for name in names:
            hypotheses.parse(name)
        return names

    @field_validator("combine_with")
    @classmethod
    def _name(cls, name: str | None) -> str | None:
        if name is not None:
            hypotheses.parse(name)
        return name


def load_targeted(path: Path) -> TargetedSpec:
    return validate_model(TargetedSpec, safe_yaml.load_file(path) or {}, "")


@dataclass(frozen=True)
class CellSet:
    """One set of printed cells of a column: its label (subsets.csv's), its groups of mirror twins
    (row positions of the column's cells), and the consistency study's nearest miss."""

    column: Column
    label: str
    groups: tuple[tuple[int, ...], ...]
    least_miss: float

    @property
    def key(self) -> str:
        return f"{self.column[0]} {self.column[1]}: {self.label}"


def chosen_sets(spec: TargetedSpec, cells_of: Callable[[Column], pd.DataFrame]) -> list[CellSet]:
    """The sets searched (:class:`SetChoice`), from the consistency study's subsets.csv. A set of
    ``first`` that is not among the study's minimal unreachable sets (some loop of the study
    hits it, or a smaller set is already unreachable) is searched all the same, its study miss
    NaN."""
    subsets = pd.read_csv(Path(spec.study) / "subsets.csv", dtype={"table": str})
    rows = [
        cell_set((str(r.table), str(r.controller)), str(r.cells), float(str(r.least_miss)), cells_of)
        for r in subsets.itertuples(index=False)
    ]
    by_key = {s.key: s for s in rows}
    first = [by_key.get(k) or named_set(k, cells_of) for k in spec.sets.first]
    rest = sorted((s for s in rows if s.least_miss >= spec.sets.least_miss and s.key not in spec.sets.first),
                  key=lambda s: (s.least_miss, s.key))  # fmt: skip
    return (first + rest)[: spec.sets.cap]


def cell_set(column: Column, label: str, least_miss: float, cells_of: Callable[[Column], pd.DataFrame]) -> CellSet:
    """The set of ``column``'s cells that ``label`` names ("x.Mp & theta.Mp = phi.Mp": mirror
    twins joined by " = ", as subsets.csv writes them)."""
    groups = twins(cells_of(column))
    by_label = {" = ".join(cells_of(column).cell.iloc[m] for m in g): tuple(g) for g in groups}
    parts = label.split(" & ")
    if any(part not in by_label for part in parts):
        allowed = ", ".join(by_label)
        raise ConfigError("sets.first", f"{column[0]} {column[1]}: {label}", f"cells of the column: {allowed}")
    return CellSet(column, label, tuple(by_label[part] for part in parts), least_miss)


def named_set(key: str, cells_of: Callable[[Column], pd.DataFrame]) -> CellSet:
    """A set written "<table> <controller>: <cells>" (:attr:`CellSet.key`)."""
    head, _, label = key.partition(": ")
    table, _, controller = head.partition(" ")
    if controller not in ("conventional", "proposed") or not label:
        raise ConfigError("sets.first", key, '"<table> <conventional|proposed>: <cell> & <cell> ..."')
    try:
        return cell_set((table, controller), label, math.nan, cells_of)
    except (KeyError, IndexError):
        raise ConfigError("sets.first", key, "a printed table of the thesis") from None


def candidates(
    spec: TargetedSpec, runs: ColumnRuns, nearest: list[hypotheses.Hypothesis]
) -> list[hypotheses.Hypothesis]:
    """The hypotheses searched on one set, in order, each once: the spec's, the ``nearest``,
    those combined with ``combine_with``, and on a proposed column the AGS-structure options,
    alone and combined; each without the options that leave the column's experiment as it is
    (a z loop's option on the x pendulum), so the rank-1 combination is searched where only
    part of it applies."""
    base = [hypotheses.parse(n) for n in spec.hypotheses] + nearest
    extra = [hypotheses.parse(n) for n in spec.proposed] if runs.controller == "proposed" else []
    combined = []
    if spec.combine_with is not None:
        anchor = hypotheses.parse(spec.combine_with)
        combined = [hypotheses.combine(anchor, h) for h in nearest + extra]
    everything = [*base, *extra, *combined]
    options = {o for h in everything for o in h.options}
    moving = {h.options[0] for h in runs.examined([hypotheses.Hypothesis((o,)) for o in options])}
    reduced = [hypotheses.Hypothesis(tuple(o for o in h.options if o in moving)) for h in everything]
    return list({h.name: h for h in reduced}.values())


def nearest_hypotheses(judged: list[tuple[np.ndarray, np.ndarray]], k: int) -> list[str]:
    """The ``k`` hypotheses whose loops came nearest a set under any definition (``judged``:
    per definition, each loop's hypothesis and its largest miss over the set)."""
    if k == 0:
        return []
    frames = [pd.DataFrame({"hypothesis": names, "miss": miss}) for names, miss in judged]
    best = pd.concat(frames).groupby("hypothesis", sort=False).miss.min()
    return list(best.sort_values(kind="stable").index[:k])


@dataclass(frozen=True)
class SetJudge:
    """Judges loops on one set: each definition's largest relative miss over the set's groups
    of twins (inf where a value is undefined) and whether every cell of the set is hit."""

    cells: pd.DataFrame
    members: list[int]
    groups: tuple[tuple[int, ...], ...]

    def judge(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(largest miss, hit) per loop of ``values`` (loops, the column's cells)."""
        miss = np.nan_to_num(relative_miss(self.cells, values), nan=np.inf)[:, self.members]
        return miss.max(axis=1), np.asarray(inside(self.cells, values)[:, self.members].all(axis=1))


def search_hypothesis(
    spec: TargetedSpec,
    consistency: ConsistencySpec,
    runs: ColumnRuns,
    judge: SetJudge,
    hyp: hypotheses.Hypothesis,
    gains: dict[str, tuple[float, float]],
    start: dict[str, float],
    seed: int,
) -> pd.DataFrame:
    """CMA-ES on one set under one hypothesis, over ``gains`` (the conventional PID's box) and
    the hypothesis's own parameters: every loop evaluated, with its largest miss and hit under
    each definition and the objective (the smallest of those misses)."""
    import cma

    box = gains | hyp.free()
    keys = list(box)
    lower, upper = (np.array([b[i] for b in box.values()]) for i in (0, 1))
    frames: list[pd.DataFrame] = []

    def evaluate(unit: np.ndarray) -> pd.DataFrame:
        values = [dict(zip(keys, map(float, lower + u * (upper - lower)), strict=True)) for u in unit]
        measured = runs.measure_each(hyp, values, consistency.definitions)
        rows: dict[str, object] = {"hypothesis": hyp.name, "values": [json.dumps(v) for v in values]}
        misses = []
        for k, ours in enumerate(measured.values()):
            miss, hit = judge.judge(ours)
            rows |= {f"miss_{k}": miss, f"hit_{k}": hit}
            misses.append(miss)
        frame = pd.DataFrame(rows)
        frame["objective"] = np.min(np.stack(misses), axis=0)
        frame["hit"] = frame[[f"hit_{k}" for k in range(len(measured))]].any(axis=1)
        frames.append(frame)
        return frame

    if not keys:
        evaluate(np.zeros((1, 0)))
        return pd.concat(frames, ignore_index=True)
    limit = min(spec.budget.loops, spec.budget.per_parameter * (len(keys) + 1))
    if len(keys) == 1:  # CMA-ES needs two dimensions: one parameter gets an even grid of the same budget
        grid = np.linspace(0.0, 1.0, limit)[:, None]
        for first in range(0, limit, spec.budget.popsize):
            if evaluate(grid[first : first + spec.budget.popsize]).hit.any():
                break
        return pd.concat(frames, ignore_index=True)
    x0 = np.clip([(start.get(k, (lo + hi) / 2) - lo) / (hi - lo) for k, (lo, hi) in box.items()], 0.0, 1.0)
    options = {"bounds": [0.0, 1.0], "popsize": spec.budget.popsize, "seed": seed, "verbose": -9,
               "maxfevals": limit, "tolfun": 0.0, "tolx": 1e-9}  # fmt: skip
    es = cma.CMAEvolutionStrategy(x0, spec.budget.sigma, options)
    used = 0
    while not es.stop() and used < limit:
        unit = np.array(es.ask())[: limit - used]
        frame = evaluate(unit)
        used += len(frame)
        if frame.hit.any() or len(unit) < spec.budget.popsize:
            break
        es.tell(list(unit), list(np.minimum(frame.objective.to_numpy(), 1e3)))
    return pd.concat(frames, ignore_index=True)


def search_set(
    spec: TargetedSpec,
    consistency: ConsistencySpec,
    root: Path,
    store: Store,
    chosen: CellSet,
    cells: pd.DataFrame,
    index: int,
) -> tuple[dict[str, object], pd.DataFrame]:
    """Every candidate hypothesis of one set in turn (stopping at the first hit), started from
    the consistency study's loops in ``store``, judged on the column's ``cells`` (with their
    intervals): (the set's summary, every loop evaluated)."""
    runs = ColumnRuns(root, *chosen.column)
    members = [m for g in chosen.groups for m in g]
    judge = SetJudge(cells, members, chosen.groups)
    gains = used_box(runs.runs, runs.table, consistency.free) if runs.controller == "conventional" else {}
    fitted = [h.name for h in consistency.family() if store.fit_path(chosen.column, h.name).is_file()]
    studied = {d: store.loops(chosen.column, d, fitted) for d in consistency.definitions}
    measured = [judge.judge(loops[list(cells.cell)].to_numpy(float)) for loops in studied.values()]
    judged = [(loops.hypothesis.to_numpy(), miss) for loops, (miss, _) in zip(studied.values(), measured, strict=True)]
    study = {"study_miss": min(float(miss.min()) for miss, _ in measured),
             "study_hit": any(bool(hit.any()) for _, hit in measured)}  # fmt: skip
    near = nearest_hypotheses(judged, spec.nearest)
    ours = next(iter(studied.values()))  # nlcx's definition: the cloud and every fitted loop
    literal_fit = store.fit(chosen.column, "literal")["values"] if chosen.column[1] == "conventional" else {}
    frames = []
    for k, hyp in enumerate(candidates(spec, runs, [hypotheses.parse(n) for n in near])):
        start = {**literal_fit, **hyp.neutral()}
        mine = np.flatnonzero(judged[0][0] == hyp.name)
        if mine.size:  # from the study's loop of this hypothesis nearest the set
            start |= json.loads(ours["values"].iloc[mine[np.argmin(judged[0][1][mine])]])
        seed = spec.budget.seed + 1000 * index + k
        frame = search_hypothesis(spec, consistency, runs, judge, hyp, gains, start, seed)
        frames.append(frame)
        if frame.hit.any():
            break
    loops = pd.concat(frames, ignore_index=True)
    return summarise(spec, chosen, loops, consistency.definitions) | study, loops


def summarise(spec: TargetedSpec, chosen: CellSet, loops: pd.DataFrame, definitions: list[str]) -> dict[str, object]:
    """A set's result: its smallest miss (and under which definition, which hypothesis, which
    values), the loops evaluated until then and in all, and the verdict."""
    best = int(np.argmin(loops.objective.to_numpy()))
    row = loops.iloc[best]
    by_definition = {d: float(loops[f"miss_{k}"].min()) for k, d in enumerate(definitions)}
    hit = bool(loops.hit.any())
    smallest = float(row.objective)
    verdict = "reachable" if hit else "unreachable" if smallest >= spec.margin * spec.tolerance else "undecided"
    return {
        "table": chosen.column[0], "controller": chosen.column[1], "cells": chosen.label,
        "consistency_miss": chosen.least_miss, "smallest_miss": smallest,
        "definition": definitions[int(np.argmin([row[f"miss_{k}"] for k in range(len(definitions))]))],
        "hypothesis": str(row.hypothesis), "values": str(row["values"]),
        "loops_to_best": best + 1, "loops": len(loops), "hypotheses": int(loops.hypothesis.nunique()),
        "searched": " | ".join(dict.fromkeys(loops.hypothesis)), "verdict": verdict,
        **{f"miss {d}": m for d, m in by_definition.items()},
    }  # fmt: skip


def set_digest(spec: TargetedSpec, consistency: ConsistencySpec) -> str:
    """What a finished set depends on: this spec (but the choice of sets) and the consistency spec."""
    text = json.dumps([spec.model_dump(exclude={"sets"}), consistency.model_dump()], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def targeted(
    path: Path, out_dir: Path, jobs: int = 1, root: Path | None = None, progress: Callable[..., None] | None = None
) -> pd.DataFrame:
    """Search every chosen set of spec ``path`` (resuming finished ones): targeted.csv."""
    spec = load_targeted(path)
    consistency = load_spec((path.parent / spec.consistency).resolve())
    root = root or Path("configs") / "thesis"
    rules = tolerances.load(root / "tolerances.yaml")
    cells: dict[Column, pd.DataFrame] = {}

    def cells_of(column: Column) -> pd.DataFrame:
        if column not in cells:
            cells[column] = with_intervals(column_cells(*column), rules, consistency.zero_decimals)
        return cells[column]

    chosen = chosen_sets(spec, cells_of)
    stamp = study_digest(set_digest(spec, consistency), root)
    store = Store(Path(spec.study), study_digest(digest(consistency), root))  # the consistency study's
    t0 = time.perf_counter()
    todo = [(k, s, cells_of(s.column)) for k, s in enumerate(chosen) if not _finished(out_dir, s, stamp)]
    for done, (chosen_set, summary, loops) in enumerate(_searches(spec, consistency, root, store, todo, jobs), 1):
        _save(out_dir, chosen_set, stamp, summary, loops)
        if progress is not None:
            progress(len(chosen) - len(todo) + done, len(chosen), f"{chosen_set.key}: {summary['verdict']}")
    write_study(out_dir, len(chosen), len(todo), jobs, time.perf_counter() - t0, path)
    rows = [json.loads(_path(out_dir, s).read_text())["summary"] for s in chosen]
    table = pd.DataFrame(rows)
    report.write_csv(out_dir / "targeted.csv", table)
    return table


def _path(out_dir: Path, chosen: CellSet) -> Path:
    return out_dir / "sets" / f"{slug(chosen.key)}.json"


def _finished(out_dir: Path, chosen: CellSet, stamp: str) -> bool:
    path = _path(out_dir, chosen)
    return path.is_file() and json.loads(path.read_text()).get("digest") == stamp


def _save(out_dir: Path, chosen: CellSet, stamp: str, summary: dict[str, object], loops: pd.DataFrame) -> None:
    """A finished set, atomically: its loops first, then the summary that marks it done."""
    path = _path(out_dir, chosen)
    report.write_csv(path.with_suffix(".loops.csv"), loops)
    report.write_text(path, json.dumps({"summary": summary, "digest": stamp}, indent=2) + "\n")


def _searches(
    spec: TargetedSpec,
    consistency: ConsistencySpec,
    root: Path,
    store: Store,
    todo: list[tuple[int, CellSet, pd.DataFrame]],
    jobs: int,
) -> Iterator[tuple[CellSet, dict[str, object], pd.DataFrame]]:
    """Each set's search as it finishes (a set's search depends only on the set and its
    index in the spec's choice, so the number of workers changes nothing)."""
    if jobs <= 1:
        for k, chosen, cells in todo:
            yield chosen, *search_set(spec, consistency, root, store, chosen, cells, k)
        return
    with ProcessPoolExecutor(max_workers=jobs, initializer=runtime.worker) as pool:
        futures = {pool.submit(search_set, spec, consistency, root, store, chosen, cells, k): chosen
                   for k, chosen, cells in todo}  # fmt: skip
        for future in as_completed(futures):
            yield futures[future], *future.result()

"""Can the thesis's printed conventional columns hold together?

The identification study fits one loop to several tables. This study asks a narrower
question of each printed conventional column on its own (a table whose conventional cells,
plant and scenario repeat another's is the same column: Table 2.5 repeats 2.3): does *any*
loop of the family give it, and if not, which printed numbers cannot hold together?

For each column, a diagnostic (never a profile, never a choice of the identification):

- **the most generous fit**: the conventional gains it uses, refitted by the seeded GA on that
  column alone, under every hypothesis of the families that change a conventional loop
  (derivative, actuator lag, reference prefilter, sampling, saturation; the others either touch
  only the AGS schedules or, with free gains, only re-parametrise them), the literal loop's fit
  seeding the others;
- **a cloud of random loops**: random hypotheses of the same family with random gains and
  parameters in a wide box, measured under each definition of t_r and t_s
  (:data:`nlcx.thesis.identify.DEFINITIONS`).

Every loop evaluated, GA candidates included, is kept. A printed cell is *hit* by a loop when
|ours - printed| <= tolerance * max(|printed|, floor) (floors as the fits': 0.05 for M_p,
0.5 s for times). The column is reproduced when one loop hits all its cells; the sets of
cells that no loop hits together, while every smaller set is hit, are the printed numbers
that cannot hold together (*minimal unreachable sets*).

Outputs (``nlcx identify configs/identify/consistency.yaml``): ``columns.csv``, ``cells.csv``,
``subsets.csv``, ``consistency.png``; each task's loops in ``loops/`` (resumable).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import re
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from nlcx import engine, report
from nlcx.thesis import catalog, hypotheses
from nlcx.thesis.identify import DEFINITIONS, FLOORS, TableRuns, cell_values, measure_cells, train_loss, write_study
from nlcx.tuning.optimise import GASettings, check_search_box, evolve
from nlcx.validation import validate_model

#: The option families that change a conventional loop with free gains.
CONVENTIONAL_FAMILIES = ("derivative", "lag", "prefilter", "sampling", "saturation")
NLCX_DEFINITION = next(iter(DEFINITIONS))
Box = dict[str, tuple[float, float]]


class CloudSettings(BaseModel):
    """Random loops per column and definition: a random hypothesis of the family each, its
    gains uniform in ``box`` (default: the spec's ``free``), its own parameters in theirs."""

    model_config = ConfigDict(extra="forbid")
    n: int = Field(1500, ge=1)
    seed: int = Field(7, ge=0)
    box: Box | None = None


class ConsistencySpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    kind: Literal["consistency"]
    #: One table per conventional column (the others that print it are found and reported).
    tables: list[str] = Field(min_length=1)
    families: list[str] = Field(default_factory=lambda: list(CONVENTIONAL_FAMILIES))
    max_options: int = Field(2, ge=0, le=len(CONVENTIONAL_FAMILIES))
    #: The conventional gains (a column's fit frees those its experiment reads) and bounds.
    free: Box = Field(min_length=1)
    warm_start: GASettings = GASettings(pop_size=30, generations=10, seed=1)
    optimiser: GASettings = GASettings(pop_size=12, generations=8, seed=1)
    cloud: CloudSettings = CloudSettings()
    #: A cell is hit within tolerance * max(|printed|, floor).
    tolerance: float = Field(0.10, gt=0, lt=1)
    #: Definitions of t_r and t_s the clouds are measured under; the first is nlcx's, which
    #: the fits use.
    definitions: list[str] = Field(default_factory=lambda: list(DEFINITIONS))

    @field_validator("families")
    @classmethod
    def _known(cls, families: list[str]) -> list[str]:
        unknown = [f for f in families if f not in CONVENTIONAL_FAMILIES]
        if unknown:
            raise ValueError(f"unknown option families {unknown}; allowed: {', '.join(CONVENTIONAL_FAMILIES)}")
        return families

    @field_validator("free")
    @classmethod
    def _bounds(cls, free: Box) -> Box:
        return check_search_box(free, ("vars.conventional.",), "only the conventional gains (vars.conventional.*)")

    @field_validator("definitions")
    @classmethod
    def _definitions(cls, definitions: list[str]) -> list[str]:
        unknown = [d for d in definitions if d not in DEFINITIONS]
        if unknown:
            raise ValueError(f"unknown definitions {unknown}; allowed: {', '.join(DEFINITIONS)}")
        if not definitions or definitions[0] != NLCX_DEFINITION:
            raise ValueError(f"the first definition must be nlcx's ({NLCX_DEFINITION}): the fits are measured under it")
        return definitions

    @model_validator(mode="after")
    def _tables(self) -> ConsistencySpec:
        known = set(catalog.thesis_metrics().table)
        for table in self.tables:
            if table not in known:
                raise ValueError(f"table {table} is not a pendulum metrics table; allowed: {', '.join(sorted(known))}")
        return self


def column_cells(table: str) -> pd.DataFrame:
    """The printed conventional cells (M_p, t_r, t_s) of ``table``, with a ``cell`` label."""
    rows = catalog.thesis_metrics()
    rows = rows[(rows.table == table) & (rows.controller == "conventional") & rows.metric.isin(FLOORS)]
    rows = rows[["table", "signal", "controller", "metric", "value"]].reset_index(drop=True)
    return rows.assign(cell=rows.signal + "." + rows.metric)


def also_printed(table: str) -> list[str]:
    """The other tables that print the same conventional column (same plant and scenario)."""
    rows = catalog.thesis_metrics()
    rows = rows[(rows.controller == "conventional") & rows.metric.isin(FLOORS)]

    def column(t: str) -> tuple[Any, ...]:
        mine = rows[rows.table == t]
        cells = sorted(zip(mine.signal, mine.metric, mine.value, strict=True))
        return (mine.plant.iloc[0], mine.scenario.iloc[0], tuple(cells))

    return [t for t in dict.fromkeys(rows.table) if t != table and column(t) == column(table)]


def used_box(runs: TableRuns, table: str, free: Box) -> Box:
    """The keys of ``free`` the experiment of ``table`` reads (its controllers change with them)."""

    def controllers(key: str, end: int) -> Any:
        values = {k: b[0] for k, b in free.items()} | {key: free[key][end]}
        return runs.experiment(table, hypotheses.Hypothesis(), values).raw["controllers"]

    return {k: b for k, b in free.items() if controllers(k, 0) != controllers(k, 1)}


class ColumnRuns:
    """One column's experiment with only the conventional controller, measured on its cells."""

    def __init__(self, root: Path, table: str) -> None:
        self.table, self.cells = table, column_cells(table)
        self.runs = TableRuns(root, [table], controllers=("conventional",))

    def measure(self, hyp: hypotheses.Hypothesis, candidates: list[dict[str, float]]) -> np.ndarray:
        """The cells (columns) of every candidate (rows) under nlcx's definitions; NaN where a
        run failed."""
        return measure_cells(self.runs, hyp, candidates, self.cells).T

    def measure_each(
        self, hyp: hypotheses.Hypothesis, candidates: list[dict[str, float]], definitions: list[str]
    ) -> dict[str, np.ndarray]:
        """:meth:`measure` under each of ``definitions``, the runs simulated once."""
        exps = [self.runs.experiment(self.table, hyp, c) for c in candidates]
        results = engine.evaluate(exps, record_logs=False)
        return {
            d: cell_values(engine.remeasure(results, DEFINITIONS[d]), self.cells, len(candidates)).T
            for d in definitions
        }


def loops_frame(
    column: ColumnRuns, hyp: hypotheses.Hypothesis, candidates: list[dict[str, float]], ours: np.ndarray, source: str
) -> pd.DataFrame:
    """One row per evaluated loop: source, hypothesis, its values (JSON), loss, every cell."""
    frame = pd.DataFrame(ours, columns=list(column.cells.cell))
    loss = train_loss(ours.T, column.cells)
    head = {"source": source, "hypothesis": hyp.name, "values": [json.dumps(c) for c in candidates], "loss": loss}
    return pd.concat([pd.DataFrame(head), frame], axis=1)


def fit_column(
    spec: ConsistencySpec, root: Path, table: str, hyp: hypotheses.Hypothesis, start: dict[str, float] | None
) -> tuple[dict[str, Any], pd.DataFrame]:
    """The GA fit of ``hyp`` on one column (the literal loop with ``spec.warm_start``, every
    other hypothesis from ``start``): (summary, every loop the GA evaluated)."""
    column = ColumnRuns(root, table)
    box = used_box(column.runs, table, spec.free) | hyp.free()
    keys = list(box)
    seen: list[pd.DataFrame] = []

    def objective(X: np.ndarray) -> np.ndarray:
        candidates = [dict(zip(keys, map(float, x), strict=True)) for x in np.atleast_2d(X)]
        ours = column.measure(hyp, candidates)
        seen.append(loops_frame(column, hyp, candidates, ours, "fit"))
        return train_loss(ours.T, column.cells)

    lower, upper = (np.array([b[i] for b in box.values()]) for i in (0, 1))
    settings = spec.warm_start if start is None else spec.optimiser
    seed = None if start is None else np.array([[{**start, **hyp.neutral()}[k] for k in keys]])
    result = evolve(objective, lower, upper, settings, start=seed)
    values = dict(zip(keys, map(float, result.x), strict=True))
    summary = {"table": table, "hypothesis": hyp.name, "values": values, "loss": float(result.f)}
    return summary, pd.concat(seen, ignore_index=True)


def random_loops(spec: ConsistencySpec, root: Path, table: str) -> dict[str, pd.DataFrame]:
    """The cloud of one column: ``spec.cloud.n`` random loops of the family (one seed per
    column), each simulated once and measured under every definition of the spec."""
    column = ColumnRuns(root, table)
    family = hypotheses.family(spec.families, spec.max_options)
    box = used_box(column.runs, table, spec.cloud.box or spec.free)
    rng = np.random.default_rng([spec.cloud.seed, *map(int, table.split("."))])
    picks = rng.integers(len(family), size=spec.cloud.n)
    frames: dict[str, list[pd.DataFrame]] = {d: [] for d in spec.definitions}
    for index in np.unique(picks):
        hyp = family[index]
        full = box | hyp.free()
        lower, upper = ([b[i] for b in full.values()] for i in (0, 1))
        draws = rng.uniform(lower, upper, (int(np.sum(picks == index)), len(full)))
        candidates = [dict(zip(full, map(float, row), strict=True)) for row in draws]
        for definition, ours in column.measure_each(hyp, candidates, spec.definitions).items():
            frames[definition].append(loops_frame(column, hyp, candidates, ours, "random"))
    return {d: pd.concat(f, ignore_index=True) for d, f in frames.items()}


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")


class Store:
    """The study's finished tasks on disk: fits/<table>/<hypothesis>.json with the loops the
    fit evaluated, loops/<table>/<definition>.csv for the clouds (each written atomically)."""

    def __init__(self, out_dir: Path, digest: str) -> None:
        self.out_dir, self.digest = out_dir, digest

    def fit_path(self, table: str, hyp: str) -> Path:
        return self.out_dir / "fits" / slug(table) / f"{hyp}.json"

    def cloud_path(self, table: str, definition: str) -> Path:
        return self.out_dir / "loops" / slug(table) / f"random_{slug(definition)}.csv"

    def has_fit(self, table: str, hyp: str) -> bool:
        path = self.fit_path(table, hyp)
        return path.is_file() and json.loads(path.read_text()).get("spec_digest") == self.digest

    def has_cloud(self, table: str, definition: str) -> bool:
        stamp = self.cloud_path(table, definition).with_suffix(".digest")
        return stamp.is_file() and stamp.read_text() == self.digest

    def save_fit(self, summary: dict[str, Any], loops: pd.DataFrame) -> None:
        path = self.fit_path(summary["table"], summary["hypothesis"])
        report.write_csv(path.with_suffix(".loops.csv"), loops)
        report.write_text(path, json.dumps({**summary, "spec_digest": self.digest}, indent=2) + "\n")

    def save_cloud(self, table: str, definition: str, loops: pd.DataFrame) -> None:
        path = self.cloud_path(table, definition)
        report.write_csv(path, loops)
        report.write_text(path.with_suffix(".digest"), self.digest)

    def fit(self, table: str, hyp: str) -> dict[str, Any]:
        return json.loads(self.fit_path(table, hyp).read_text())

    def loops(self, table: str, definition: str, hyps: list[str]) -> pd.DataFrame:
        """Every loop of a column measured under ``definition``: its cloud, and under nlcx's
        definition also every GA candidate."""
        frames = [pd.read_csv(self.cloud_path(table, definition))]
        if definition == NLCX_DEFINITION:
            frames += [pd.read_csv(self.fit_path(table, h).with_suffix(".loops.csv")) for h in hyps]
        return pd.concat(frames, ignore_index=True)


def digest(spec: ConsistencySpec) -> str:
    """What a finished task depends on: the spec."""
    return hashlib.sha256(json.dumps(spec.model_dump(), sort_keys=True).encode()).hexdigest()[:16]


def load_spec(path: Path) -> ConsistencySpec:
    return validate_model(ConsistencySpec, yaml.safe_load(path.read_text(encoding="utf-8")) or {}, "")


def consistency(
    path: Path, out_dir: Path, jobs: int = 1, root: Path | None = None, progress: Callable[..., None] | None = None
) -> pd.DataFrame:
    """Run the study of spec ``path`` (resuming finished tasks) and write its analysis."""
    spec = load_spec(path)
    root = root or Path("configs") / "thesis"
    store = Store(out_dir, digest(spec))
    family = hypotheses.family(spec.families, spec.max_options)
    t0 = time.perf_counter()
    first = [("fit", t, family[0].name) for t in spec.tables if not store.has_fit(t, family[0].name)]
    first += [("cloud", t, "") for t in spec.tables if not all(store.has_cloud(t, d) for d in spec.definitions)]
    rest = [("fit", t, h.name) for t in spec.tables for h in family[1:] if not store.has_fit(t, h.name)]
    total, done = len(first) + len(rest), 0
    for phase in (first, rest):
        for task, result in _run(spec, root, store, phase, jobs):
            done += 1
            if task[0] == "fit":
                store.save_fit(*result)
            else:
                for definition, loops in result.items():
                    store.save_cloud(task[1], definition, loops)
            if progress is not None:
                progress(done, total, f"{task[1]} {task[2] or 'random loops'}")
    write_study(out_dir, total, done, jobs, time.perf_counter() - t0)
    return analyse(spec, store, [h.name for h in family])


def _task(spec: ConsistencySpec, root: Path, task: tuple[str, str, str], start: dict[str, float] | None) -> Any:
    """One task in a worker: a column's cloud, or a hypothesis's fit."""
    kind, table, name = task
    if kind == "cloud":
        return random_loops(spec, root, table)
    hyp = next(h for h in hypotheses.family(spec.families, spec.max_options) if h.name == name)
    return fit_column(spec, root, table, hyp, start)


def _run(
    spec: ConsistencySpec, root: Path, store: Store, tasks: list[tuple[str, str, str]], jobs: int
) -> Iterator[tuple[tuple[str, str, str], Any]]:
    """Each task's result as it finishes (fits other than the literal one start from the
    column's literal fit)."""

    def start(task: tuple[str, str, str]) -> dict[str, float] | None:
        literal = hypotheses.Hypothesis().name
        return None if task[0] == "cloud" or task[2] == literal else store.fit(task[1], literal)["values"]

    if jobs <= 1:
        for task in tasks:
            yield task, _task(spec, root, task, start(task))
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(_task, spec, root, t, start(t)): t for t in tasks}
        for future in as_completed(futures):
            yield futures[future], future.result()


def hits(loops: pd.DataFrame, cells: pd.DataFrame, tolerance: float) -> np.ndarray:
    """(loops, cells) booleans: the loop's value within tolerance of the printed cell."""
    printed = cells.value.to_numpy()
    scale = np.maximum(np.abs(printed), cells.metric.map(FLOORS).to_numpy())
    ours = loops[list(cells.cell)].to_numpy(dtype=float)
    with np.errstate(invalid="ignore"):
        return np.abs(ours - printed) <= tolerance * scale


#: The mirror signals of the symmetric pendulums: y mirrors x, phi mirrors theta.
MIRROR = {"y": "x", "phi": "theta"}


def twins(cells: pd.DataFrame) -> list[list[int]]:
    """Groups of cells (row positions) the thesis prints alike for mirror signals: y.Mp with
    x.Mp when both print the same value, and so on; every other cell alone."""
    groups: dict[tuple[str, str, float], list[int]] = {}
    row: Any  # a row of ``cells``: its signal, metric (str) and printed value (float)
    for i, row in enumerate(cells.itertuples(index=False)):
        groups.setdefault((MIRROR.get(row.signal, row.signal), row.metric, row.value), []).append(i)
    return list(groups.values())


def group_hits(hit: np.ndarray, miss: np.ndarray, groups: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Per group of twins: hit when every member is hit, missed by the largest member's miss."""
    merged_hit = np.stack([hit[:, g].all(axis=1) for g in groups], axis=1)
    merged_miss = np.stack([np.nan_to_num(miss[:, g], nan=np.inf).max(axis=1) for g in groups], axis=1)
    return merged_hit, merged_miss


def unreachable_sets(hit: np.ndarray, max_size: int) -> list[tuple[int, ...]]:
    """The minimal sets of cells (column indices of ``hit``, up to ``max_size``) that no loop
    hits together while every proper subset is hit by some loop."""
    n = hit.shape[1]
    masks = hit.astype(np.int64) @ (1 << np.arange(n, dtype=np.int64))
    reached = {0}
    minimal = []
    for size in range(1, max_size + 1):
        for subset in itertools.combinations(range(n), size):
            bits = sum(1 << i for i in subset)
            if np.any((masks & bits) == bits):
                reached.add(bits)
            elif all(bits & ~(1 << i) in reached for i in subset):
                minimal.append(subset)
    return minimal


@dataclass(frozen=True)
class Evidence:
    """A column's loops under one definition, judged on its cells with mirror twins merged:
    ``hit`` and ``miss`` (relative, inf where undefined) are (loops, groups of :func:`twins`)."""

    loops: pd.DataFrame
    hit: np.ndarray
    miss: np.ndarray


def evidence(cells: pd.DataFrame, groups: list[list[int]], loops: pd.DataFrame, tolerance: float) -> Evidence:
    scale = np.maximum(cells.value.abs().to_numpy(), cells.metric.map(FLOORS).to_numpy())
    miss = np.abs(loops[list(cells.cell)].to_numpy(float) - cells.value.to_numpy()) / scale
    return Evidence(loops, *group_hits(hits(loops, cells, tolerance), miss, groups))


def nearest_miss(ev: Evidence, subset: tuple[int, ...]) -> tuple[float, int]:
    """(largest relative miss over ``subset`` of the loop nearest to hitting it all, that loop)."""
    worst = ev.miss[:, list(subset)].max(axis=1)
    k = int(np.argmin(worst))
    return float(worst[k]), k


def analyse(spec: ConsistencySpec, store: Store, hyps: list[str]) -> pd.DataFrame:
    """columns.csv, cells.csv, subsets.csv and consistency.png from the stored loops."""
    columns, cell_rows, subset_rows, clouds = [], [], [], {}
    for table in spec.tables:
        cells = column_cells(table)
        groups = twins(cells)
        fits = pd.DataFrame([store.fit(table, h) for h in hyps]).sort_values("loss", kind="stable")
        judged = {d: evidence(cells, groups, store.loops(table, d, hyps), spec.tolerance) for d in spec.definitions}
        for definition, ev in judged.items():
            hit = hits(ev.loops, cells, spec.tolerance)
            columns.append(column_row(table, definition, cells, ev, hit, fits.iloc[0]))
            cell_rows += cell_table(table, definition, cells, ev.loops, hit)
        subset_rows += subset_table(table, cells, groups, judged)
        clouds[table] = judged[spec.definitions[0]].loops
    out = store.out_dir
    frame = pd.DataFrame(columns)
    report.write_csv(out / "columns.csv", frame)
    report.write_csv(out / "cells.csv", pd.DataFrame(cell_rows))
    report.write_csv(out / "subsets.csv", pd.DataFrame(subset_rows))
    figure(clouds, out / "consistency.png")
    return frame


def column_row(
    table: str, definition: str, cells: pd.DataFrame, ev: Evidence, hit: np.ndarray, best: pd.Series
) -> dict[str, Any]:
    """One column under one definition: the loops examined, the most cells one loop hits, the
    minimal unreachable sets, and (nlcx's definition) the best GA fit."""
    counts = hit.sum(axis=1)
    head = catalog.thesis_metrics().query("table == @table").iloc[0]
    values = ev.loops[list(cells.cell)].to_numpy(float)
    row = {
        "table": table,
        "also_printed_in": " ".join(also_printed(table)),
        "plant": head.plant,
        "scenario": head.scenario,
        "definition": definition,
        "cells": len(cells),
        "loops": len(ev.loops),
        "settled_share": float(np.mean(np.all(np.isfinite(values), axis=1))),
        "most_cells_hit": int(counts.max()),
        "loops_hitting_all": int(np.sum(counts == len(cells))),
        "reproduced": bool(np.any(counts == len(cells))),
        "unreachable_sets": len(unreachable_sets(ev.hit, 3)),
    }
    if definition == NLCX_DEFINITION:
        row |= {
            "best_fit": best.hypothesis,
            "best_fit_loss": float(best.loss),
            "best_fit_values": json.dumps(best["values"]),
        }
    return row


def cell_table(
    table: str, definition: str, cells: pd.DataFrame, loops: pd.DataFrame, hit: np.ndarray
) -> list[dict[str, Any]]:
    """Per cell: printed, the value of the loop nearest the whole column (least loss), the
    range the loops reach, and how many hit it."""
    nearest = loops.iloc[int(loops.loss.argmin())]
    rows = []
    cell: Any  # a row of ``cells``: its cell name (a column of ``loops``) and printed value
    for i, cell in enumerate(cells.itertuples(index=False)):
        values = loops[cell.cell].to_numpy(dtype=float)
        finite = values[np.isfinite(values)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (np.nan, np.nan)
        rows.append({
            "table": table, "definition": definition, "cell": cell.cell, "printed": cell.value,
            "nearest_loop": float(nearest[cell.cell]), "nearest_hypothesis": nearest.hypothesis,
            "min": lo, "max": hi, "loops_hitting": int(hit[:, i].sum()),
        })  # fmt: skip
    return rows


def subset_table(
    table: str, cells: pd.DataFrame, groups: list[list[int]], judged: dict[str, Evidence], max_size: int = 3
) -> list[dict[str, Any]]:
    """The minimal sets of printed cells (up to ``max_size``; mirror twins such as
    x.Mp = y.Mp count as one cell, hit when both are) that no loop examined under the first
    definition hits together, with the loop nearest to hitting each (the one whose largest
    relative miss over the set is smallest) and that nearest miss under every definition."""
    label = [" = ".join(cells.cell.iloc[m] for m in g) for g in groups]
    first, *_ = judged.values()
    rows = []
    for subset in unreachable_sets(first.hit, max_size):
        _, k = nearest_miss(first, subset)
        members = [m for i in subset for m in groups[i]]
        near = ", ".join(f"{cells.cell.iloc[m]} {first.loops[cells.cell.iloc[m]].iloc[k]:.3g}" for m in members)
        misses = {f"miss {d}": nearest_miss(ev, subset)[0] for d, ev in judged.items()}
        rows.append({
            "table": table, "cells": " & ".join(label[i] for i in subset),
            "printed": ", ".join(f"{cells.value.iloc[groups[i][0]]:g}" for i in subset), "size": len(subset),
            "loops": len(first.loops), "nearest": near, **misses, "least_miss": min(misses.values()),
        })  # fmt: skip
    return rows


def figure(clouds: dict[str, pd.DataFrame], path: Path) -> None:
    """Per column: x rise time against x overshoot of every loop examined, and the printed pair."""
    from nlcx.drawing import atomic_write, new_figure

    n = len(clouds)
    cols = min(4, n)
    n_rows = (n + cols - 1) // cols
    fig, axes = new_figure(n_rows, cols, (3.4 * cols, 3.0 * n_rows))
    for ax, (table, loops) in zip(axes.flat, clouds.items(), strict=False):
        cells = column_cells(table).set_index("cell").value
        for source, rows in loops.groupby("source"):
            ax.scatter(rows["x.tr"], rows["x.Mp"], s=2, alpha=0.3, label=f"{source} loops")
        ax.scatter([cells["x.tr"]], [cells["x.Mp"]], marker="*", s=160, color="red", label="printed")
        ax.set_xlim(0, max(5.0, 1.5 * cells["x.tr"]))
        ax.set_ylim(0, 1.2)
        ax.set_title(f"Table {table}, conventional", fontsize=9)
        ax.set_xlabel("x t_r (s)", fontsize=8)
        ax.set_ylabel("x M_p", fontsize=8)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    legend = axes.flat[0].legend(fontsize=7)
    for handle in legend.legend_handles:  # the same modest marker for the dots and the star
        handle.set_sizes([30.0])
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))

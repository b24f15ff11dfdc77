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
"""

from __future__ import annotations

import hashlib
import io
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
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from nlcx import config as cfg
from nlcx import engine, report, safe_yaml
from nlcx.pages import tolerances
from nlcx.thesis import catalog, hypotheses
from nlcx.thesis.fitting import DEFINITIONS, FLOORS, TableRuns, cell_values, measure_cells, train_loss, write_study
from nlcx.tuning.optimise import GASettings, check_search_box, evolve
from nlcx.validation import validate_model

#: The option families that change a conventional loop with free gains.
CONVENTIONAL_FAMILIES = ("derivative", "lag", "prefilter", "sampling", "saturation")
#: The families that change a column's reference, initial state, disturbance, integrators or
#: the measurement (either controller's).
SCENARIO_FAMILIES = ("theta_settling", "reference_amplitude", "step_time", "initial_angle", "z_loop",
                     "disturbance_phase", "disturbance_start", "disturbance_entry", "integrator_limit")  # fmt: skip
STUDY_FAMILIES = CONVENTIONAL_FAMILIES + SCENARIO_FAMILIES
NLCX_DEFINITION = next(iter(DEFINITIONS))
Box = dict[str, tuple[float, float]]
Column = tuple[str, str]  # (table, controller)
Family = list[hypotheses.Hypothesis]
Task = tuple[str, str, str, str]  # (fit or cloud, table, controller, hypothesis; "" for a cloud)


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
    #: One table per printed column (the others that print it are found and reported).
    tables: list[str] = Field(min_length=1)
    #: The columns of each table: conventional (gains free), proposed (printed AGS gains).
    controllers: list[Literal["conventional", "proposed"]] = Field(["conventional"], min_length=1)
    #: Families whose options are combined, up to ``max_options`` of them.
    families: list[str] = Field(default_factory=lambda: list(CONVENTIONAL_FAMILIES))
    max_options: int = Field(2, ge=0, le=len(STUDY_FAMILIES))
    #: Families whose options are examined one at a time, never combined.
    alone: list[str] = Field(default_factory=list)
    #: The conventional gains (a column's fit frees those its experiment reads) and bounds.
    free: Box = Field(min_length=1)
    warm_start: GASettings = GASettings(pop_size=30, generations=10, seed=1)
    optimiser: GASettings = GASettings(pop_size=12, generations=8, seed=1)
    cloud: CloudSettings = CloudSettings()
    #: The decimals a printed "0" is read with (None: none, as any integer).
    zero_decimals: int | None = Field(None, ge=0)
    #: Definitions of t_r and t_s the clouds are measured under; the first is nlcx's, which
    #: the fits use.
    definitions: list[str] = Field(default_factory=lambda: list(DEFINITIONS))

    @field_validator("families", "alone")
    @classmethod
    def _known(cls, families: list[str]) -> list[str]:
        unknown = [f for f in families if f not in STUDY_FAMILIES or f not in hypotheses.FAMILIES]
        if unknown:
            raise ValueError(f"unknown option families {unknown}; allowed: {', '.join(STUDY_FAMILIES)}")
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
        if both := sorted(set(self.families) & set(self.alone)):
            raise ValueError(f"families {both} are in both families and alone; name each once")
        return self

    def family(self) -> Family:
        """The literal loop, every combination of up to ``max_options`` options of ``families``,
        and each option of ``alone`` by itself."""
        return hypotheses.family(self.families, self.max_options) + hypotheses.family(self.alone, 1)[1:]


def column_cells(table: str, controller: str = "conventional") -> pd.DataFrame:
    """The printed cells (M_p, t_r, t_s) of one controller's column of ``table``, with a
    ``cell`` label and the ``text`` printed (as transcribed: its decimals are the print's)."""
    text = (catalog.DATA / "pendulum_metrics.csv").read_text(encoding="utf-8")
    rows = catalog.thesis_metrics().assign(text=pd.read_csv(io.StringIO(text), dtype=str).value)
    rows = rows[(rows.table == table) & (rows.controller == controller) & rows.metric.isin(FLOORS)]
    rows = rows[["table", "signal", "controller", "metric", "value", "text"]].reset_index(drop=True)
    return rows.assign(cell=rows.signal + "." + rows.metric)


def printed_interval(text: str, rel: float, zero_decimals: int | None = None) -> tuple[float, float]:
    """The values a printed cell covers: v printed with d decimals stands for [v - 0.5 10^-d,
    v + 0.5 10^-d] (5.79: [5.785, 5.795]; 12: [11.5, 12.5]), widened on each side by ``rel`` |v|,
    the metric's relative tolerance. A bare "0" is read with ``zero_decimals`` decimals when
    given (the thesis prints a zero as "0" in columns it prints to 2 decimals)."""
    value, decimals = float(text), len(text.partition(".")[2])
    if value == 0 and decimals == 0 and zero_decimals is not None:
        decimals = zero_decimals
    half = 0.5 * 10.0**-decimals + rel * abs(value)
    return value - half, value + half


def with_intervals(cells: pd.DataFrame, rules: tolerances.Tolerances, zero_decimals: int | None) -> pd.DataFrame:
    """``cells`` with the interval each printed text covers (``lower``, ``upper``;
    :func:`printed_interval`), widened by the relative tolerance of its metric in
    tolerances.yaml (``cells.by_metric``, a measured response's; its absolute tolerance is the
    print's resolution, which the rounding already gives)."""
    rel = [rules.for_metric(metric).rel for metric in cells.metric]
    bounds = [printed_interval(text, r, zero_decimals) for text, r in zip(cells.text, rel, strict=True)]
    return cells.assign(lower=[b[0] for b in bounds], upper=[b[1] for b in bounds])


def also_printed(table: str, controller: str = "conventional") -> list[str]:
    """The other tables that print the same column (same plant, scenario and cells; for the
    proposed controller also the same AGS)."""
    rows = catalog.thesis_metrics()
    rows = rows[(rows.controller == controller) & rows.metric.isin(FLOORS)]

    def column(t: str) -> tuple[Any, ...]:
        mine = rows[rows.table == t]
        cells = sorted(zip(mine.signal, mine.metric, mine.value, strict=True))
        ags = mine.ags.iloc[0] if controller == "proposed" else ""
        return (mine.plant.iloc[0], mine.scenario.iloc[0], ags, tuple(cells))

    return [t for t in dict.fromkeys(rows.table) if t != table and column(t) == column(table)]


def used_box(runs: TableRuns, table: str, free: Box) -> Box:
    """The keys of ``free`` the experiment of ``table`` reads (its controllers change with them)."""

    def controllers(key: str, end: int) -> Any:
        values = {k: b[0] for k, b in free.items()} | {key: free[key][end]}
        return runs.experiment(table, hypotheses.Hypothesis(), values).raw["controllers"]

    return {k: b for k, b in free.items() if controllers(k, 0) != controllers(k, 1)}


class ColumnRuns:
    """One column's experiment with only its controller, measured on its cells."""

    def __init__(self, root: Path, table: str, controller: str = "conventional") -> None:
        self.table, self.controller, self.cells = table, controller, column_cells(table, controller)
        self.runs = TableRuns(root, [table], controllers=(controller,))

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
        n = len(candidates)
        return {d: cell_values(engine.remeasure(results, DEFINITIONS[d]), self.cells, n).T for d in definitions}

    def examined(self, family: Family) -> Family:
        """The hypotheses of ``family`` each of whose options changes this column's experiment (one
        that leaves it as configured, e.g. a z loop's option on the x pendulum, repeats a smaller one)."""
        raw, inputs = cfg.interpolate(self.runs.raw[self.table]), self.runs.inputs[self.table]

        def changes(option: tuple[str, str]) -> bool:
            hyp = hypotheses.Hypothesis((option,))
            middle = {k: (lo + hi) / 2 for k, (lo, hi) in hyp.free().items()}
            return hyp.apply(raw, middle, inputs) != raw

        moving = {option for option in {o for h in family for o in h.options} if changes(option)}
        return [h for h in family if set(h.options) <= moving]


def families_of(family: Family) -> list[str]:
    """The families with an option in ``family``, in the order of :data:`hypotheses.OPTIONS`."""
    named = {f for h in family for f, _ in h.options}
    return [f for f in hypotheses.OPTIONS if f in named]


def loops_frame(
    column: ColumnRuns, hyp: hypotheses.Hypothesis, candidates: list[dict[str, float]], ours: np.ndarray, source: str
) -> pd.DataFrame:
    """One row per evaluated loop: source, hypothesis, its values (JSON), loss, every cell."""
    frame = pd.DataFrame(ours, columns=list(column.cells.cell))
    loss = train_loss(ours.T, column.cells)
    head = {"source": source, "hypothesis": hyp.name, "values": [json.dumps(c) for c in candidates], "loss": loss}
    return pd.concat([pd.DataFrame(head), frame], axis=1)


def fit_column(
    spec: ConsistencySpec, root: Path, column: Column, hyp: hypotheses.Hypothesis, start: dict[str, float] | None
) -> tuple[dict[str, Any], pd.DataFrame]:
    """The GA fit of ``hyp``'s free values on one column (the literal loop with ``spec.warm_start``,
    the others with ``spec.optimiser`` from ``start`` and their parameters' neutral values; with
    nothing free, one loop): (summary, every loop evaluated)."""
    runs = ColumnRuns(root, *column)
    box = used_box(runs.runs, runs.table, spec.free) | hyp.free()
    keys = list(box)
    seen: list[pd.DataFrame] = []

    def objective(X: np.ndarray) -> np.ndarray:
        candidates = [dict(zip(keys, map(float, x), strict=True)) for x in np.atleast_2d(X)]
        ours = runs.measure(hyp, candidates)
        seen.append(loops_frame(runs, hyp, candidates, ours, "fit"))
        return train_loss(ours.T, runs.cells)

    if box:
        lower, upper = (np.array([b[i] for b in box.values()]) for i in (0, 1))
        settings = spec.warm_start if start is None else spec.optimiser
        seed = None if start is None else np.array([[{**start, **hyp.neutral()}[k] for k in keys]])
        result = evolve(objective, lower, upper, settings, start=seed)
        values, loss = dict(zip(keys, map(float, result.x), strict=True)), float(result.f)
    else:
        values, loss = {}, float(objective(np.zeros((1, 0)))[0])
    summary = {"table": column[0], "controller": column[1], "hypothesis": hyp.name, "values": values, "loss": loss}
    return summary, pd.concat(seen, ignore_index=True)


def random_loops(spec: ConsistencySpec, root: Path, column: Column, family: Family) -> dict[str, pd.DataFrame]:
    """The cloud of one column: ``spec.cloud.n`` picks of a random hypothesis of ``family``
    with random free values (one seed per column; the picks of a hypothesis with nothing free
    are one loop), each loop simulated once and measured under every definition of the spec."""
    runs = ColumnRuns(root, *column)
    box = used_box(runs.runs, runs.table, spec.cloud.box or spec.free)
    rng = np.random.default_rng([spec.cloud.seed, *map(int, column[0].split(".")), int(column[1] == "proposed")])
    picks = rng.integers(len(family), size=spec.cloud.n)
    frames: dict[str, list[pd.DataFrame]] = {d: [] for d in spec.definitions}
    for index in np.unique(picks):
        hyp = family[index]
        full = box | hyp.free()
        lower, upper = ([b[i] for b in full.values()] for i in (0, 1))
        draws = rng.uniform(lower, upper, (int(np.sum(picks == index)) if full else 1, len(full)))
        candidates = [dict(zip(full, map(float, row), strict=True)) for row in draws]
        for definition, ours in runs.measure_each(hyp, candidates, spec.definitions).items():
            frames[definition].append(loops_frame(runs, hyp, candidates, ours, "random"))
    return {d: pd.concat(f, ignore_index=True) for d, f in frames.items()}


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")


class Store:
    """The study's finished tasks on disk: fits/<table>_<controller>/<hypothesis>.json with the
    loops the fit evaluated, loops/<table>_<controller>/<definition>.csv for the clouds (each
    written atomically)."""

    def __init__(self, out_dir: Path, digest: str) -> None:
        self.out_dir, self.digest = out_dir, digest

    def fit_path(self, column: Column, hyp: str) -> Path:
        return self.out_dir / "fits" / slug(" ".join(column)) / f"{hyp}.json"

    def cloud_path(self, column: Column, definition: str) -> Path:
        return self.out_dir / "loops" / slug(" ".join(column)) / f"random_{slug(definition)}.csv"

    def has_fit(self, column: Column, hyp: str) -> bool:
        path = self.fit_path(column, hyp)
        return path.is_file() and json.loads(path.read_text()).get("spec_digest") == self.digest

    def has_cloud(self, column: Column, definition: str) -> bool:
        stamp = self.cloud_path(column, definition).with_suffix(".digest")
        return stamp.is_file() and stamp.read_text() == self.digest

    def save_fit(self, summary: dict[str, Any], loops: pd.DataFrame) -> None:
        path = self.fit_path((summary["table"], summary["controller"]), summary["hypothesis"])
        report.write_csv(path.with_suffix(".loops.csv"), loops)
        report.write_text(path, json.dumps({**summary, "spec_digest": self.digest}, indent=2) + "\n")

    def save_cloud(self, column: Column, definition: str, loops: pd.DataFrame) -> None:
        path = self.cloud_path(column, definition)
        report.write_csv(path, loops)
        report.write_text(path.with_suffix(".digest"), self.digest)

    def fit(self, column: Column, hyp: str) -> dict[str, Any]:
        return json.loads(self.fit_path(column, hyp).read_text())

    def loops(self, column: Column, definition: str, hyps: list[str]) -> pd.DataFrame:
        """Every loop of a column measured under ``definition``: its cloud, and under nlcx's
        definition also every GA candidate."""
        frames = [pd.read_csv(self.cloud_path(column, definition))]
        if definition == NLCX_DEFINITION:
            frames += [pd.read_csv(self.fit_path(column, h).with_suffix(".loops.csv")) for h in hyps]
        return pd.concat(frames, ignore_index=True)


def digest(spec: ConsistencySpec) -> str:
    """What a finished task depends on: the spec."""
    return hashlib.sha256(json.dumps(spec.model_dump(), sort_keys=True).encode()).hexdigest()[:16]


def load_spec(path: Path) -> ConsistencySpec:
    return validate_model(ConsistencySpec, safe_yaml.load_file(path) or {}, "")


def consistency(
    path: Path, out_dir: Path, jobs: int = 1, root: Path | None = None, progress: Callable[..., None] | None = None
) -> pd.DataFrame:
    """Run the study of spec ``path`` (resuming finished tasks) and write its analysis."""
    spec = load_spec(path)
    root = root or Path("configs") / "thesis"
    store = Store(out_dir, digest(spec))
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
    write_study(out_dir, total, done, jobs, time.perf_counter() - t0)
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
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(_task, spec, root, t, start(t), families[t[1:3]]): t for t in tasks}
        for future in as_completed(futures):
            yield futures[future], future.result()


def hits(loops: pd.DataFrame, cells: pd.DataFrame) -> np.ndarray:
    """(loops, cells) booleans: the loop's value inside the interval the printed cell covers,
    ``cells.lower`` <= ours <= ``cells.upper`` (:func:`with_intervals`: the printed value's
    rounding to its decimals, widened by its metric's relative tolerance)."""
    ours = loops[list(cells.cell)].to_numpy(dtype=float)
    with np.errstate(invalid="ignore"):
        return (cells.lower.to_numpy() <= ours) & (ours <= cells.upper.to_numpy())


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
    """A column's loops under one definition judged on its cells, ``cell_hit`` (loops, cells), and
    with mirror twins merged: ``hit``, ``miss`` (relative, inf where undefined), (loops, groups)."""

    loops: pd.DataFrame
    cell_hit: np.ndarray
    hit: np.ndarray
    miss: np.ndarray


def evidence(cells: pd.DataFrame, groups: list[list[int]], loops: pd.DataFrame) -> Evidence:
    scale = np.maximum(cells.value.abs().to_numpy(), cells.metric.map(FLOORS).to_numpy())
    miss = np.abs(loops[list(cells.cell)].to_numpy(float) - cells.value.to_numpy()) / scale
    cell_hit = hits(loops, cells)
    return Evidence(loops, cell_hit, *group_hits(cell_hit, miss, groups))


def nearest_miss(ev: Evidence, subset: tuple[int, ...]) -> tuple[float, int]:
    """(largest relative miss over ``subset`` of the loop nearest to hitting it all, that loop)."""
    worst = ev.miss[:, list(subset)].max(axis=1)
    k = int(np.argmin(worst))
    return float(worst[k]), k


def analyse(
    spec: ConsistencySpec, store: Store, families: dict[Column, Family], rules: tolerances.Tolerances
) -> pd.DataFrame:
    """columns.csv, cells.csv, subsets.csv, summary.json and consistency.png from the stored loops."""
    columns, cell_rows, subset_rows, clouds, summary = [], [], [], {}, []
    for column, family in families.items():
        names, examined = [h.name for h in family], " ".join(families_of(family))
        cells = with_intervals(column_cells(*column), rules, spec.zero_decimals)
        groups = twins(cells)
        fits = pd.DataFrame([store.fit(column, h) for h in names]).sort_values("loss", kind="stable")
        judged = {d: evidence(cells, groups, store.loops(column, d, names)) for d in spec.definitions}
        for definition, ev in judged.items():
            columns.append(column_row(column, definition, cells, ev, fits.iloc[0]) | {"families": examined})
            cell_rows += cell_table(column, definition, cells, ev)
        subset_rows += [row | {"families": examined} for row in subset_table(column, cells, groups, judged)]
        clouds[column] = judged[NLCX_DEFINITION].loops
        summary.append({"table": column[0], "controller": column[1], "families": families_of(family),
                        "hypotheses": len(family)})  # fmt: skip
    out = store.out_dir
    frame = pd.DataFrame(columns)
    report.write_csv(out / "columns.csv", frame)
    report.write_csv(out / "cells.csv", pd.DataFrame(cell_rows))
    report.write_csv(out / "subsets.csv", pd.DataFrame(subset_rows))
    scope = {"families": spec.families, "max_options": spec.max_options, "alone": spec.alone, "columns": summary}
    report.write_text(out / "summary.json", json.dumps(scope, indent=2) + "\n")
    figure(clouds, out / "consistency.png")
    return frame


def column_row(column: Column, definition: str, cells: pd.DataFrame, ev: Evidence, best: pd.Series) -> dict[str, Any]:
    """One column under one definition: the loops examined, the most cells one loop hits, the
    minimal unreachable sets, and (nlcx's definition) the best GA fit."""
    table, controller = column
    counts = ev.cell_hit.sum(axis=1)
    head = catalog.thesis_metrics().query("table == @table").iloc[0]
    values = ev.loops[list(cells.cell)].to_numpy(float)
    row = {
        "table": table, "controller": controller, "also_printed_in": " ".join(also_printed(*column)),
        "plant": head.plant, "scenario": head.scenario, "definition": definition, "cells": len(cells),
        "loops": len(ev.loops), "settled_share": float(np.mean(np.all(np.isfinite(values), axis=1))),
        "most_cells_hit": int(counts.max()), "loops_hitting_all": int(np.sum(counts == len(cells))),
        "reproduced": bool(np.any(counts == len(cells))), "unreachable_sets": len(unreachable_sets(ev.hit, 3)),
    }  # fmt: skip
    if definition == NLCX_DEFINITION:
        row |= {"best_fit": best.hypothesis, "best_fit_loss": float(best.loss),
                "best_fit_values": json.dumps(best["values"])}  # fmt: skip
    return row


def cell_table(column: Column, definition: str, cells: pd.DataFrame, ev: Evidence) -> list[dict[str, Any]]:
    """Per cell: printed (its text and the interval it covers), the value of the loop nearest
    the whole column (least loss), the range the loops reach, and how many hit it."""
    loops = ev.loops
    nearest = loops.iloc[int(loops.loss.argmin())]
    rows = []
    cell: Any  # a row of ``cells``: its cell name (a column of ``loops``), printed value and interval
    for i, cell in enumerate(cells.itertuples(index=False)):
        values = loops[cell.cell].to_numpy(dtype=float)
        finite = values[np.isfinite(values)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (np.nan, np.nan)
        rows.append({
            "table": column[0], "controller": column[1], "definition": definition, "cell": cell.cell,
            "printed": cell.value, "text": cell.text, "lower": cell.lower, "upper": cell.upper,
            "nearest_loop": float(nearest[cell.cell]), "nearest_hypothesis": nearest.hypothesis,
            "min": lo, "max": hi, "loops_hitting": int(ev.cell_hit[:, i].sum()),
        })  # fmt: skip
    return rows


def subset_table(
    column: Column, cells: pd.DataFrame, groups: list[list[int]], judged: dict[str, Evidence], max_size: int = 3
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
            "table": column[0], "controller": column[1], "cells": " & ".join(label[i] for i in subset),
            "printed": ", ".join(cells.text.iloc[groups[i][0]] for i in subset), "size": len(subset),
            "loops": len(first.loops), "nearest": near, **misses, "least_miss": min(misses.values()),
        })  # fmt: skip
    return rows


def figure(clouds: dict[Column, pd.DataFrame], path: Path) -> None:
    """Per column: x rise time against x overshoot of every loop examined, and the printed pair."""
    from nlcx.drawing import atomic_write, new_figure

    n = len(clouds)
    cols = min(4, n)
    n_rows = (n + cols - 1) // cols
    fig, axes = new_figure(n_rows, cols, (3.4 * cols, 3.0 * n_rows))
    for ax, (column, loops) in zip(axes.flat, clouds.items(), strict=False):
        cells = column_cells(*column).set_index("cell").value
        for source, rows in loops.groupby("source"):
            ax.scatter(rows["x.tr"], rows["x.Mp"], s=2, alpha=0.3, label=f"{source} loops")
        ax.scatter([cells["x.tr"]], [cells["x.Mp"]], marker="*", s=160, color="red", label="printed")
        ax.set(xlim=(0, max(5.0, 1.5 * cells["x.tr"])), ylim=(0, 1.2))
        ax.set_title(f"Table {column[0]}, {column[1]}", fontsize=9)
        ax.set_xlabel("x t_r (s)", fontsize=8)
        ax.set_ylabel("x M_p", fontsize=8)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    legend = axes.flat[0].legend(fontsize=7)
    for handle in legend.legend_handles:  # the same modest marker for the dots and the star
        handle.set_sizes([30.0])
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))

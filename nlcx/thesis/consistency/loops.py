"""A column's loops in the consistency study: run and measured on its cells, fitted by the
seeded GA, drawn at random (the cloud), and kept on disk as finished tasks (:class:`Store`)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from nlcx import config as cfg
from nlcx import engine, report
from nlcx.thesis import hypotheses
from nlcx.thesis.consistency.spec import NLCX_DEFINITION, Box, Column, ConsistencySpec, Family, column_cells
from nlcx.thesis.fitting import DEFINITIONS, TableRuns, cell_values, measure_cells, train_loss
from nlcx.tuning.optimise import evolve


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

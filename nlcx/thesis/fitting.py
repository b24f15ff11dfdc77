"""A hypothesis's loops on the thesis's tables: their experiments, cells, train loss and scores.

The pieces every identification study shares (:mod:`nlcx.thesis.identify`, the lockstep fits of
:mod:`nlcx.thesis.lockstep`, the consistency study): each table's experiment with candidate values
and a hypothesis applied (:class:`TableRuns`), our value of each thesis cell (:func:`measure_cells`),
the train loss a GA minimises (:func:`train_loss`, :class:`FitObjective`), a fitted hypothesis's
summary and fit table (:func:`search`, :func:`fitted`) and its scores per part (:func:`scores`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple, TypeAlias

import numpy as np
import pandas as pd

from nlcx import config as cfg
from nlcx import engine, report
from nlcx.compiled_cache import files_digest, source_digest
from nlcx.engine.gpu import Ensemble
from nlcx.engine.metric_rows import MetricColumns
from nlcx.engine.results import ExperimentResult
from nlcx.thesis import catalog, hypotheses, packed_cells, profiles
from nlcx.thesis.tables import lookup_value, rows_lookup
from nlcx.tuning.optimise import OptimResult

#: A study's progress: (hypotheses done, hypotheses in all, the name of the one just finished).
StudyProgress: TypeAlias = Callable[[int, int, str], None]

FLOORS = {"Mp": 0.05, "tr": 0.5, "ts": 0.5}
PENALTY = 10.0
CONTROLLERS = ("conventional", "proposed")

#: Measurement-side definitions, reported beside the fits and never part of a hypothesis.
DEFINITIONS = {
    "rise 10-90 %, band 2 % (nlcx)": {"rise_limits": [0.1, 0.9], "settling_band": 0.02},
    "rise 0-100 %, band 2 %": {"rise_limits": [0.0, 1.0], "settling_band": 0.02},
    "rise 10-90 %, band 5 %": {"rise_limits": [0.1, 0.9], "settling_band": 0.05},
    "rise 0-100 %, band 5 %": {"rise_limits": [0.0, 1.0], "settling_band": 0.05},
}


class TableRuns:
    """The experiment of each thesis table, with candidate values and a hypothesis applied."""

    def __init__(
        self, root: Path, tables: list[str], controllers: tuple[str, ...] | None = None, device: str = "cpu"
    ) -> None:
        """``controllers``: keep only these controllers of each experiment (default: all);
        ``device``: where their loops run (``simulation.device``)."""
        paths = {t.table: t.configs[0] for t in catalog.tables(root) if t.kind == "metrics"}
        self.raw = {table: _on(_keep(cfg.read_config(paths[table]), controllers), device) for table in tables}
        self.inputs = {table: profiles.plant_inputs(raw) for table, raw in self.raw.items()}

    def experiment(
        self, table: str, hyp: hypotheses.Hypothesis, values: dict[str, float], metrics: dict[str, Any] | None = None
    ) -> cfg.Experiment:
        """Table ``table``'s experiment with the free values set and the hypothesis applied
        (the same path as a reproduction profile, :func:`nlcx.thesis.profiles.apply`)."""
        return profiles.apply(self.raw[table], hyp, values, self.inputs[table], metrics)


def _on(raw: dict[str, Any], device: str) -> dict[str, Any]:
    """``raw`` with its loops on ``device`` (unchanged on the CPU, the default)."""
    return raw if device == "cpu" else {**raw, "simulation": {**raw.get("simulation", {}), "device": device}}


def _keep(raw: dict[str, Any], controllers: tuple[str, ...] | None) -> dict[str, Any]:
    if controllers is None:
        return raw
    return {**raw, "controllers": {k: v for k, v in raw["controllers"].items() if k in controllers}}


def measure_cells(
    runs: TableRuns,
    hyp: hypotheses.Hypothesis,
    candidates: list[dict[str, float]],
    cells: pd.DataFrame,
    metrics: dict[str, Any] | None = None,
) -> np.ndarray:
    """Our value of every cell (rows) for every candidate (columns); NaN where a run diverged
    or the metric is undefined. All candidates' experiments go through one pipeline call."""
    tables = list(dict.fromkeys(cells.table))
    exps = [runs.experiment(t, hyp, c, metrics) for c in candidates for t in tables]
    return cell_values(engine.evaluate(exps, record_logs=False), cells, len(candidates))


def cell_values(results: list[ExperimentResult], cells: pd.DataFrame, n_candidates: int) -> np.ndarray:
    """The cells (rows) of each candidate (columns) from the results of its tables' experiments
    (candidate-major, tables in the order of ``cells``)."""
    tables = list(dict.fromkeys(cells.table))
    out = np.full((len(cells), n_candidates), np.nan)
    of_table: dict[str, list[tuple[int, str, str, str]]] = {t: [] for t in tables}  # row, controller, signal, metric
    for i, (table, *cell) in enumerate(zip(cells.table, cells.controller, cells.signal, cells.metric, strict=True)):
        of_table[table].append((i, *cell))
    for k in range(n_candidates):
        for t_index, table in enumerate(tables):
            result = results[k * len(tables) + t_index]
            ok = {run.label for run in result.runs if run.status == "ok"}
            values = rows_lookup(result.metric_rows)
            for i, controller, signal, metric in of_table[table]:
                if controller in ok:
                    out[i, k] = lookup_value(values, controller, signal, metric)
    return out


def train_loss(ours: np.ndarray, cells: pd.DataFrame) -> np.ndarray:
    """Mean squared relative residual per candidate (columns of ``ours``); PENALTY where undefined."""
    thesis = cells.value.to_numpy()[:, None]
    floor = cells.metric.map(FLOORS).to_numpy()[:, None]
    with np.errstate(invalid="ignore"):
        residual = (ours - thesis) / np.maximum(np.abs(thesis), floor)
    residual = np.where(np.isfinite(residual), residual, PENALTY)
    return np.mean(residual**2, axis=0)


class FitObjective:
    """Train loss of a population (rows of X: the free values of ``box``, in its order): packed into
    each table whose free values land in its arrays as themselves (:mod:`nlcx.thesis.packed_cells`),
    built candidate by candidate elsewhere (:func:`measure_cells`); the same cells bit for bit."""

    def __init__(self, root: Path, hyp: hypotheses.Hypothesis, box: packed_cells.Box, cells: pd.DataFrame,
                 device: str = "cpu", runs: TableRuns | None = None) -> None:  # fmt: skip
        """``runs``: the tables' experiments, when they are shared (default: read on first use)."""
        self.root, self.hyp, self.box, self.keys, self.cells, self.device = root, hyp, box, list(box), cells, device
        self._runs = runs
        self._packed: dict[str, packed_cells.PackedTable | str] | None = None

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_runs": None, "_packed": None}

    def tables(self) -> TableRuns:
        """The train tables' experiments (read on first use, per process)."""
        if self._runs is None:
            self._runs = TableRuns(self.root, list(dict.fromkeys(self.cells.table)), device=self.device)
        return self._runs

    def packing(self) -> dict[str, packed_cells.PackedTable | str]:
        """Each train table's packing, or why it has none (prepared on first use, per process)."""
        if self._packed is None:
            tables = list(dict.fromkeys(self.cells.table))
            self._packed = packed_cells.packings(tables, self.tables().experiment, self.hyp, self.box)
        return self._packed

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return self.losses(X)

    def ensembles(self, X: np.ndarray) -> dict[str, Ensemble]:
        """The population X as an ensemble of each packed table (to measure with others')."""
        return packed_cells.population_ensembles(self.packing(), np.atleast_2d(X), self.keys)

    def losses(self, X: np.ndarray, measured_rows: dict[str, MetricColumns] | None = None) -> np.ndarray:
        """Train loss of each row of X (``measured_rows``: the metric rows of its
        :meth:`ensembles`, when measured elsewhere)."""
        by_candidate = functools.partial(measure_cells, self.tables(), self.hyp)
        X = np.atleast_2d(X)
        ours = packed_cells.population_cells(self.packing(), X, self.keys, self.cells, by_candidate, measured_rows)
        return train_loss(ours, self.cells)


def relative_errors(fit: pd.DataFrame) -> pd.Series:
    """|nlcx - thesis| / |thesis| per cell; inf where our run diverged or the metric is
    undefined (a failure counts, it is not dropped), NaN where the thesis prints 0."""
    rel = (fit.nlcx - fit.thesis).abs() / fit.thesis.abs().where(fit.thesis != 0)
    return rel.where(fit.nlcx.notna() | (fit.thesis == 0), np.inf)


def scores(fit: pd.DataFrame) -> dict[str, float]:
    """Per part: median relative error overall, per controller and per controller and metric
    (failed cells count as infinitely wrong), the share of cells we measured, and direction
    agreement."""
    out: dict[str, float] = {}
    fit = fit.assign(rel_error=relative_errors(fit))
    for part, rows in fit.groupby("part", sort=False):
        rel = rows[rows.thesis != 0]
        out[f"{part}_median_rel_error"] = float(np.median(rel.rel_error)) if len(rel) else math.nan
        for c in CONTROLLERS:
            mine = rel[rel.controller == c]
            out[f"{part}_{c}_median_rel_error"] = float(np.median(mine.rel_error)) if len(mine) else math.nan
            for metric in FLOORS:
                cells = mine[mine.metric == metric]
                key = f"{part}_{c}_{metric}_median_rel_error"
                out[key] = float(np.median(cells.rel_error)) if len(cells) else math.nan
        out[f"{part}_measured_share"] = float(rows.nlcx.notna().mean())
        out[f"{part}_direction_agreement"] = direction_agreement(rows)
    return out


def direction_agreement(rows: pd.DataFrame) -> float:
    """Share of (table, signal, metric) cells with both controllers where the sign of
    (proposed - conventional) is the thesis's; cells the thesis prints equal are left out."""
    wide = rows.pivot_table(index=["table", "signal", "metric"], columns="controller", values=["thesis", "nlcx"])
    if not all((col, c) in wide.columns for col in ("thesis", "nlcx") for c in CONTROLLERS):
        return math.nan
    theirs = np.sign(wide["thesis"]["proposed"] - wide["thesis"]["conventional"])
    ours = np.sign(wide["nlcx"]["proposed"] - wide["nlcx"]["conventional"])
    comparable = (theirs != 0) & ours.notna()
    return float((theirs[comparable] == ours[comparable]).mean()) if comparable.any() else math.nan


class Search(NamedTuple):
    """A hypothesis's GA search: its objective, the box [lower, upper] of its free values (in the
    objective's order) and the rows seeding its first population (None: drawn at random)."""

    objective: FitObjective
    lower: np.ndarray
    upper: np.ndarray
    start: np.ndarray | None


def search(
    root: Path, hyp: hypotheses.Hypothesis, free: dict[str, tuple[float, float]], cells: pd.DataFrame,
    device: str = "cpu", start: dict[str, float] | None = None, runs: TableRuns | None = None,
) -> Search:  # fmt: skip
    """The search of ``hyp`` on the train cells of ``cells``: the conventional gains ``free`` and
    the hypothesis's freed parameters, the first population seeded with ``start`` (the
    conventional gains) and the freed parameters' neutral values."""
    bounds = {**free, **hyp.free()}
    keys = list(bounds)
    train = cells[cells.part == "train"].reset_index(drop=True)
    lower, upper = (np.array([b[i] for b in bounds.values()]) for i in (0, 1))
    seed = None if start is None else np.array([[{**start, **hyp.neutral()}[k] for k in keys]])
    return Search(FitObjective(root, hyp, bounds, train, device, runs), lower, upper, seed)


def fitted_values(objective: FitObjective, result: OptimResult) -> dict[str, float]:
    """The GA's best candidate as the free values by key."""
    return dict(zip(objective.keys, map(float, result.x), strict=True))


def measure_fits(runs: TableRuns, fits: list[tuple[hypotheses.Hypothesis, dict[str, float]]],
                 cells: pd.DataFrame) -> list[np.ndarray]:  # fmt: skip
    """Our value of every cell for each fitted hypothesis (its values), all in one pipeline call."""
    tables = list(dict.fromkeys(cells.table))
    results = engine.evaluate([runs.experiment(t, h, v) for h, v in fits for t in tables], record_logs=False)
    n = len(tables)
    return [cell_values(results[k * n : (k + 1) * n], cells, 1)[:, 0] for k in range(len(fits))]


def fit_table(cells: pd.DataFrame, ours: np.ndarray) -> pd.DataFrame:
    """The cells with the thesis's value (``thesis``), ours and the relative error of each."""
    fit = cells.rename(columns={"value": "thesis"}).assign(nlcx=ours)
    fit["rel_error"] = relative_errors(fit)
    return fit


def fitted(
    hyp: hypotheses.Hypothesis, cells: pd.DataFrame, values: dict[str, float], result: OptimResult,
    ours: np.ndarray, wall_s: float,
) -> tuple[dict[str, Any], pd.DataFrame]:  # fmt: skip
    """A finished fit: (summary, fit table) from the GA's result, the fitted ``values`` and our
    value of every cell under them."""
    fit = fit_table(cells, ours)
    summary = {
        "hypothesis": hyp.name,
        "options": dict(hyp.options),
        "values": values,
        "train_loss": float(result.f),
        "evaluations": result.evaluations,
        "wall_s": round(wall_s, 2),
        **scores(fit),
    }
    return summary, fit


#: Files under the thesis configs that a study writes rather than reads (``make identify`` copies
#: the selected profile there): left out of :func:`study_digest`.
STUDY_OUTPUTS = ("profiles/selected.yaml",)


@functools.cache
def _code_digest(root: Path) -> str:
    return files_digest(root, "*.yaml", skip=STUDY_OUTPUTS, prefix=source_digest().encode())


def study_digest(spec_digest: str, root: Path) -> str:
    """What a finished task of a study (a fit, a cloud of loops, a searched set) depends on: its
    spec's digest, nlcx's source (every Python file of the package: the loops, the metrics, the
    optimisers; :func:`nlcx.compiled_cache.source_digest`) and the thesis configs under ``root``
    that its tables run. A study resumes only from tasks that the same source and configs
    finished; any other task is done again, so that no study mixes the results of two versions."""
    return hashlib.sha256(f"{spec_digest}:{_code_digest(root.resolve())}".encode()).hexdigest()[:16]


def spec_provenance(spec: Path) -> dict[str, Any]:
    """Which spec a study ran: its path, the SHA-256 of its text, the last commit that changed
    it and whether the file is that commit's (None for both outside a git checkout), so a
    pre-registered spec can be shown to precede its results."""
    digest = hashlib.sha256(spec.read_bytes()).hexdigest()
    record: dict[str, Any] = {"spec": spec.as_posix(), "spec_sha256": digest, "spec_commit": None,
                              "spec_committed": None}  # fmt: skip
    where = str(spec.resolve().parent)
    try:
        last = subprocess.run(["git", "-C", where, "log", "-1", "--format=%H", "--", spec.resolve().name],
                              capture_output=True, text=True, timeout=10)  # fmt: skip
        changed = subprocess.run(["git", "-C", where, "status", "--porcelain", "--", spec.resolve().name],
                                 capture_output=True, text=True, timeout=10)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return record
    if last.returncode == 0 and last.stdout.strip():
        record |= {"spec_commit": last.stdout.strip(), "spec_committed": changed.stdout.strip() == ""}
    return record


def write_study(
    out_dir: Path, hypotheses_total: int, fitted: int, jobs: int, wall_s: float, spec: Path | None = None
) -> None:
    """study.json: how many hypotheses the study holds, how many this invocation fitted, on how
    many workers and in what wall time (a resumed study's time covers only its rest; a run
    that fitted nothing keeps the record of the last one that did), and the ``spec`` it ran
    (:func:`spec_provenance`)."""
    if fitted == 0 and (out_dir / "study.json").is_file():
        return
    record = {"hypotheses": hypotheses_total, "fitted_now": fitted, "jobs": jobs, "wall_s": round(wall_s, 1)}
    if spec is not None:
        record |= spec_provenance(spec)
    report.write_text(out_dir / "study.json", json.dumps(record, indent=2) + "\n")

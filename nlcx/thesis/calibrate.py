"""Calibrate what the thesis does not print by fitting one of its tables.

A calibration spec (YAML) names a base experiment, the config keys to fit with their
bounds, the thesis table column to fit and the optimiser settings::

    name: calibrate_x
    base: ../ch2/fig_2_04.yaml             # plant, references, simulation
    controller: conventional               # the controller whose numbers are fitted
    parameters:                            # dotted config keys (overrides) and bounds
      vars.conventional.angle.kp: [10, 80]
    target: {table: "2.3", controller: conventional, metrics: [Mp, tr, ts]}
    optimiser: {kind: ga, pop_size: 40, generations: 30, seed: 1}
    write: {file: ../gains/conventional.yaml, keys: [vars.conventional.angle]}

The loss is the mean squared relative residual over the target cells,
((ours - thesis) / max(|thesis|, floor))^2 with floors 0.05 for M_p and 0.5 s for times;
a diverged run or an undefined metric costs a residual of 10. Every candidate of a
generation is simulated in one batched kernel call.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TypedDict, cast

import numpy as np
import pandas as pd
import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nlcx import config as cfg
from nlcx import engine, manifest, runtime, safe_yaml
from nlcx.errors import ConfigError
from nlcx.thesis import catalog
from nlcx.thesis.tables import lookup_value, metric_lookup
from nlcx.tuning.optimise import GASettings, OptimResult, check_search_box, evolve
from nlcx.validation import validate_model

FLOORS = {"Mp": 0.05, "tr": 0.5, "ts": 0.5, "ess": 0.01}
PENALTY = 10.0


class Target(BaseModel):
    model_config = ConfigDict(extra="forbid")
    table: str
    controller: str = "conventional"
    metrics: list[str] = Field(default_factory=lambda: ["Mp", "tr", "ts"])
    #: Restrict to these signals (default: every signal of the table).
    signals: list[str] | None = None


class WriteBack(BaseModel):
    model_config = ConfigDict(extra="forbid")
    file: str
    keys: list[str]


class CalibrationSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    base: str
    controller: str = "conventional"
    parameters: dict[str, tuple[float, float]] = Field(min_length=1)
    target: Target
    optimiser: GASettings = GASettings()
    write: WriteBack | None = None

    @field_validator("parameters")
    @classmethod
    def _bounds(cls, params: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        refusal = "only controller settings (controllers.* or vars.*) can be fitted"
        return check_search_box(params, ("vars.", "controllers."), refusal)


def target_cells(target: Target) -> pd.DataFrame:
    """The thesis cells to fit: signal, metric, value."""
    table = catalog.thesis_metrics()
    rows = table[(table.table == target.table) & (table.controller == target.controller)]
    rows = rows[rows.metric.isin(target.metrics)]
    if target.signals is not None:
        rows = rows[rows.signal.isin(target.signals)]
    if rows.empty:
        raise ConfigError("target", target.model_dump(), "selects no cell of the thesis's tables")
    return rows[["signal", "metric", "value"]].reset_index(drop=True)


class CalibrationObjective:
    """Loss of a batch of candidates (rows of X); picklable for a process pool."""

    def __init__(self, base_raw: dict[str, object], spec: CalibrationSpec) -> None:
        self.base_raw = base_raw
        self.spec = spec
        self.keys = list(spec.parameters)
        self.cells = target_cells(spec.target)

    def candidate_config(self, x: np.ndarray) -> dict[str, object]:
        overrides = [f"{k}={float(v)!r}" for k, v in zip(self.keys, x, strict=True)]
        return cfg.interpolate(cfg.apply_overrides(self.base_raw, overrides))

    def candidate_experiment(self, x: np.ndarray, label: str) -> cfg.Experiment:
        """The candidate's experiment with only the fitted controller, labelled ``label``."""
        raw = self.candidate_config(x)
        controllers = cast(dict[str, object], raw["controllers"])  # validated by calibrate's first build
        raw["controllers"] = {label: controllers[self.spec.controller]}
        return cfg.build(raw)

    def measure(self, X: np.ndarray) -> pd.DataFrame:
        """Metrics of every candidate, labelled c0, c1, ... (one batched pipeline call)."""
        results = engine.evaluate([self.candidate_experiment(x, f"c{i}") for i, x in enumerate(np.atleast_2d(X))])
        table = pd.concat([r.metrics for r in results], ignore_index=True)
        status = {run.label: run.status for r in results for run in r.runs}
        table["run_status"] = table.controller.map(status)
        return table

    def residuals(self, table: pd.DataFrame, label: str) -> np.ndarray:
        out = np.empty(len(self.cells))
        rows = table[table.controller == label]
        unstable = (rows.run_status != "ok").any()
        values = metric_lookup(rows)
        # a row of the cells table: its signal, metric (str) and printed value (float)
        for k, (signal, metric, value) in enumerate(self.cells.itertuples(index=False)):
            ours = lookup_value(values, label, signal, metric)
            scale = max(abs(value), FLOORS.get(metric, 0.05))
            out[k] = PENALTY if unstable or math.isnan(ours) else (ours - value) / scale
        return out

    def __call__(self, X: np.ndarray) -> np.ndarray:
        table = self.measure(X)
        return np.array([float(np.mean(self.residuals(table, f"c{i}") ** 2)) for i in range(len(X))])


def load_spec(path: Path, overrides: list[str] | None = None) -> CalibrationSpec:
    raw = cfg.apply_overrides(cfg.read_yaml(path), overrides or [])
    return validate_model(CalibrationSpec, raw, "")


class Calibration(TypedDict):
    """What :func:`calibrate` found."""

    spec: CalibrationSpec
    result: OptimResult
    #: The target cells with nlcx's values and the residuals.
    fit: pd.DataFrame
    tuning: pd.DataFrame
    #: The base experiment's config with the fitted values, interpolated.
    config: dict[str, object]
    #: The fitted keys as a nested mapping (what goes into the gains file).
    block: dict[str, object]
    base: Path


def calibrate(
    path: Path,
    out_dir: Path,
    jobs: int = 1,
    overrides: list[str] | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> Calibration:
    """Run the fit of spec ``path``; write tuning.csv, fit.csv, history.csv and calibrated.yaml."""
    from nlcx import report

    start = time.perf_counter()
    spec = load_spec(path, overrides)
    base_path = (path.parent / spec.base).resolve()
    base_raw = cfg.read_config(base_path)
    objective = CalibrationObjective(base_raw, spec)
    cfg.build(objective.candidate_config(np.array([np.mean(b) for b in spec.parameters.values()])))
    lower = np.array([b[0] for b in spec.parameters.values()])
    upper = np.array([b[1] for b in spec.parameters.values()])
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs, initializer=runtime.worker) as pool:
            result = evolve(objective, lower, upper, spec.optimiser, pool, jobs, progress)
    else:
        result = evolve(objective, lower, upper, spec.optimiser, callback=progress)
    best = result.x
    table = objective.measure(best[None])
    residuals = objective.residuals(table, "c0")
    fit = objective.cells.copy()
    values = metric_lookup(table)
    cells = objective.cells
    fit["nlcx"] = [lookup_value(values, "c0", s, m) for s, m in zip(cells.signal, cells.metric, strict=True)]
    fit["residual"] = residuals
    fit = fit.rename(columns={"value": "thesis"})
    tuning = pd.DataFrame(
        [
            {"controller": spec.controller, "parameter": k, "value": float(v), "lower": lo, "upper": hi}
            for (k, (lo, hi)), v in zip(spec.parameters.items(), best, strict=True)
        ]
    )
    history = pd.DataFrame(result.history, columns=["generation", "evaluations", "best_loss"])
    report.write_csv(out_dir / "tuning.csv", tuning)
    report.write_csv(out_dir / "fit.csv", fit)
    report.write_csv(out_dir / "history.csv", history)
    calibrated = objective.candidate_config(best)
    block = _block(objective.base_raw, objective.keys, best, spec)
    report.write_text(out_dir / "calibrated.yaml", yaml.safe_dump(block, sort_keys=False))
    report.write_text(
        out_dir / "spec.yaml", yaml.safe_dump(spec.model_dump(mode="json"), sort_keys=False, allow_unicode=True)
    )
    info = {
        "name": spec.name,
        "loss": result.f,
        "evaluations": result.evaluations,
        "optimiser": spec.optimiser.model_dump(),
        "wall_s": round(time.perf_counter() - start, 2),
        **report.provenance(overrides or [], start),
        **report.environment(),
    }
    manifest.write(out_dir, {manifest.MARKER: "calibration", **info})
    return {
        "spec": spec,
        "result": result,
        "fit": fit,
        "tuning": tuning,
        "config": calibrated,
        "block": block,
        "base": base_path,
    }


def _block(
    base_raw: dict[str, object], keys: list[str], values: np.ndarray, spec: CalibrationSpec
) -> dict[str, object]:
    """The fitted keys as a nested mapping (what goes into the gains file)."""
    raw = cfg.apply_overrides(base_raw, [f"{k}={round(float(v), 4)!r}" for k, v in zip(keys, values, strict=True)])
    out: dict[str, object] = {}
    for key in spec.write.keys if spec.write else keys:
        node: object = raw
        for part in key.split("."):
            node = cast(dict[str, object], node)[part]  # a mapping above each part of a key the config holds
        target = out
        parts = key.split(".")
        for part in parts[:-1]:
            target = cast(dict[str, object], target.setdefault(part, {}))  # a mapping made here
        target[parts[-1]] = node
    return out


def write_back(spec_path: Path, outcome: Calibration) -> Path:
    """Merge the fitted values into the spec's ``write.file``, keeping its header comments."""
    spec = outcome["spec"]
    if spec.write is None:
        raise ConfigError("write", None, "the spec names no file to write the fitted values to")
    path = (spec_path.parent / spec.write.file).resolve()
    text = path.read_text(encoding="utf-8")
    header = "".join(line + "\n" for line in text.splitlines() if line.startswith("#"))
    gains = cast(dict[str, object], safe_yaml.load_text(text, str(path)) or {})  # a gains file: a mapping
    data = cfg.deep_merge(gains, outcome["block"])
    from nlcx import report

    body = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
    report.write_text(path, header + body)
    return path

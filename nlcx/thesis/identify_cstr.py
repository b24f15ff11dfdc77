"""Chapter 5's identification study: which loop gives Table 5.8's ZN row?

The chapter-5 counterpart of :mod:`nlcx.thesis.identify`. A hypothesis is a set of options of
:data:`nlcx.thesis.hypotheses.CSTR_FAMILIES` (ZN rule, PI vs PID, derivative, set-point
weight, step time, actuator limit, the model's time unit, transfer function vs the nonlinear
reactor); it applies to every Table 5.8 method's experiment (configs/thesis/ch5), whose
tuners then run as configured (ZN, fuzzy, ANFIS, GA, the single neuron). The ZN gains follow
from the rule, so only a hypothesis's own parameters (u_max) are fitted, by the seeded GA, on
the train rows (the ZN row); a hypothesis without one is measured once. The split holds no
chapter-5 validation row, so hypotheses are ranked by train loss (ties: fewer options first);
the test rows (fuzzy, ANN, ANFIS, GA) are reported, never used for a choice.
"""

from __future__ import annotations

import json
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nlcx import config as cfg
from nlcx import engine, report, runtime, safe_yaml
from nlcx.errors import NlcxError
from nlcx.kernel.signatures import FloatArray
from nlcx.thesis import catalog, hypotheses, profiles, split
from nlcx.thesis.cstr import CSTR_METRICS, cstr_value
from nlcx.thesis.fitting import StudyProgress, fit_table, relative_errors, study_digest, train_loss, write_study
from nlcx.thesis.identify import finished, save_fit, spec_digest
from nlcx.tuning.optimise import GASettings, evolve
from nlcx.validation import validate_model

#: The split's metric names as nlcx's metrics of Table 5.8's columns.
METRIC = {m: CSTR_METRICS[column][0] for m, column in split.CSTR_COLUMNS.items()}


class CstrSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    #: Marks a chapter-5 spec (``nlcx identify`` dispatches on it).
    chapter: Literal[5]
    split: str
    families: list[str] = Field(default_factory=lambda: list(hypotheses.CSTR_FAMILIES))
    max_options: int = Field(3, ge=0, le=len(hypotheses.CSTR_FAMILIES))
    #: GA of the hypotheses that free a parameter (u_max).
    optimiser: GASettings = GASettings(pop_size=8, generations=5, seed=1)

    @field_validator("families")
    @classmethod
    def _known(cls, families: list[str]) -> list[str]:
        unknown = [f for f in families if f not in hypotheses.CSTR_FAMILIES]
        if unknown:
            raise ValueError(f"unknown option families {unknown}; allowed: {', '.join(hypotheses.CSTR_FAMILIES)}")
        return families


def all_cells(spec_split: split.Split) -> pd.DataFrame:
    """Every Table 5.8 cell of the split with its part: part, method, metric, value."""
    parts = [split.cells(spec_split, part)[1].assign(part=part) for part in split.PARTS]
    return pd.concat(parts, ignore_index=True)[["part", "method", "metric", "value"]].astype({"value": float})


class MethodRuns:
    """Each Table 5.8 method's experiment, with a hypothesis applied."""

    def __init__(self, root: Path, methods: list[str]) -> None:
        self.files = {m: catalog.CSTR_METHODS[m] for m in methods}
        self.raw = {m: cfg.read_config(root / "ch5" / file) for m, (file, _) in self.files.items()}

    def experiment(self, method: str, hyp: hypotheses.Hypothesis, values: dict[str, float]) -> cfg.Experiment:
        return profiles.apply(self.raw[method], hyp, values, ["u"])


def measure(
    runs: MethodRuns, hyp: hypotheses.Hypothesis, candidates: list[dict[str, float]], cells: pd.DataFrame
) -> FloatArray:
    """Our value of every cell (rows) for every candidate (columns); NaN where a run or its
    tuning failed or the metric is undefined."""
    methods = list(dict.fromkeys(cells.method))
    out = np.full((len(cells), len(candidates)), np.nan)
    for k, values in enumerate(candidates):
        for method in methods:
            try:
                (result,) = engine.evaluate([runs.experiment(method, hyp, values)], record_logs=False)
            except NlcxError:  # a tuner that cannot tune this loop (e.g. no ultimate gain): failed cells
                continue
            label = runs.files[method][1]
            if not any(run.label == label and run.status == "ok" for run in result.runs):
                continue
            for i, cell in enumerate(cells.itertuples(index=False)):
                if cell.method == method:
                    out[i, k] = cstr_value(result.metrics, label, METRIC[str(cell.metric)])
    return out


class Objective:
    """Train loss of candidates (rows of X: the hypothesis's free parameters in ``keys`` order)."""

    def __init__(self, root: Path, hyp: hypotheses.Hypothesis, keys: list[str], cells: pd.DataFrame) -> None:
        self.root, self.hyp, self.keys, self.cells = root, hyp, keys, cells

    def __call__(self, X: np.ndarray) -> np.ndarray:
        runs = MethodRuns(self.root, list(dict.fromkeys(self.cells.method)))
        candidates = [dict(zip(self.keys, map(float, x), strict=True)) for x in np.atleast_2d(X)]
        return train_loss(measure(runs, self.hyp, candidates, self.cells), self.cells)


def fit_hypothesis(
    spec: CstrSpec, root: Path, hyp: hypotheses.Hypothesis, cells: pd.DataFrame
) -> tuple[dict[str, Any], pd.DataFrame]:
    """Fit ``hyp``'s free parameters on the train rows (if any), measure every cell."""
    t0 = time.perf_counter()
    free = hyp.free()
    train = cells[cells.part == "train"].reset_index(drop=True)
    values: dict[str, float] = {}
    if free:
        lower, upper = (np.array([b[i] for b in free.values()]) for i in (0, 1))
        result = evolve(Objective(root, hyp, list(free), train), lower, upper, spec.optimiser)
        values = dict(zip(free, map(float, result.x), strict=True))
    ours = measure(MethodRuns(root, list(dict.fromkeys(cells.method))), hyp, [values], cells)[:, 0]
    fit = fit_table(cells, ours)
    summary = {
        "hypothesis": hyp.name,
        "options": dict(hyp.options),
        "values": values,
        "train_loss": float(train_loss(ours[(cells.part == "train").to_numpy()][:, None], train)[0]),
        "wall_s": round(time.perf_counter() - t0, 2),
        **method_scores(fit),
    }
    return summary, fit


def method_scores(fit: pd.DataFrame) -> dict[str, float]:
    """Per part: the median relative error of M_p, t_r, t_s over its rows, and per method."""
    out: dict[str, float] = {}
    fit = fit.assign(rel_error=relative_errors(fit))
    for part, rows in fit.groupby("part", sort=False):
        rel = rows[rows.thesis != 0]
        out[f"{part}_median_rel_error"] = float(np.median(rel.rel_error)) if len(rel) else float("nan")
        for method, mine in rel.groupby("method", sort=False):
            out[f"{part}_{method}_median_rel_error"] = float(np.median(mine.rel_error))
    return out


def identify_cstr(
    path: Path, out_dir: Path, jobs: int = 1, root: Path | None = None, progress: StudyProgress | None = None
) -> pd.DataFrame:
    """Fit every chapter-5 hypothesis of spec ``path`` (resuming: each finished fit is written
    at once); ranking.csv (by train loss) and profile.yaml."""
    spec = validate_model(CstrSpec, safe_yaml.load_file(path) or {}, "")
    spec_split = split.load((path.parent / spec.split).resolve())
    cells = all_cells(spec_split)
    root = root or Path("configs") / "thesis"
    digest = study_digest(spec_digest(spec, spec_split), root)
    family = hypotheses.family(spec.families, spec.max_options)
    fits = out_dir / "fits"
    todo = [h for h in family if not finished(fits / f"{h.name}.json", digest)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(jobs, 1), initializer=runtime.worker) as pool:
        futures = [pool.submit(fit_hypothesis, spec, root, hyp, cells) for hyp in todo]
        for k, future in enumerate(as_completed(futures)):
            summary, fit = future.result()
            save_fit(fits, digest, summary, fit)
            if progress is not None:
                progress(len(family) - len(todo) + k + 1, len(family), summary["hypothesis"])
    write_study(out_dir, len(family), len(todo), jobs, time.perf_counter() - t0, path)
    return write_ranking(out_dir, [h.name for h in family])


def write_ranking(out_dir: Path, names: list[str]) -> pd.DataFrame:
    """ranking.csv by train loss (stable: fewer options first on ties) and profile.yaml, the
    first-ranked hypothesis as the ``chapter5`` part of a reproduction profile."""
    rows = []
    for name in names:
        summary = json.loads((out_dir / "fits" / f"{name}.json").read_text())
        fit = pd.read_csv(out_dir / "fits" / f"{name}.fit.csv")
        keep = ("hypothesis", "train_loss")
        rows.append(
            {**{k: summary[k] for k in keep}, **method_scores(fit),
             "options": json.dumps(summary["options"]), "values": json.dumps(summary["values"])}
        )  # fmt: skip
    ranking = pd.DataFrame(rows).sort_values("train_loss", kind="stable")
    ranking.insert(0, "rank", np.arange(1, len(ranking) + 1))
    report.write_csv(out_dir / "ranking.csv", ranking)
    best = ranking.iloc[0]
    profile = {"chapter5": {"hypothesis": json.loads(best["options"]), "values": json.loads(best["values"])}}
    header = "# Generated by nlcx identify (chapter 5: the hypothesis ranked first by train loss); do not edit.\n"
    report.write_text(out_dir / "profile.yaml", header + yaml.safe_dump(profile, sort_keys=False))
    return ranking

"""Which loop did the thesis simulate? Fit each hypothesis on the train tables, rank on validation.

An identification spec (YAML) names the split (configs/identify/split.yaml), the option
families and the largest number of options combined, the conventional gains left free in
every hypothesis, and the GA settings::

    name: pendulum_loop
    split: split.yaml
    families: [ordering, derivative, integral, ags_error, saturation]
    max_options: 3
    free:
      vars.conventional.angle.kp: [10, 120]
      ...
    optimiser: {kind: ga, pop_size: 30, generations: 20, seed: 1}
    screen: {keep: 6, min_gain: 0.05}   # optional

With ``screen``, the families are screened on train before any combination: every single
non-default value of each family is fitted (from the literal fit, as every hypothesis) and
scored by its train loss only; a family goes forward when its best value lowers the literal
fit's train loss by at least ``min_gain`` (relative), at most ``keep`` families, the largest
gain first (ties: the families' order). The combinations of up to ``max_options`` values are
then those of the forwarded families only, fitted and ranked as without a screen; the
screening's table is screening.csv.

For every hypothesis (:mod:`nlcx.thesis.hypotheses`), the seeded GA minimises the mean squared
relative residual over the train cells only (floors as the calibration: 0.05 for M_p, 0.5 s
for times; a diverged run or an undefined metric costs 10), a generation packed into each
train table prepared once (:mod:`nlcx.thesis.packed_cells`). The fitted loop is then
measured on every table and scored per part: the median relative error |ours - thesis| /
|thesis| of M_p, t_r, t_s (cells with a printed 0 excluded), per controller, and the share of
comparable cells where the sign of (proposed - conventional) agrees with the thesis.
Hypotheses are ranked by the validation score, never by the test score.

Each finished fit is written at once (``fits/<hypothesis>.json`` and ``.fit.csv``, atomically),
so a killed study loses no finished fit and a rerun skips them (the screening's fits included:
a hypothesis screened and then combined is fitted once). With ``device: cuda`` the hypotheses
are fitted side by side in this process (:mod:`nlcx.thesis.lockstep`), each fit the one it gets
alone, written when the lockstep ends.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from nlcx import report, runtime, safe_yaml
from nlcx.errors import ConfigError
from nlcx.thesis import hypotheses, lockstep, profiles, split
from nlcx.thesis.fitting import (
    DEFINITIONS,
    TableRuns,
    fitted,
    fitted_values,
    measure_cells,
    measure_fits,
    scores,
    search,
    study_digest,
    write_study,
)
from nlcx.tuning.optimise import GASettings, check_search_box, evolve
from nlcx.validation import validate_model


class Screen(BaseModel):
    """The screening rule, fixed in the spec before any fit."""

    model_config = ConfigDict(extra="forbid")
    #: At most this many families go forward to the combinations.
    keep: int = Field(ge=1)
    #: The least relative gain, 1 - (best single value's train loss) / (literal fit's), that
    #: sends a family forward.
    min_gain: float = Field(ge=0, lt=1)


class IdentifySpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    split: str
    families: list[str] = Field(default_factory=lambda: list(hypotheses.FAMILIES))
    max_options: int = Field(3, ge=0, le=len(hypotheses.FAMILIES))
    #: Conventional gains free in every hypothesis: dotted config keys and bounds.
    free: dict[str, tuple[float, float]] = Field(min_length=1)
    optimiser: GASettings = GASettings(pop_size=30, generations=20, seed=1)
    #: Fit only these hypotheses (by name; default: the whole family); not with ``screen``,
    #: which chooses them.
    only: list[str] | None = None
    #: GA settings of a first fit of the literal loop whose gains seed every other
    #: hypothesis's first population, the freed parameters at their values nearest the default
    #: loop (:data:`nlcx.thesis.hypotheses.NEUTRAL`): each GA then starts from the literal
    #: fit, and its elitism keeps the best candidate. None: every GA starts at random.
    warm_start: GASettings | None = None
    #: How many of the top-ranked hypotheses (besides the literal loop) get a full
    #: reproduction for their claims (claims.csv, the claims_* columns of ranking.csv);
    #: None: no reproduction.
    claims_top: int | None = Field(5, ge=0)
    #: Screen the families on train before combining them (None: combine every family).
    screen: Screen | None = None
    #: Where every candidate's closed loops run (``simulation.device`` of each experiment):
    #: a generation's loops in one kernel call on the CPU, or on the GPU (docs/guide/gpu.md).
    device: Literal["cpu", "cuda"] = "cpu"

    @field_validator("families")
    @classmethod
    def _known(cls, families: list[str]) -> list[str]:
        unknown = [f for f in families if f not in hypotheses.FAMILIES]
        if unknown:
            raise ValueError(f"unknown option families {unknown}; allowed: {', '.join(hypotheses.FAMILIES)}")
        return families

    @model_validator(mode="after")
    def _only_or_screen(self) -> IdentifySpec:
        if self.only is not None and self.screen is not None:
            raise ValueError("only and screen exclude each other: the screen chooses the hypotheses fitted")
        return self

    @field_validator("free")
    @classmethod
    def _bounds(cls, free: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        refusal = "only the conventional gains (vars.conventional.*) are free"
        return check_search_box(free, ("vars.conventional.",), refusal)


def all_cells(spec_split: split.Split) -> pd.DataFrame:
    """Every pendulum cell of the split with its part."""
    parts = [split.cells(spec_split, part)[0].assign(part=part) for part in split.PARTS]
    return pd.concat(parts, ignore_index=True)[["part", "table", "signal", "controller", "metric", "value"]]


def fit_hypothesis(
    spec: IdentifySpec,
    root: Path,
    hyp: hypotheses.Hypothesis,
    cells: pd.DataFrame,
    jobs: int = 1,
    start: dict[str, float] | None = None,
) -> tuple[dict[str, Any], pd.DataFrame]:
    """Fit ``hyp`` on the train cells (the GA's first population seeded with ``start``, the
    conventional gains, and the freed parameters' neutral values), then measure it on every
    cell: (summary, fit table)."""
    objective, lower, upper, seed = search(root, hyp, spec.free, cells, spec.device, start)
    t0 = time.perf_counter()
    if jobs > 1:
        with ProcessPoolExecutor(
            max_workers=jobs, mp_context=_context(spec.device), initializer=runtime.worker
        ) as pool:
            result = evolve(objective, lower, upper, spec.optimiser, pool, jobs, start=seed)
    else:
        result = evolve(objective, lower, upper, spec.optimiser, start=seed)
    values = fitted_values(objective, result)
    ours = measure_fits(TableRuns(root, list(dict.fromkeys(cells.table)), device=spec.device), [(hyp, values)], cells)
    return fitted(hyp, cells, values, result, ours[0], time.perf_counter() - t0)


def load_spec(path: Path) -> IdentifySpec:
    return validate_model(IdentifySpec, safe_yaml.load_file(path) or {}, "")


def spec_digest(spec: BaseModel, spec_split: split.Split) -> str:
    """What a finished fit depends on: the spec (but ``only``; ``warm_start`` and ``screen``
    when set, so the fits of a spec written before they existed stay valid) and the split."""
    unset = {key for key in ("warm_start", "screen") if getattr(spec, key, None) is None}
    unset |= {"device"} if getattr(spec, "device", "cpu") == "cpu" else set()  # the fits of before it existed
    exclude = {"only", "claims_top"} | unset
    text = json.dumps([spec.model_dump(exclude=exclude), spec_split.model_dump()], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def identify(
    path: Path, out_dir: Path, jobs: int = 1, root: Path | None = None, progress: Any = None, device: str | None = None
) -> pd.DataFrame:
    """Fit every hypothesis of spec ``path`` (resuming; screening the families first if the
    spec says so), write ranking.csv and the figure. ``device``: the spec's ``device`` replaced."""
    spec = load_spec(path)
    if device is not None:
        spec = spec.model_copy(update={"device": device})
    spec_split = split.load((path.parent / spec.split).resolve())
    root = root or Path("configs") / "thesis"
    cells = all_cells(spec_split)
    t0 = time.perf_counter()
    fits = Fits(spec, root, cells, out_dir / "fits", study_digest(spec_digest(spec, spec_split), root), jobs, progress)
    families = spec.families
    if spec.screen is not None:
        singles = hypotheses.family(spec.families, 1)
        fits.fit(singles)
        table = screening([fits.summary(h.name) for h in singles], spec.screen)
        report.write_csv(out_dir / "screening.csv", table)
        families = list(table.family[table.forwarded == "yes"])
    family = select(spec, hypotheses.family(families, spec.max_options))
    fits.fit(family)
    write_study(out_dir, len(fits.examined), fits.fitted_now, jobs, time.perf_counter() - t0, path)
    ranking = write_ranking(out_dir, [h.name for h in family])
    chosen = list(dict.fromkeys(["literal", str(ranking.hypothesis.iloc[0])]))
    write_definitions(out_dir, root, cells, [n for n in chosen if n in set(ranking.hypothesis)])
    return ranking if spec.claims_top is None else add_claims(out_dir, root, ranking, spec.claims_top, jobs)


def add_claims(out_dir: Path, root: Path, ranking: pd.DataFrame, top: int, jobs: int) -> pd.DataFrame:
    """The thesis's claims under the ``top`` first-ranked hypotheses and the literal loop, each
    with its fitted values (a full reproduction each, kept in claims/<hypothesis>/ and reused
    while its fitted values are unchanged): claims.csv, and claims_yes / partly / no in
    ranking.csv (empty for the others)."""
    from nlcx.thesis.reproduce import reproduce

    names = [n for n in dict.fromkeys([*ranking.hypothesis.head(top), "literal"]) if n in set(ranking.hypothesis)]
    rows = []
    for name in names:
        fitted = ranking[ranking.hypothesis == name].iloc[0]
        target = out_dir / "claims" / name
        stamp = json.dumps([fitted["options"], fitted["values"]])
        done = (target / "fit.json").is_file() and (target / "fit.json").read_text() == stamp
        if not done or not (target / "claims.csv").is_file():
            profile = profiles.Profile(
                name=name, hypothesis=json.loads(fitted["options"]), values=json.loads(fitted["values"])
            )
            reproduce(root, target, jobs=jobs, profile=profile)
            report.write_text(target / "fit.json", stamp)
        counts = pd.read_csv(target / "claims.csv").reproduced.value_counts()
        rows.append({"hypothesis": name, **{f"claims_{v}": int(counts.get(v, 0)) for v in ("yes", "partly", "no")}})
    claims = pd.DataFrame(rows, columns=["hypothesis", "claims_yes", "claims_partly", "claims_no"])
    report.write_csv(out_dir / "claims.csv", claims)
    ranking = ranking.drop(columns=[c for c in claims.columns[1:] if c in ranking]).merge(claims, how="left")
    report.write_csv(out_dir / "ranking.csv", ranking)
    return ranking


def select(spec: IdentifySpec, family: list[hypotheses.Hypothesis]) -> list[hypotheses.Hypothesis]:
    """The hypotheses of ``family`` the spec's ``only`` names (all without it)."""
    if spec.only is None:
        return family
    known = {h.name for h in family}
    missing = [n for n in spec.only if n not in known]
    if missing:
        raise ConfigError("only", missing[0], "not a hypothesis of the spec's families and max_options")
    return [h for h in family if h.name in spec.only]


class Fits:
    """The study's fits in ``fits/``: :meth:`fit` fits the hypotheses not finished under the
    spec's digest (with a warm start, the literal loop first, by the warm start's GA), and
    counts what it examined and fitted."""

    def __init__(
        self, spec: IdentifySpec, root: Path, cells: pd.DataFrame, path: Path, digest: str, jobs: int, progress: Any
    ) -> None:
        self.spec, self.root, self.cells, self.path, self.digest = spec, root, cells, path, digest
        self.jobs, self.progress = jobs, progress
        #: Every hypothesis the study has asked for (fitted now or before), in order.
        self.examined: dict[str, None] = {}
        self.fitted_now = 0
        self._start: dict[str, float] | None = None

    def summary(self, name: str) -> dict[str, Any]:
        """The finished fit of hypothesis ``name`` (fits/<name>.json)."""
        summary: dict[str, Any] = json.loads((self.path / f"{name}.json").read_text())
        return summary

    def fit(self, family: list[hypotheses.Hypothesis]) -> None:
        """Fit the hypotheses of ``family`` not yet finished (resuming)."""
        self.examined.update(dict.fromkeys(h.name for h in family))
        start = self._warm_start()
        todo = [h for h in family if not finished(self.path / f"{h.name}.json", self.digest)]
        for k, (summary, fit) in enumerate(_fits(self.spec, self.root, todo, self.cells, self.jobs, start)):
            save_fit(self.path, self.digest, summary, fit)
            self.fitted_now += 1
            if self.progress is not None:
                self.progress(len(family) - len(todo) + k + 1, len(family), summary["hypothesis"])

    def _warm_start(self) -> dict[str, float] | None:
        """The literal fit's values every GA starts from (None without a warm start); the
        literal loop is fitted first where it is not finished."""
        if self.spec.warm_start is None or self._start is not None:
            return self._start
        literal = hypotheses.Hypothesis()
        self.examined[literal.name] = None
        if not finished(self.path / f"{literal.name}.json", self.digest):
            first = self.spec.model_copy(update={"optimiser": self.spec.warm_start})
            save_fit(self.path, self.digest, *next(_fits(first, self.root, [literal], self.cells, self.jobs, None)))
            self.fitted_now += 1
        self._start = self.summary(literal.name)["values"]
        return self._start


def screening(summaries: list[dict[str, Any]], rule: Screen) -> pd.DataFrame:
    """The screening table from the fits of the literal loop and of every single option
    (``summaries``, the literal's among them): per family, its best value by train loss (ties:
    the first), that loss, the gain 1 - loss / literal loss (0 where the literal loss is 0) and
    whether the family goes forward: a gain of at least ``rule.min_gain``, among the
    ``rule.keep`` largest (ties: the families' order). Rows by gain, largest first."""
    literal = next(s["train_loss"] for s in summaries if not s["options"])
    best: dict[str, tuple[str, float]] = {}
    for s in summaries:
        for family, value in s["options"].items():
            if family not in best or s["train_loss"] < best[family][1]:
                best[family] = (value, s["train_loss"])
    rows = [
        {"family": f, "best_value": v, "train_loss": loss, "gain": 1.0 - loss / literal if literal > 0 else 0.0}
        for f, (v, loss) in best.items()
    ]
    table = pd.DataFrame(rows, columns=["family", "best_value", "train_loss", "gain"])
    table = table.sort_values("gain", ascending=False, kind="stable").reset_index(drop=True)
    passed = table.gain >= rule.min_gain
    table["forwarded"] = np.where(passed & (passed.cumsum() <= rule.keep), "yes", "no")
    return table


def finished(path: Path, digest: str) -> bool:
    return path.exists() and json.loads(path.read_text()).get("spec_digest") == digest


def save_fit(fits: Path, digest: str, summary: dict[str, Any], fit: pd.DataFrame) -> None:
    """A finished fit, atomically: the fit table first, then the summary that marks it done."""
    report.write_csv(fits / f"{summary['hypothesis']}.fit.csv", fit)
    text = json.dumps({**summary, "spec_digest": digest}, indent=2) + "\n"
    report.write_text(fits / f"{summary['hypothesis']}.json", text)


def _fits(
    spec: IdentifySpec,
    root: Path,
    todo: list[hypotheses.Hypothesis],
    cells: pd.DataFrame,
    jobs: int,
    start: dict[str, float] | None,
) -> Iterator[tuple[dict[str, Any], pd.DataFrame]]:
    """Each hypothesis's fit as it finishes: one hypothesis per worker (a fit depends only on
    its hypothesis and ``start``, so the order and the number of workers change nothing); on
    the GPU, all of them in lockstep in this process (:mod:`nlcx.thesis.lockstep`)."""
    if spec.device == "cuda":
        yield from lockstep.fits(spec.free, spec.optimiser, root, todo, cells, start)
        return
    if jobs <= 1 or len(todo) <= 1:
        for hyp in todo:
            yield fit_hypothesis(spec, root, hyp, cells, jobs, start)
        return
    with ProcessPoolExecutor(max_workers=jobs, mp_context=_context(spec.device), initializer=runtime.worker) as pool:
        futures = [pool.submit(fit_hypothesis, spec, root, hyp, cells, 1, start) for hyp in todo]
        for future in as_completed(futures):
            yield future.result()


def _context(device: str) -> Any:
    """The workers' start method: forked on the CPU; started afresh for the GPU, which a
    process that forks after using CUDA cannot hand on (each worker opens its own context)."""
    import multiprocessing

    return None if device == "cpu" else multiprocessing.get_context("spawn")


def write_definitions(out_dir: Path, root: Path, cells: pd.DataFrame, names: list[str]) -> pd.DataFrame:
    """definitions.csv: the fitted loops of ``names`` (their fitted values, unchanged)
    measured under each definition of :data:`DEFINITIONS`, scored per part."""
    runs = TableRuns(root, list(dict.fromkeys(cells.table)))
    rows = []
    for name in names:
        summary = json.loads((out_dir / "fits" / f"{name}.json").read_text())
        hyp = hypotheses.Hypothesis(tuple(summary["options"].items()))
        for label, metrics in DEFINITIONS.items():
            ours = measure_cells(runs, hyp, [summary["values"]], cells, metrics)[:, 0]
            fit = cells.rename(columns={"value": "thesis"}).assign(nlcx=ours)
            rows.append({"hypothesis": name, "definition": label, **scores(fit)})
    table = pd.DataFrame(rows)
    report.write_csv(out_dir / "definitions.csv", table)
    return table


def write_ranking(out_dir: Path, names: list[str]) -> pd.DataFrame:
    """ranking.csv (by validation median relative error) and ranking.png from the fits; the
    scores are recomputed from each fit's cells, so a change of scoring needs no refit."""
    rows = []
    for name in names:
        summary = json.loads((out_dir / "fits" / f"{name}.json").read_text())
        fit = pd.read_csv(out_dir / "fits" / f"{name}.fit.csv", dtype={"table": str})
        keep = ("hypothesis", "train_loss", "evaluations")
        rows.append(
            {**{k: summary[k] for k in keep}, **scores(fit),
             "options": json.dumps(summary["options"]), "values": json.dumps(summary["values"])}
        )  # fmt: skip
    ranking = pd.DataFrame(rows).sort_values(
        ["validation_median_rel_error", "validation_direction_agreement"], ascending=[True, False], kind="stable"
    )
    ranking.insert(0, "rank", np.arange(1, len(ranking) + 1))
    report.write_csv(out_dir / "ranking.csv", ranking)
    ranking_figure(ranking, out_dir / "ranking.png")
    write_profile(out_dir, ranking.iloc[0])
    return ranking


def write_profile(out_dir: Path, best: pd.Series) -> None:
    """profile.yaml: the hypothesis ranked first by validation, as a reproduction profile
    (``nlcx reproduce --profile``; `make identify` copies it to configs/thesis/profiles/selected.yaml)."""
    profile = {
        "name": "selected",
        "hypothesis": json.loads(best["options"]),
        "values": json.loads(best["values"]),
        "source": f"nlcx identify: {best.hypothesis}, rank 1 of the validation ranking in {out_dir.name}",
    }
    header = "# Generated by nlcx identify (the hypothesis ranked first by validation error); do not edit.\n"
    report.write_text(out_dir / "profile.yaml", header + yaml.safe_dump(profile, sort_keys=False))


def ranking_figure(ranking: pd.DataFrame, path: Path, top: int = 8) -> None:
    """Train, validation and test median relative error of the top hypotheses beside the
    literal one, as horizontal bars (the hypotheses' names are long)."""
    from nlcx.drawing import atomic_write, new_figure

    shown = pd.concat([ranking.head(top), ranking[ranking.hypothesis == "literal"]]).drop_duplicates("hypothesis")
    y = np.arange(len(shown))[::-1]
    fig, axes = new_figure(1, 1, (11.0, 1.0 + 0.55 * len(shown)))
    ax = axes[0, 0]
    for i, part in enumerate(split.PARTS):
        ax.barh(y + (1 - i) * 0.27, shown[f"{part}_median_rel_error"], height=0.27, label=part)
    ax.set_yticks(y, [f"{r}. {h.replace('+', ' + ')}" for r, h in zip(shown["rank"], shown.hypothesis, strict=True)],
                  fontsize=8)  # fmt: skip
    ax.set_xlabel("median |nlcx - thesis| / |thesis| of M_p, t_r, t_s")
    ax.set_title("Hypotheses ranked by validation error, beside the literal loop")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))

"""The identification study: hypotheses are real loop options; fits see only the train cells."""

from __future__ import annotations

import itertools
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from nlcx import config, engine
from nlcx.cli import app
from nlcx.thesis import catalog, fitting, hypotheses, profiles, split
from nlcx.thesis import identify as identify_module
from nlcx.thesis.fitting import TableRuns, direction_agreement, train_loss
from nlcx.thesis.identify import IdentifySpec, Screen, load_spec, screening
from nlcx.thesis.tables import ANGLE_METRICS, POSITION_METRICS, lookup_value, metric_lookup, rows_lookup
from nlcx.uncertainty.actuator_lag import first_order_lag

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "configs" / "thesis"
SPLIT = ROOT / "configs" / "identify" / "split.yaml"
runner = CliRunner()
GAINS = {
    "vars.conventional.angle.kp": 71.7077, "vars.conventional.angle.ki": 9.1422, "vars.conventional.angle.kd": 4.8168,
    "vars.conventional.position.kp": -9.851, "vars.conventional.position.ki": -3.6512,
    "vars.conventional.position.kd": -12.2729,
}  # fmt: skip


def built(hyp: hypotheses.Hypothesis, table: str = "2.5", **values: float) -> engine.Prepared:
    runs = TableRuns(THESIS, [table])
    return engine.prepare(runs.experiment(table, hyp, {**GAINS, **values}))


def test_the_family_is_every_combination_of_up_to_three_options() -> None:
    family = hypotheses.family(list(hypotheses.FAMILIES)[:11], 3)
    names = [h.name for h in family]
    assert names[0] == "literal" and len(names) == len(set(names)) == 508  # 1 + 15 + 100 + 392
    assert all(len(h.options) <= 3 for h in family)
    assert all(len({f for f, _ in h.options}) == len(h.options) for h in family)  # one value per family


def test_the_study_screens_every_family_within_the_former_studys_fits() -> None:
    """Whichever families the screen forwards, the study fits no more hypotheses than the
    former study of every combination of up to three of the first 11 families (508)."""
    spec = load_spec(ROOT / "configs" / "identify" / "pendulum_all.yaml")
    final_round = ("conventional_gains", "z_schedule", "rise_time")  # the final round's own families
    assert spec.families == [f for f in hypotheses.FAMILIES if f not in final_round] and len(spec.families) == 20
    assert spec.screen is not None and spec.screen.keep <= 8 and spec.screen.min_gain == 0.05
    screened = {h.name for h in hypotheses.family(spec.families, 1)}
    assert len(screened) == 31  # the literal loop and the 30 single values
    # the largest combination: the ``keep`` families with the most values (any tie gives the same count)
    widest = sorted(spec.families, key=lambda f: len(hypotheses.FAMILIES[f]), reverse=True)[: spec.screen.keep]
    combined = {h.name for h in hypotheses.family(widest, spec.max_options)}
    counts = [len(hypotheses.FAMILIES[f]) - 1 for f in widest]
    pairs = sum(a * b for a, b in itertools.combinations(counts, 2))
    triples = sum(a * b * c for a, b, c in itertools.combinations(counts, 3))
    assert len(combined) == 1 + sum(counts) + pairs + triples
    assert len(screened | combined) <= 508


def test_the_screen_forwards_the_largest_gains_above_the_least_at_most_keep() -> None:
    def fit(loss: float, **options: str) -> dict[str, Any]:
        return {"options": options, "train_loss": loss}

    summaries = [
        fit(2.0),
        fit(1.5, derivative="filtered"), fit(1.0, derivative="measurement"),  # best 1.0: gain 0.5
        fit(1.96, integral="inside"),  # gain 0.02 < 0.05
        fit(1.0, form="ideal"), fit(1.2, form="series"),  # 0.5, tied with derivative: family order
        fit(2.5, lag="first_order"),  # worse than the literal fit
        fit(1.9, units="degrees"),  # 0.05: passes, but beyond keep
    ]  # fmt: skip
    table = screening(summaries, Screen(keep=2, min_gain=0.05))
    assert list(table.family) == ["derivative", "form", "units", "integral", "lag"]
    assert list(table.best_value) == ["measurement", "ideal", "degrees", "inside", "first_order"]
    assert np.allclose(table.gain, [0.5, 0.5, 0.05, 0.02, -0.25]) and list(table.train_loss)[:2] == [1.0, 1.0]
    assert list(table.forwarded) == ["yes", "yes", "no", "no", "no"]
    assert list(screening(summaries, Screen(keep=5, min_gain=0.05)).forwarded) == ["yes"] * 3 + ["no"] * 2
    assert set(screening(summaries, Screen(keep=5, min_gain=0.6)).forwarded) == {"no"}
    assert list(screening([fit(0.0), fit(0.0, lag="first_order")], Screen(keep=1, min_gain=0.0)).gain) == [0.0]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"screen": {"keep": 0, "min_gain": 0.05}}, "screen.keep = 0"),
        ({"screen": {"keep": 2}}, "screen.min_gain"),
        ({"screen": {"keep": 2, "min_gain": 0.05}, "only": ["literal"]}, "only and screen exclude each other"),
    ],
)
def test_a_bad_screen_is_refused_in_one_line(tmp_path: Path, change: dict, message: str) -> None:
    raw = yaml.safe_load(_spec(tmp_path, SPLIT).read_text())
    del raw["only"]
    raw |= change
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(raw))
    result = runner.invoke(app, ["identify", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and message in result.output and len(result.output.strip().splitlines()) == 1


def test_literal_is_the_experiment_as_configured() -> None:
    ours = built(hypotheses.Hypothesis())
    default = engine.prepare(config.load(THESIS / "ch2" / "fig_2_17.yaml"))
    for a, b in zip(ours.controllers, default.controllers, strict=True):
        assert np.array_equal(a.cp, b.cp)


def test_options_reach_the_controllers_as_loop_settings() -> None:
    hyp = hypotheses.Hypothesis((("ordering", "magnitude"), ("derivative", "filtered"), ("saturation", "clamping")))
    prep = built(hyp, F_max=7.5)
    proposed = next(c for c in prep.controllers if c.label == "proposed").config
    assert proposed["loops"]["x"]["schedule"]["kp"] == {"min": -2.4, "max": -3.0}  # |min| < |max|
    assert proposed["loops"]["theta"]["schedule"]["kp"] == {"min": 24.0, "max": 36.0}  # positive: unchanged
    assert proposed["derivative"]["method"] == "filtered" and proposed["derivative"]["N"] == 100.0
    assert proposed["saturation"] == {"limits": {"F_x": 7.5}, "anti_windup": "clamping", "kb": 1.0}
    signed = built(hypotheses.Hypothesis((("ags_error", "signed"), ("integral", "inside"))))
    proposed = next(c for c in signed.controllers if c.label == "proposed").config
    assert proposed["loops"]["x"]["schedule"]["error"] == "signed" and proposed["integral"] == "inside"
    assert hyp.free() == {"F_max": (2.0, 100.0)}
    loop = hypotheses.Hypothesis((("lag", "first_order"), ("prefilter", "first_order")))
    prep = built(loop, tau=0.05, T_f=0.4)
    assert [(e.hook, e.function) for e in prep.hooks.elements] == [("actuator", first_order_lag)]
    _, cfg = prep.references["x"]
    assert cfg.kind == "filtered_step" and cfg.time_constant == 0.4 and cfg.final == 1.0
    assert loop.free() == {"tau": (0.001, 0.3), "T_f": (0.01, 3.0)}


def test_train_loss_is_the_mean_squared_relative_residual_with_floors() -> None:
    cells = pd.DataFrame({"metric": ["Mp", "tr", "ts"], "value": [0.0, 2.0, 4.0]})
    ours = np.array([[0.1, np.nan], [2.5, 2.0], [4.0, 4.0]])
    loss = train_loss(ours, cells)
    assert np.isclose(loss[0], ((0.1 / 0.05) ** 2 + 0.25**2 + 0.0) / 3)
    assert np.isclose(loss[1], (10.0**2 + 0 + 0) / 3)  # an undefined metric costs 10


def test_direction_agreement_counts_signs_of_proposed_minus_conventional() -> None:
    rows = pd.DataFrame(
        [
            ("2.3", "x", "Mp", "conventional", 0.5, 0.4),
            ("2.3", "x", "Mp", "proposed", 0.2, 0.3),  # both better: agrees
            ("2.3", "x", "tr", "conventional", 2.0, 1.0),
            ("2.3", "x", "tr", "proposed", 2.1, 0.9),  # thesis worse, ours better: disagrees
            ("2.3", "x", "ts", "conventional", 3.0, 3.0),
            ("2.3", "x", "ts", "proposed", 3.0, 2.0),  # printed equal: not comparable
        ],
        columns=["table", "signal", "metric", "controller", "thesis", "nlcx"],
    )
    assert direction_agreement(rows) == 0.5


def _spec(tmp_path: Path, split: Path) -> Path:
    raw = {
        "name": "tiny",
        "split": str(split),
        "families": ["saturation"],
        "max_options": 1,
        "only": ["literal", "saturation=back_calculation"],
        "free": {k: [v * 0.8, v * 1.2] if v > 0 else [v * 1.2, v * 0.8] for k, v in GAINS.items()}
        | {"vars.conventional.z.kp": [60, 100], "vars.conventional.z.ki": [20, 30], "vars.conventional.z.kd": [25, 35]},
        "optimiser": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 3},
        "claims_top": None,
    }
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


@pytest.mark.slow
def test_a_study_stopped_part_way_resumes_in_its_own_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A study that stops after its first fit (an error, as Ctrl-C would) leaves its directory
    listed in its manifest: the rerun resumes there, fitting only what is left, and refuses
    nothing it wrote itself."""
    spec, out = _spec(tmp_path, SPLIT), tmp_path / "out"
    real = identify_module.save_fit
    saved: list[str] = []

    def save_then_stop(fits: Path, digest: str, summary: dict[str, Any], fit: pd.DataFrame) -> None:
        real(fits, digest, summary, fit)
        saved.append(summary["hypothesis"])
        raise RuntimeError("stopped")

    monkeypatch.setattr(identify_module, "save_fit", save_then_stop)
    stopped = runner.invoke(app, ["identify", str(spec), "--out", str(out)])
    assert stopped.exit_code != 0 and len(saved) == 1
    monkeypatch.setattr(identify_module, "save_fit", real)
    fitted = _counting_fits(monkeypatch)
    resumed = runner.invoke(app, ["identify", str(spec), "--out", str(out)])
    assert resumed.exit_code == 0, resumed.output
    assert saved[0] not in fitted and len(fitted) == 1  # the stopped run's fit is kept
    (out / "foreign.txt").write_text("not nlcx's")
    refused = runner.invoke(app, ["identify", str(spec), "--out", str(out)])
    assert refused.exit_code != 0 and "foreign.txt" in refused.output  # someone else's file still refused


def test_a_study_digest_follows_the_spec_the_source_and_the_configs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A task a study finished is taken over only by the same spec, nlcx source and thesis
    configs; the selected profile, which `make identify` writes there, is not an input."""
    (tmp_path / "profiles").mkdir()
    (tmp_path / "x.yaml").write_text("a: 1\n")
    first = fitting.study_digest("spec", tmp_path)
    assert fitting.study_digest("spec", tmp_path) == first and fitting.study_digest("other", tmp_path) != first
    (tmp_path / "profiles" / "selected.yaml").write_text("name: selected\n")
    fitting._code_digest.cache_clear()
    assert fitting.study_digest("spec", tmp_path) == first
    (tmp_path / "x.yaml").write_text("a: 2\n")
    fitting._code_digest.cache_clear()
    changed_config = fitting.study_digest("spec", tmp_path)
    monkeypatch.setattr(fitting, "source_digest", lambda: "another nlcx")
    fitting._code_digest.cache_clear()
    assert len({first, changed_config, fitting.study_digest("spec", tmp_path)}) == 3
    fitting._code_digest.cache_clear()


@pytest.mark.slow
def test_a_study_is_done_again_by_another_nlcx_source(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Rerun after nlcx's source changed, a study fits every hypothesis again instead of resuming
    from fits the older source made (the same source resumes and fits none)."""
    spec, out = _spec(tmp_path, SPLIT), tmp_path / "out"
    assert runner.invoke(app, ["identify", str(spec), "--out", str(out)]).exit_code == 0
    fitted = _counting_fits(monkeypatch)
    assert runner.invoke(app, ["identify", str(spec), "--out", str(out)]).exit_code == 0
    assert fitted == []
    monkeypatch.setattr(fitting, "source_digest", lambda: "another nlcx")
    fitting._code_digest.cache_clear()
    try:
        again = runner.invoke(app, ["identify", str(spec), "--out", str(out)])
    finally:
        fitting._code_digest.cache_clear()
    assert again.exit_code == 0, again.output
    assert len(fitted) == 2  # both hypotheses of the spec


#: Runs `nlcx identify` with SIGTERM sent to itself right after its first fit is saved, as a
#: batch scheduler's time limit would end it.
TERMINATED_AFTER_FIRST_FIT = """
import os, signal, sys
from nlcx.thesis import identify
real = identify.save_fit
def save_then_terminate(*args):
    real(*args)
    os.kill(os.getpid(), signal.SIGTERM)
identify.save_fit = save_then_terminate
from nlcx.cli import main
main()
"""


@pytest.mark.slow
def test_a_terminated_study_resumes_in_its_own_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGTERM after the first fit ends `nlcx identify` as Ctrl-C would: one line, exit 143, its
    directory listed in its manifest, so that the rerun resumes there with the fit kept."""
    spec, out = _spec(tmp_path, SPLIT), tmp_path / "out"
    command = [sys.executable, "-c", TERMINATED_AFTER_FIRST_FIT, "identify", str(spec), "--out", str(out)]
    stopped = subprocess.run(command, capture_output=True, text=True, timeout=900)
    assert stopped.returncode == 143, stopped.stderr
    assert stopped.stderr.splitlines()[-1].startswith("terminated: ")
    fitted = _counting_fits(monkeypatch)
    resumed = runner.invoke(app, ["identify", str(spec), "--out", str(out)])
    assert resumed.exit_code == 0, resumed.output
    assert len(fitted) == 1  # of the spec's two hypotheses, only the one the stopped run left


@pytest.mark.slow
def test_identify_fits_on_train_only_ranks_on_validation_and_resumes(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = runner.invoke(app, ["identify", str(_spec(tmp_path, SPLIT)), "--out", str(out)])
    assert result.exit_code == 0, result.output
    ranking = pd.read_csv(out / "ranking.csv")
    assert set(ranking.hypothesis) == {"literal", "saturation=back_calculation"}
    assert list(ranking.validation_median_rel_error) == sorted(ranking.validation_median_rel_error)
    assert (out / "ranking.png").stat().st_size > 0
    definitions = pd.read_csv(out / "definitions.csv")  # measurement side, reported apart
    default = definitions[definitions.definition.str.endswith("(nlcx)") & (definitions.hypothesis == "literal")]
    literal = ranking[ranking.hypothesis == "literal"]
    for column in ("train_median_rel_error", "validation_median_rel_error", "test_median_rel_error"):
        assert default[column].item() == literal[column].item()
    assert len(set(definitions.definition)) == 4
    profile = profiles.load(str(out / "profile.yaml"), THESIS)  # rank 1 as a reproduction profile
    assert profile.as_hypothesis().name == ranking.hypothesis.iloc[0]
    assert set(profile.values) >= {"vars.conventional.angle.kp", "vars.conventional.z.kd"}
    fit = pd.read_csv(out / "fits" / "literal.fit.csv", dtype={"table": str})
    assert set(fit[fit.part == "train"].table) == {"2.3", "2.5", "3.7"}
    first = json.loads((out / "fits" / "literal.json").read_text())
    # a second run resumes: the finished fits are not redone
    stamp = (out / "fits" / "literal.json").stat().st_mtime_ns
    assert runner.invoke(app, ["identify", str(_spec(tmp_path, SPLIT)), "--out", str(out)]).exit_code == 0
    assert (out / "fits" / "literal.json").stat().st_mtime_ns == stamp
    # moving a validation table to test changes nothing the fit saw: same values, same loss
    moved = yaml.safe_load(SPLIT.read_text())
    moved["pendulum"]["validation"].remove("2.4")
    moved["pendulum"]["test"].append("2.4")
    other = tmp_path / "other_split.yaml"
    other.write_text(yaml.safe_dump(moved))
    out2 = tmp_path / "out2"
    assert runner.invoke(app, ["identify", str(_spec(tmp_path, other)), "--out", str(out2)]).exit_code == 0
    second = json.loads((out2 / "fits" / "literal.json").read_text())
    assert second["values"] == first["values"] and second["train_loss"] == first["train_loss"]
    moved_fit = pd.read_csv(out2 / "fits" / "literal.fit.csv", dtype={"table": str})
    assert set(moved_fit[moved_fit.table == "2.4"].part) == {"test"}  # scored, as test, not fitted


def _screened_spec(tmp_path: Path, families: list[str], keep: int, max_options: int) -> Path:
    """The tiny spec, its families screened (every gain >= 0 passes; at most ``keep``), the
    literal loop fitted first and every GA started from it."""
    raw = yaml.safe_load(_spec(tmp_path, SPLIT).read_text())
    del raw["only"]
    raw |= {"families": families, "max_options": max_options, "screen": {"keep": keep, "min_gain": 0.0}}
    raw |= {"warm_start": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 2}}
    path = tmp_path / "screened.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def _counting_fits(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The hypotheses fitted from now on, in order (the study fits in this process: one job)."""
    fitted: list[str] = []
    real = identify_module.fit_hypothesis

    def counted(
        spec: IdentifySpec, root: Path, hyp: hypotheses.Hypothesis, *args: Any, **kwargs: Any
    ) -> tuple[dict[str, Any], pd.DataFrame]:
        fitted.append(hyp.name)
        return real(spec, root, hyp, *args, **kwargs)

    monkeypatch.setattr(identify_module, "fit_hypothesis", counted)
    return fitted


@pytest.mark.slow
def test_the_screen_forwards_by_train_loss_reuses_its_fits_and_resumes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = _screened_spec(tmp_path, ["derivative", "integral", "prefilter", "sampling"], keep=2, max_options=2)
    fitted = _counting_fits(monkeypatch)
    out = tmp_path / "out"
    identify_module.identify(spec, out, root=THESIS)
    fits = {p.stem: json.loads(p.read_text()) for p in (out / "fits").glob("*.json")}
    # the screening table, recomputed from the single fits: best value per family (ties: the
    # first of its values), its gain, the rule
    literal = fits["literal"]["train_loss"]
    best: dict[str, tuple[float, str]] = {}
    for hyp in hypotheses.family(["derivative", "integral", "prefilter", "sampling"], 1)[1:]:
        ((family, value),) = hyp.options
        if fits[hyp.name]["train_loss"] < best.get(family, (math.inf, ""))[0]:
            best[family] = (fits[hyp.name]["train_loss"], value)
    table = pd.read_csv(out / "screening.csv")
    assert set(table.family) == {"derivative", "integral", "prefilter", "sampling"}
    for row in table.itertuples():
        assert (row.train_loss, row.best_value) == best[row.family]
        assert math.isclose(row.gain, 1 - row.train_loss / literal)
    assert list(table.gain) == sorted(table.gain, reverse=True)
    forwarded = [f for f, g in zip(table.family, table.gain, strict=True) if g >= 0.0][:2]
    assert list(table.family[table.forwarded == "yes"]) == forwarded
    assert set(table.forwarded) == {"yes", "no"}  # the screen dropped a family
    # the forwarded families' combinations are ranked; every hypothesis was fitted once
    family = [h.name for h in hypotheses.family(forwarded, 2)]
    assert sorted(pd.read_csv(out / "ranking.csv").hypothesis) == sorted(family)
    singles = [h.name for h in hypotheses.family(table.family.tolist(), 1)]
    assert sorted(fitted) == sorted(set(singles) | set(family)) == sorted(fits)
    assert json.loads((out / "study.json").read_text())["hypotheses"] == len(fits)
    # a study killed before its last fit resumes: that fit only, the same ranking
    ranking = (out / "ranking.csv").read_bytes()
    (out / "fits" / f"{family[-1]}.json").unlink()
    fitted.clear()
    identify_module.identify(spec, out, root=THESIS)
    assert fitted == [family[-1]]
    assert (out / "ranking.csv").read_bytes() == ranking  # byte for byte


@pytest.mark.slow
def test_the_test_tables_change_no_fit_no_screen_no_ranking_and_no_profile(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every printed value of the test tables doubled: the fits, the screening, the ranking and
    the selected profile are those of the thesis's values; only the test scores move."""
    spec = _screened_spec(tmp_path, ["derivative", "prefilter"], keep=1, max_options=1)
    test_tables = split.load(SPLIT).pendulum.test
    printed = catalog.thesis_metrics()
    doubled = printed.assign(value=printed.value.where(~printed.table.isin(test_tables), 2 * printed.value))
    changed = doubled.value != printed.value
    assert changed.equals(printed.table.isin(test_tables) & (printed.value != 0)) and changed.sum() > 100
    runs = {}
    for name, table in (("printed", printed), ("doubled", doubled)):
        monkeypatch.setattr(catalog, "thesis_metrics", lambda table=table: table)
        out = tmp_path / name / "out"
        runs[name] = identify_module.identify(spec, out, root=THESIS)
    a, b = (tmp_path / name / "out" for name in runs)
    for path in (a / "fits").glob("*.json"):
        ours, theirs = json.loads(path.read_text()), json.loads((b / "fits" / path.name).read_text())
        assert (ours["values"], ours["train_loss"]) == (theirs["values"], theirs["train_loss"]), path.stem
    assert sorted(p.name for p in (a / "fits").glob("*.json")) == sorted(p.name for p in (b / "fits").glob("*.json"))
    assert (a / "screening.csv").read_bytes() == (b / "screening.csv").read_bytes()
    assert (a / "profile.yaml").read_bytes() == (b / "profile.yaml").read_bytes()
    first, second = runs["printed"], runs["doubled"]
    assert list(first.hypothesis) == list(second.hypothesis)
    for column in [c for c in first.columns if c.startswith(("train_", "validation_"))]:
        assert first[column].equals(second[column]), column
    assert not first.test_median_rel_error.equals(second.test_median_rel_error)  # the doubling was seen


@pytest.mark.slow
def test_the_test_tables_change_nothing_the_final_round_decides(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The final round's own spec (configs/identify/final_round.yaml) with a tiny GA and four of
    its hypotheses: with every printed value of the test tables doubled, its fits, its ranking
    and its rule's decision are those of the thesis's values; only the test scores move."""
    raw = yaml.safe_load((ROOT / "configs" / "identify" / "final_round.yaml").read_text())
    first = "theta_settling=absolute+z_loop=no_feedforward_printed+integrator_limit=position"
    raw |= {"split": str(SPLIT), "claims_top": None, "only": ["literal", first, "conventional_gains=own_with_z",
            f"{first}+z_schedule=rate_free"], "warm_start": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 1},
            "optimiser": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 1}}  # fmt: skip
    spec = tmp_path / "final_round.yaml"
    spec.write_text(yaml.safe_dump(raw))
    test_tables = split.load(SPLIT).pendulum.test
    printed = catalog.thesis_metrics()
    doubled = printed.assign(value=printed.value.where(~printed.table.isin(test_tables), 2 * printed.value))
    runs = {}
    for name, table in (("printed", printed), ("doubled", doubled)):
        monkeypatch.setattr(catalog, "thesis_metrics", lambda table=table: table)
        runs[name] = identify_module.identify(spec, tmp_path / name / "out", root=THESIS)
    a, b = (tmp_path / name / "out" for name in runs)
    for path in (a / "fits").glob("*.json"):
        ours, theirs = json.loads(path.read_text()), json.loads((b / "fits" / path.name).read_text())
        assert (ours["values"], ours["train_loss"]) == (theirs["values"], theirs["train_loss"]), path.stem
    first_run, second_run = runs["printed"], runs["doubled"]
    assert list(first_run.hypothesis) == list(second_run.hypothesis)
    for column in [c for c in first_run.columns if c.startswith(("train_", "validation_"))]:
        assert first_run[column].equals(second_run[column]), column

    def decision(ranking: pd.DataFrame) -> bool:
        return profiles.final_round_selects(ranking.iloc[0], ranking[ranking.hypothesis == first].iloc[0])

    assert decision(first_run) == decision(second_run)
    assert (a / "profile.yaml").read_bytes() == (b / "profile.yaml").read_bytes()
    assert not first_run.test_median_rel_error.equals(second_run.test_median_rel_error)  # the doubling was seen


def test_a_diverged_cell_counts_as_a_failure_not_as_missing() -> None:
    from nlcx.thesis.fitting import scores

    fit = pd.DataFrame(
        {
            "part": ["validation"] * 3,
            "table": ["2.4"] * 3,
            "signal": ["x"] * 3,
            "controller": ["conventional"] * 3,
            "metric": ["Mp", "tr", "ts"],
            "thesis": [0.5, 2.0, 4.0],
            "nlcx": [0.5, np.nan, np.nan],
        }
    )
    got = scores(fit)
    assert got["validation_median_rel_error"] == np.inf and got["validation_measured_share"] == 1 / 3
    assert got["validation_conventional_Mp_median_rel_error"] == 0.0  # per controller and metric
    assert got["validation_conventional_tr_median_rel_error"] == np.inf


@pytest.mark.slow
def test_a_warm_start_seeds_the_first_population_and_the_fit_never_loses_to_it(tmp_path: Path) -> None:
    """With warm_start, each hypothesis's GA starts from the literal fit (the freed T_s at its
    neutral 1 ms = dt, which is the literal loop): elitism keeps its train loss <= the literal's.
    Workers fit one hypothesis each; the fits equal the serial ones."""
    raw = yaml.safe_load(_spec(tmp_path, SPLIT).read_text())
    raw |= {"families": ["sampling", "saturation"], "only": ["literal", "sampling=discrete", "saturation=plain"]}
    raw |= {"warm_start": {"kind": "ga", "pop_size": 6, "generations": 2, "seed": 2}}
    spec = tmp_path / "warm.yaml"
    spec.write_text(yaml.safe_dump(raw))
    for out, jobs in ((tmp_path / "serial", "1"), (tmp_path / "pool", "2")):
        assert runner.invoke(app, ["identify", str(spec), "--out", str(out), "--jobs", jobs]).exit_code == 0
    fits = {name: json.loads((tmp_path / "serial" / "fits" / f"{name}.json").read_text()) for name in raw["only"]}
    literal = fits["literal"]
    assert literal["evaluations"] == 12  # the warm start's GA, not the spec's (4 x 1)
    for name in ("sampling=discrete", "saturation=plain"):
        assert fits[name]["train_loss"] <= literal["train_loss"] + 1e-12
        pooled = json.loads((tmp_path / "pool" / "fits" / f"{name}.json").read_text())
        assert pooled["values"] == fits[name]["values"] and pooled["train_loss"] == fits[name]["train_loss"]


def test_the_first_population_is_the_start_then_seeded_draws_in_the_box() -> None:
    from nlcx.tuning.optimise import GASettings, _first_population

    lower, upper = np.array([0.0, -1.0]), np.array([1.0, 1.0])
    settings = GASettings(pop_size=5, seed=4)
    pop = _first_population(np.array([[0.5, 3.0]]), lower, upper, settings)
    assert pop.shape == (5, 2) and list(pop[0]) == [0.5, 1.0]  # clipped into the box
    assert np.all((pop >= lower) & (pop <= upper))
    assert np.array_equal(pop, _first_population(np.array([[0.5, 3.0]]), lower, upper, settings))


def test_claims_come_from_a_reproduction_under_each_top_fit_and_are_reused(tmp_path: Path, monkeypatch) -> None:
    """add_claims reproduces the thesis under the top fits (options and fitted values as a
    profile) and the literal loop, merges the counts into ranking.csv, and reuses them."""
    import nlcx.thesis.reproduce as reproduce_module
    from nlcx.thesis.identify import add_claims

    calls = []

    def fake_reproduce(root: Path, out: Path, jobs: int, profile: profiles.Profile) -> None:
        calls.append(profile)
        verdicts = ["yes"] * (3 + len(calls)) + ["no"] * 2
        out.mkdir(parents=True, exist_ok=True)
        pd.DataFrame({"reproduced": verdicts}).to_csv(out / "claims.csv", index=False)

    monkeypatch.setattr(reproduce_module, "reproduce", fake_reproduce)
    ranking = pd.DataFrame(
        {
            "hypothesis": ["saturation=plain", "lag=first_order", "literal"],
            "options": ['{"saturation": "plain"}', '{"lag": "first_order"}', "{}"],
            "values": ['{"F_max": 9.0}', '{"tau": 0.02}', '{"vars.conventional.angle.kp": 70.0}'],
        }
    )
    out = add_claims(tmp_path, THESIS, ranking, 1, 1)
    assert [(p.hypothesis, p.values) for p in calls] == [
        ({"saturation": "plain"}, {"F_max": 9.0}),
        ({}, {"vars.conventional.angle.kp": 70.0}),
    ]
    assert list(out.claims_yes.fillna(-1)) == [4, -1, 5] and list(out.claims_no.fillna(-1)) == [2, -1, 2]
    assert pd.read_csv(tmp_path / "ranking.csv").claims_yes.iloc[0] == 4
    add_claims(tmp_path, THESIS, ranking, 1, 1)
    assert len(calls) == 2  # unchanged fits: the reproductions are reused


def test_the_cell_lookup_reads_what_a_filter_of_the_metrics_reads() -> None:
    """Every thesis (controller, signal, metric) read through the one-pass lookup equals the
    first matching row of a boolean filter of the run's metrics (M_p of a position: overshoot
    / 100; a metric the thesis does not define, or a missing signal: NaN). The lookup of the
    rows themselves, without the DataFrame, is the same, a missing value NaN as in the frame."""
    result = engine.evaluate([built(hypotheses.Hypothesis())])[0]
    metrics = result.metrics
    values = metric_lookup(metrics)
    from_rows = rows_lookup(result.metric_rows)
    assert list(from_rows) == list(values)
    assert all(from_rows[k] == v or (math.isnan(from_rows[k]) and math.isnan(v)) for k, v in values.items())
    assert math.isnan(rows_lookup([["c", "x", "overshoot", None, "%", "ok", ""]])["c", "x", "overshoot"])
    checked = 0
    for controller in ("conventional", "proposed", "absent"):
        for signal in ("x", "theta", "nowhere"):
            for metric in ("Mp", "tr", "ts", "ess", "IAE"):
                name = (ANGLE_METRICS if signal == "theta" else POSITION_METRICS).get(metric)
                match = (metrics.controller == controller) & (metrics.signal == signal) & (metrics.metric == name)
                scale = 100.0 if name == "overshoot" else 1.0
                expected = math.nan if not match.any() else float(metrics[match].value.iloc[0]) / scale
                ours = lookup_value(values, controller, signal, metric)
                assert ours == expected or (math.isnan(ours) and math.isnan(expected)), (controller, signal, metric)
                checked += not math.isnan(expected)
    assert checked == 14  # both controllers: M_p, t_r, t_s, e_ss of x and M_p, t_s, e_ss of theta


#: Hypotheses whose free values land in every train table's arrays, and one (a first-order
#: actuator lag, whose time constant enters its element's parameters transformed) that does not.
PACKED_CASES = ["literal", "saturation=back_calculation", "z_loop=printed", "lag=first_order"]


@pytest.mark.parametrize("name", PACKED_CASES)
def test_a_population_packed_into_prepared_tables_gives_each_candidate_s_own_cells(name: str) -> None:
    """The objective prepares each train table once and packs the population into its arrays;
    its losses are those of every candidate's own experiments (:func:`measure_cells`), bit for
    bit, at the corners of the box and inside it, diverged runs included."""
    spec = load_spec(ROOT / "configs" / "identify" / "pendulum_all.yaml")
    cells = identify_module.all_cells(split.load(SPLIT))
    train = cells[cells.part == "train"].reset_index(drop=True)
    hyp = next(h for h in hypotheses.family(spec.families, 1) if h.name == name)
    box = {**spec.free, **hyp.free()}
    objective = fitting.FitObjective(THESIS, hyp, box, train)
    lower, upper = (np.array([b[i] for b in box.values()]) for i in (0, 1))
    X = np.vstack([lower, upper, np.random.default_rng(3).uniform(lower, upper, size=(6, len(box)))])
    packing = objective.packing()
    packed = [t for t, p in packing.items() if not isinstance(p, str)]
    if name == "lag=first_order":
        assert not packed and all("tau: it is not packed as itself" in p for p in packing.values()), packing
    else:
        assert packed == list(dict.fromkeys(train.table)), packing
    candidates = [dict(zip(box, map(float, x), strict=True)) for x in X]
    own = fitting.measure_cells(TableRuns(THESIS, list(dict.fromkeys(train.table))), hyp, candidates, train)
    assert np.isnan(own).any()  # cells of diverged runs or undefined metrics among those compared
    assert np.array_equal(objective(X), train_loss(own, train))


@pytest.mark.slow
def test_fits_in_lockstep_are_the_fits_alone(tmp_path: Path) -> None:
    """The GPU's way of fitting (every hypothesis's GA stepped side by side, each generation's
    populations measured together, the fitted loops measured together) gives each hypothesis
    the fit it gets alone, bit for bit (here on the CPU, where the GPU's share is the kernel)."""
    from nlcx.thesis import lockstep
    from nlcx.tuning.optimise import GASettings

    spec = load_spec(_spec(tmp_path, SPLIT)).model_copy(
        update={"optimiser": GASettings(pop_size=4, generations=2, seed=5)}
    )
    cells = identify_module.all_cells(split.load(SPLIT))
    family = [h for h in hypotheses.family(["saturation", "z_loop"], 1) if h.name != "lag=first_order"]
    start = {k: (lo + hi) / 2 for k, (lo, hi) in spec.free.items()}
    together = list(lockstep.fits(spec.free, spec.optimiser, THESIS, family, cells, start, device="cpu"))
    assert [s["hypothesis"] for s, _ in together] == [h.name for h in family] and len(family) >= 3
    for (summary, fit), hyp in zip(together, family, strict=True):
        own_summary, own_fit = identify_module.fit_hypothesis(spec, THESIS, hyp, cells, 1, start)
        same = [json.dumps({**s, "wall_s": 0}, sort_keys=True) for s in (summary, own_summary)]
        assert same[0] == same[1], hyp.name  # NaN scores included
        pd.testing.assert_frame_equal(fit, own_fit)

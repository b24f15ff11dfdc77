"""Chapter 5's identification study: options reach every Table 5.8 experiment, the ZN row is
the only train row, and a profile's chapter-5 part reaches the chapter-5 experiments only."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from typer.testing import CliRunner

from nlcx import config, engine
from nlcx.cli import app
from nlcx.thesis import hypotheses, profiles
from nlcx.thesis.identify_cstr import MethodRuns
from nlcx.uncertainty.actuator_saturation import saturate_inputs

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "configs" / "thesis"
runner = CliRunner()


def test_chapter5_options_reach_the_tuners_the_pid_and_the_loop() -> None:
    hyp = hypotheses.Hypothesis(
        (("zn_rule", "pessen"), ("cstr_derivative", "filtered_n10"), ("actuator_limit", "saturated"))
    )
    exp = MethodRuns(THESIS, ["ANFIS"]).experiment("ANFIS", hyp, {"u_max": 2.0})
    anfis = exp.resolved()["controllers"]["anfis"]
    assert anfis["tune"][0]["rule"] == "pessen"
    assert anfis["derivative"] == {"method": "filtered", "N": 10, "on": "error"}
    prep = engine.prepare(exp)
    assert [(e.hook, e.function) for e in prep.hooks.elements] == [("actuator", saturate_inputs)]
    assert hyp.free() == {"u_max": (0.1, 20.0)}


def _zn_metrics(hyp: hypotheses.Hypothesis) -> pd.DataFrame:
    (result,) = engine.evaluate([MethodRuns(THESIS, ["ZN"]).experiment("ZN", hyp, {})], record_logs=False)
    return result.metrics.set_index(["controller", "signal", "metric"]).value


def test_the_model_read_in_seconds_is_the_same_loop_sixty_times_slower() -> None:
    """G(s) -> G(60 s) with t_end and dt x 60: ZN's K_u is unchanged and T_u x 60, so the loop
    is the same in scaled time: every time x 60, M_p unchanged (to the integration's rounding)."""
    minutes = _zn_metrics(hypotheses.Hypothesis())
    seconds = _zn_metrics(hypotheses.Hypothesis((("time_unit", "seconds"),)))
    for metric in ("rise_time", "settling_time", "peak_time"):
        np.testing.assert_allclose(seconds["zn", "C_B", metric], 60 * minutes["zn", "C_B", metric], rtol=1e-9)
    np.testing.assert_allclose(seconds["zn", "C_B", "overshoot"], minutes["zn", "C_B", "overshoot"], rtol=1e-9)


def test_a_small_step_on_the_nonlinear_reactor_is_near_its_transfer_function() -> None:
    """The transfer function 5.10 is the reactor linearised at its operating point: a 0.05 gmol/L
    step about C_Bs gives nearly the same ZN loop (M_p within 10 %, t_r within 15 %)."""
    linear = _zn_metrics(hypotheses.Hypothesis())
    reactor = _zn_metrics(hypotheses.Hypothesis((("reactor", "nonlinear"),)))
    assert abs(reactor["zn", "C_B", "overshoot"] / linear["zn", "C_B", "overshoot"] - 1) < 0.25
    assert abs(reactor["zn", "C_B", "rise_time"] / linear["zn", "C_B", "rise_time"] - 1) < 0.3


def test_identify_chapter5_fits_on_the_zn_row_and_writes_a_chapter5_profile(tmp_path: Path) -> None:
    spec = {
        "name": "tiny5",
        "chapter": 5,
        "split": str(ROOT / "configs" / "identify" / "split.yaml"),
        "families": ["actuator_limit"],
        "max_options": 1,
        "optimiser": {"kind": "ga", "pop_size": 4, "generations": 1, "seed": 2},
    }
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    result = runner.invoke(app, ["identify", str(path), "--out", str(out), "--jobs", "2"])
    assert result.exit_code == 0, result.output
    ranking = pd.read_csv(out / "ranking.csv")
    assert set(ranking.hypothesis) == {"literal", "actuator_limit=saturated"}
    assert list(ranking.train_loss) == sorted(ranking.train_loss)
    fit = pd.read_csv(out / "fits" / "actuator_limit=saturated.fit.csv")
    assert set(fit[fit.part == "train"].method) == {"ZN"}
    assert set(fit[fit.part == "test"].method) == {"Fuzzy", "ANN", "ANFIS", "GA"}
    fitted = json.loads((out / "fits" / "actuator_limit=saturated.json").read_text())["values"]
    assert 0.1 <= fitted["u_max"] <= 20.0
    profile = yaml.safe_load((out / "profile.yaml").read_text())
    assert profile["chapter5"]["hypothesis"] == json.loads(ranking.options.iloc[0])
    stamp = (out / "fits" / "literal.json").stat().st_mtime_ns  # resumes: nothing refitted
    assert runner.invoke(app, ["identify", str(path), "--out", str(out)]).exit_code == 0
    assert (out / "fits" / "literal.json").stat().st_mtime_ns == stamp


def test_a_profiles_chapter5_part_reaches_the_chapter5_experiments_only() -> None:
    profile = profiles.Profile(name="p5", chapter5={"hypothesis": {"zn_rule": "pi"}})
    assert not profile.literal
    zn = profiles.experiment(THESIS / "ch5" / "fig_5_02.yaml", [], profile).resolved()["controllers"]["zn"]
    assert zn["tune"][0]["rule"] == "pi"
    pendulum = THESIS / "ch2" / "fig_2_04.yaml"
    assert profiles.experiment(pendulum, [], profile).resolved() == config.load(pendulum).resolved()

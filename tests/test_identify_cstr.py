"""Chapter 5's identification study: options reach every Table 5.8 experiment, the ZN row is
the only train row, and a profile's chapter-5 part reaches the chapter-5 experiments only."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.optimize import brentq
from typer.testing import CliRunner

from nlcx import config, engine
from nlcx.cli import app
from nlcx.thesis import hypotheses, profiles
from nlcx.thesis.hypotheses import CSTR_OPERATING_CB
from nlcx.thesis.identify_cstr import MethodRuns
from nlcx.uncertainty.actuator_saturation import saturate_inputs

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "configs" / "thesis"
runner = CliRunner()


@pytest.mark.slow
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


def _zn_loop(exp: config.Experiment) -> pd.Series:
    """M_p and t_r of C_B under the ZN controller of ``exp``."""
    (result,) = engine.evaluate([exp], record_logs=False)
    metrics = result.metrics.set_index(["controller", "signal", "metric"]).value
    return pd.Series({m: metrics["zn", "C_B", m] for m in ("overshoot", "rise_time")})


def _reactor(scale: float = 1.0) -> config.Experiment:
    """The ZN row with the option reactor=nonlinear, its step of C_B about C_Bs times ``scale``."""
    exp = MethodRuns(THESIS, ["ZN"]).experiment("ZN", hypotheses.Hypothesis((("reactor", "nonlinear"),)), {})
    raw = copy.deepcopy(exp.raw)
    reference = raw["reference"]["C_B"]
    assert reference["final"] - reference["initial"] == pytest.approx(0.05)
    reference["final"] = reference["initial"] + scale * 0.05
    return config.build(raw)


def _linearised_reactor(c_b: float) -> tuple[list[float], list[float]]:
    """(num, den) of eqs. 5.1-5.2 linearised at the steady state with C_B = ``c_b``: the
    transfer function 5.10 when ``c_b`` is C_Bs (the steady state solved here, not by nlcx)."""
    k1, k2, k3, c_af = 5 / 6, 5 / 3, 1 / 6, 10.0

    def steady(u: float) -> tuple[float, float]:
        c_a = (-(k1 + u) + math.sqrt((k1 + u) ** 2 + 4 * k3 * u * c_af)) / (2 * k3)
        return c_a, k1 * c_a / (u + k2)

    u = brentq(lambda d: steady(d)[1] - c_b, 0.1, 1.2)  # C_B rises with u up to its peak, at u > 1.2
    c_a = steady(u)[0]
    a11, a22 = -u - k1 - 2 * k3 * c_a, -u - k2
    return [-c_b, c_b * a11 + k1 * (c_af - c_a)], [1.0, -(a11 + a22), a11 * a22]


def test_the_zn_loop_on_the_reactor_tends_to_the_loop_on_its_transfer_function() -> None:
    """The transfer function 5.10 is the reactor linearised at C_Bs, so the ZN loop on the
    reactor tends to the loop on 5.10 as the step about C_Bs shrinks, the gap in M_p and t_r
    first order in the step: a 0.005 gmol/L step is near (M_p within 10 %, t_r within 15 %), and
    the chapter-5 option's step, ten times larger, has a gap 5 to 20 times larger (10, give or
    take second-order terms). That gap is not small (M_p about a quarter lower, t_r a fifth
    longer): C_Bs + 0.05 lies toward the reactor's peak C_B, where dC_B/du is lower, and a lower
    loop gain means less overshoot and a slower rise. The same ZN gains on the reactor
    linearised at C_Bs + 0.05 (one point of the path the step travels) move M_p and t_r the
    same way; the reactor's gap is half to twice theirs."""
    linear_exp = MethodRuns(THESIS, ["ZN"]).experiment("ZN", hypotheses.Hypothesis(), {})
    params = linear_exp.raw["plant"]["params"]
    num, den = _linearised_reactor(CSTR_OPERATING_CB)
    assert params["num"] + params["den"] == pytest.approx(num + den, rel=1e-4)  # 5.10 as printed, to 5 digits
    linear = _zn_loop(linear_exp)
    small = _zn_loop(_reactor(0.1)) / linear - 1
    option = _zn_loop(_reactor()) / linear - 1
    assert abs(small.overshoot) < 0.10
    assert abs(small.rise_time) < 0.15
    assert (option / small).between(5, 20).all()

    gains = {row["parameter"]: row["value"] for row in engine.prepare(linear_exp).tuning}
    raw = copy.deepcopy(linear_exp.raw)
    num, den = _linearised_reactor(CSTR_OPERATING_CB + 0.05)
    raw["plant"]["params"].update(num=num, den=den)
    raw["controllers"]["zn"] = {
        "kind": "pid",
        "loops": {"C_B": {"schedule": {"kind": "constant", **{k: gains[k] for k in ("kp", "ki", "kd")}}}},
    }
    at_the_end = _zn_loop(config.build(raw)) / linear - 1
    assert option.overshoot < 0 < option.rise_time
    assert (option / at_the_end).between(0.5, 2).all()


@pytest.mark.slow
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

"""Unknown names are one line with the closest name suggested; list elements are overridden by index."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from nlcx import config, registry
from nlcx.cli import app
from nlcx.config import apply_overrides
from nlcx.errors import ConfigError, did_you_mean

ROOT = Path(__file__).resolve().parent.parent
CONFIG = "configs/x_error_ags.yaml"
runner = CliRunner()


@pytest.fixture(autouse=True)
def _in_checkout(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)


def validate(*args: str):
    return runner.invoke(app, ["validate", *args])


def test_the_shared_hint_names_the_closest_choice_or_nothing() -> None:
    assert did_you_mean("propsed", ["conventional", "proposed"]) == " (did you mean 'proposed'?)"
    assert did_you_mean("zzz", ["conventional", "proposed"]) == ""
    assert did_you_mean(3, ["3"]) == ""
    assert did_you_mean("a.yml", ["a.yaml"], lambda name: f"dir/{name}") == " (did you mean 'dir/a.yaml'?)"


def test_a_typo_in_a_controller_label_is_refused_with_the_label_suggested() -> None:
    result = validate(CONFIG, "controllers.propsed.loops.x.sign=-1")
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        "config error: controllers.propsed.loops.x.sign = -1: no controller 'propsed' (did you mean 'proposed'?); "
        "allowed: conventional, proposed, or a new controller started with controllers.propsed.kind=KIND "
        "(or +controllers.propsed.loops.x.sign=...)"
    )


def test_a_new_controller_starts_with_its_kind_or_a_plus() -> None:
    raw = {"controllers": {"a": {"kind": "pid"}}}
    out = apply_overrides(raw, ["controllers.b.kind=pid", "controllers.b.sample_time=0.01"])
    assert out["controllers"]["b"] == {"kind": "pid", "sample_time": 0.01}
    out = apply_overrides(raw, ["+controllers.c.sample_time=0.01", "++controllers.d.sample_time=0.02"])
    assert out["controllers"]["c"] == {"sample_time": 0.01} and out["controllers"]["d"] == {"sample_time": 0.02}
    with pytest.raises(ConfigError, match=r"no reference 'xx' \(did you mean 'x'\?\)"):
        apply_overrides({"reference": {"x": {"kind": "step"}}}, ["reference.xx.final=2"])


def test_an_unknown_plugin_kind_suggests_the_closest() -> None:
    assert registry.controllers.unknown_message("pdi").startswith(
        "unknown controller; allowed: lqr, open_loop, pid, pole_placement, preview, single_neuron, sliding_mode, "
        "state_feedback (did you mean 'pid'?)"
    )
    result = validate(CONFIG, "controllers.proposed.loops.x.schedule.kind=eror_ags")
    assert result.exit_code == 2 and "(did you mean 'error_ags'?)" in result.stderr


def test_an_unknown_config_key_suggests_the_closest() -> None:
    result = validate(CONFIG, "metrics.settling_bnd=0.05")
    assert result.exit_code == 2
    assert result.stderr.startswith("config error: metrics.settling_bnd = 0.05: unknown key; allowed keys: ")
    assert result.stderr.strip().endswith("(did you mean 'settling_band'?)")


def test_a_missing_config_file_suggests_a_file_beside_it() -> None:
    result = validate("configs/x_eror_ags.yaml")
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        "config error: <config> = 'configs/x_eror_ags.yaml': config file not found "
        "(did you mean 'configs/x_error_ags.yaml'?)"
    )
    result = validate("configs/nothing_like_any.yaml")
    assert result.stderr.strip() == "config error: <config> = 'configs/nothing_like_any.yaml': config file not found"


@pytest.mark.parametrize(
    ("override", "line"),
    [
        (
            "controllers.proposed.loops.theta.signal=thetaa",
            "config error: controllers.proposed.loops.theta.signal = 'thetaa': not an output of x_pendulum "
            "(did you mean 'theta'?); allowed: x, theta",
        ),
        (
            "plant.x0.thetta=0.1",
            "config error: plant.x0.thetta = 0.1: unknown state (did you mean 'theta'?); allowed: x, x_dot, theta, "
            "theta_dot",
        ),
    ],
)
def test_an_unknown_signal_suggests_the_closest(override: str, line: str) -> None:
    result = validate(CONFIG, override)
    assert result.exit_code == 2
    assert result.stderr.strip() == line


def test_an_unknown_metric_signal_column_suggests_the_closest(tmp_path: Path) -> None:
    file = tmp_path / "log.csv"
    file.write_text("t,y,y_ref\n0,0,1\n1,0.5,1\n2,0.9,1\n3,1,1\n")
    result = runner.invoke(app, ["metrics", str(file), "--signal", "yy"])
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        "metrics error: --signal = yy: not a column of log.csv (did you mean 'y'?); allowed: y, y_ref"
    )


def test_a_list_element_is_set_by_its_index() -> None:
    exp = config.load(CONFIG, ["metrics.rise_limits=[0.2, 0.8]", "metrics.rise_limits.1=0.7"])
    assert exp.section.metrics.rise_limits == (0.2, 0.7)


def test_a_list_the_config_leaves_to_its_default_is_overridden_from_the_default() -> None:
    assert "rise_limits" not in config.read_config(CONFIG).get("metrics", {})
    exp = config.load(CONFIG, ["metrics.rise_limits.0=0.05"])
    assert exp.section.metrics.rise_limits == (0.05, 0.9)
    result = validate(CONFIG, "metrics.rise_limits.0=0.05")
    assert result.exit_code == 0, result.stderr


def test_an_index_out_of_range_is_one_line() -> None:
    result = validate(CONFIG, "metrics.rise_limits.2=0.5")
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        "config error: metrics.rise_limits.2 = 2: index 2 is out of range: metrics.rise_limits has 2 element(s), "
        "allowed: 0 to 1"
    )


def test_a_run_directory_whose_time_series_was_deleted_says_it_is_missing(tmp_path: Path) -> None:
    import nlcx
    from nlcx.manifest import IntegrityError

    result = nlcx.run(CONFIG, ["simulation.t_end=0.5", "outputs.figure=false"])
    run = result.save(tmp_path / "run", report=False)
    (run / "timeseries.csv").unlink()
    with pytest.raises(IntegrityError) as caught:
        nlcx.load_run(run)
    assert str(caught.value) == (
        f"integrity error: {run / 'timeseries.csv'}: missing: the run wrote it and its manifest lists it; "
        f"allowed: write the run again: nlcx run {run / 'config.yaml'} --out {run}"
    )
    without = nlcx.run(CONFIG, ["simulation.t_end=0.5", "outputs.figure=false", "outputs.timeseries=false"])
    loaded = nlcx.load_run(without.save(tmp_path / "bare", report=False))
    assert loaded.metrics.equals(without.metrics)

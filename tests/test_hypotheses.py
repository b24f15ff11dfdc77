"""The study's families of the experiment as Simulink may have run it (hypotheses.py): each value
writes the documented config keys, changes only what the experiment has, and builds."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import pytest

from nlcx import config
from nlcx.thesis import hypotheses, profiles

THESIS = Path(__file__).resolve().parents[1] / "configs" / "thesis"
#: Real thesis experiments: a plant without and with a disturbance, and each pendulum.
CONFIGS = {
    "x": "ch2/fig_2_04.yaml",
    "x_disturbance": "ch2/fig_2_05.yaml",
    "xy": "ch3/fig_3_04.yaml",
    "xz": "ch3/fig_3_27.yaml",
    "xz_disturbance": "ch3/fig_3_28.yaml",
    "xyz": "ch4/fig_4_04.yaml",
}
NEW = (
    "theta_settling", "reference_amplitude", "step_time", "initial_angle", "z_loop", "disturbance_phase",
    "disturbance_start", "disturbance_entry", "integrator_limit",
)  # fmt: skip


def configured(name: str) -> dict[str, Any]:
    """The experiment as its config has it, interpolated (what a hypothesis changes)."""
    return config.interpolate(config.read_config(THESIS / CONFIGS[name]))


def applied(name: str, *options: tuple[str, str], **params: float) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the raw config with ``options`` applied, the resolved config built from it)."""
    raw = configured(name)
    hyp = hypotheses.Hypothesis(tuple(options))
    changed = hyp.apply(raw, params, profiles.plant_inputs(config.read_config(THESIS / CONFIGS[name])))
    return changed, config.build(copy.deepcopy(changed)).resolved()


def pids(raw: dict[str, Any]) -> list[dict[str, Any]]:
    return [c for c in raw["controllers"].values() if c.get("kind") == "pid"]


def test_the_families_and_their_values_are_the_contracts() -> None:
    values = {f: list(hypotheses.FAMILIES[f]) for f in NEW}
    assert values == {
        "theta_settling": ["relative", "absolute"],
        "reference_amplitude": ["unit", "free"],
        "step_time": ["zero", "one_second", "one_second_from_step"],
        "initial_angle": ["zero", "free"],
        "z_loop": ["as_configured", "no_feedforward", "no_feedforward_printed", "printed"],
        "disturbance_phase": ["zero", "quarter", "half", "three_quarter"],
        "disturbance_start": ["zero", "one_second"],
        "disturbance_entry": ["accelerations", "input"],
        "integrator_limit": ["none", "position", "all"],
    }
    freed = {f: hypotheses.Hypothesis(tuple((f, v) for v in list(hypotheses.FAMILIES[f])[1:2])).free() for f in NEW}
    assert freed["theta_settling"] == {"tol": (0.002, 0.05)} and freed["reference_amplitude"] == {"A": (0.2, 2.0)}
    assert freed["initial_angle"] == {"theta0": (0.0, 0.2)} and freed["integrator_limit"] == {"L": (0.01, 2.0)}
    for family in NEW:  # every freed parameter's neutral value lies in its range
        for value in hypotheses.FAMILIES[family].values():
            assert all(lo <= hypotheses.NEUTRAL[k] <= hi for k, (lo, hi) in value.free.items())


@pytest.mark.parametrize("name", list(CONFIGS))
def test_every_default_value_is_the_experiment_as_configured(name: str) -> None:
    for family in NEW:
        changed, _ = applied(name, (family, hypotheses.default(family)))
        assert changed == configured(name), family


def test_theta_settling_absolute_sets_the_regulation_band() -> None:
    changed, resolved = applied("x", ("theta_settling", "absolute"), tol=0.01)
    assert changed["metrics"]["regulation_abs_tol"] == 0.01
    assert resolved["metrics"]["regulation_abs_tol"] == 0.01
    assert {k: v for k, v in changed.items() if k != "metrics"} == {
        k: v for k, v in configured("x").items() if k != "metrics"
    }


@pytest.mark.parametrize(("name", "steps"), [("x", ["x"]), ("xz", ["x", "z"]), ("xyz", ["x", "y", "z"])])
def test_reference_amplitude_sets_every_step_final(name: str, steps: list[str]) -> None:
    changed, resolved = applied(name, ("reference_amplitude", "free"), A=0.7)
    for signal, reference in changed["reference"].items():
        if signal in steps:
            assert reference["kind"] == "step" and reference["final"] == 0.7
            assert resolved["reference"][signal]["final"] == 0.7
        else:  # the constant angle references are untouched
            assert reference == configured(name)["reference"][signal]
    # through a prefilter too (a prefiltered step is a step)
    both, _ = applied("x", ("prefilter", "first_order"), ("reference_amplitude", "free"), T_f=0.4, A=0.7)
    assert both["reference"]["x"]["kind"] == "filtered_step" and both["reference"]["x"]["final"] == 0.7


def test_step_time_moves_the_steps_and_the_origin_of_the_times() -> None:
    for value, origin in (("one_second", "start"), ("one_second_from_step", "step")):
        changed, resolved = applied("xz", ("step_time", value))
        assert [changed["reference"][s]["time"] for s in ("x", "z")] == [1.0, 1.0]
        assert [resolved["reference"][s]["time"] for s in ("x", "z")] == [1.0, 1.0]
        assert changed["metrics"]["time_origin"] == origin == resolved["metrics"]["time_origin"]


@pytest.mark.parametrize(
    ("name", "angles"), [("x", ["theta"]), ("xy", ["theta", "phi"]), ("xz", ["theta"]), ("xyz", ["theta", "phi"])]
)
def test_initial_angle_tilts_every_angle_of_the_pendulum(name: str, angles: list[str]) -> None:
    changed, resolved = applied(name, ("initial_angle", "free"), theta0=0.08)
    assert changed["plant"]["x0"] == dict.fromkeys(angles, 0.08)
    assert resolved["plant"]["x0"] == dict.fromkeys(angles, 0.08)


@pytest.mark.parametrize("name", ["xz", "xyz"])
def test_z_loop_drops_the_feedforward_and_or_takes_the_printed_equations(name: str) -> None:
    expected = {
        "no_feedforward": ("none", None),
        "printed": ("equilibrium", "printed"),
        "no_feedforward_printed": ("none", "printed"),
    }
    assert {c["feedforward"] for c in pids(configured(name))} == {"equilibrium"}
    for value, (feedforward, equations) in expected.items():
        changed, resolved = applied(name, ("z_loop", value))
        assert [c["feedforward"] for c in pids(changed)] == [feedforward] * 2
        assert changed["plant"]["params"].get("equations") == equations
        assert resolved["plant"]["params"]["equations"] == (equations or "derived")
        assert {c["feedforward"] for c in resolved["controllers"].values()} == {feedforward}


@pytest.mark.parametrize("name", ["x", "xy", "x_disturbance"])
def test_z_loop_leaves_a_pendulum_without_z_as_configured(name: str) -> None:
    for value in list(hypotheses.FAMILIES["z_loop"])[1:]:
        assert applied(name, ("z_loop", value))[0] == configured(name)


@pytest.mark.parametrize("name", ["x_disturbance", "xz_disturbance"])
def test_the_disturbance_families_set_each_disturbance(name: str) -> None:
    for value, phase in (("quarter", math.pi / 2), ("half", math.pi), ("three_quarter", 1.5 * math.pi)):
        changed, resolved = applied(name, ("disturbance_phase", value))
        assert changed["uncertainty"]["disturbance"]["phase"] == phase
        assert resolved["uncertainty"]["disturbance"]["phase"] == phase
    changed, resolved = applied(name, ("disturbance_start", "one_second"))
    assert changed["uncertainty"]["disturbance"]["start"] == 1.0 == resolved["uncertainty"]["disturbance"]["start"]
    changed, resolved = applied(name, ("disturbance_entry", "input"))
    assert changed["uncertainty"]["disturbance"]["entry"] == "input"
    assert resolved["uncertainty"]["disturbance"]["entry"] == "input"
    # each changes the disturbance only
    assert {k: v for k, v in changed.items() if k != "uncertainty"} == {
        k: v for k, v in configured(name).items() if k != "uncertainty"
    }


@pytest.mark.parametrize("name", ["x", "xz", "xyz"])
def test_the_disturbance_families_leave_an_experiment_without_disturbance_as_configured(name: str) -> None:
    for family in ("disturbance_phase", "disturbance_start", "disturbance_entry"):
        for value in list(hypotheses.FAMILIES[family])[1:]:
            assert applied(name, (family, value))[0] == configured(name), (family, value)


def test_integrator_limit_clamps_the_position_loops_or_every_loop() -> None:
    changed, resolved = applied("xyz", ("integrator_limit", "position"), L=0.5)
    for raw in (*pids(changed), *resolved["controllers"].values()):
        limits = {key: loop.get("integral_limit") for key, loop in raw["loops"].items()}
        assert limits == {"theta": None, "x": 0.5, "phi": None, "y": 0.5, "z": None}
    changed, resolved = applied("xyz", ("integrator_limit", "all"), L=0.5)
    for raw in (*pids(changed), *resolved["controllers"].values()):
        assert {key: loop["integral_limit"] for key, loop in raw["loops"].items()} == dict.fromkeys(
            ["theta", "x", "phi", "y", "z"], 0.5
        )


def test_step_time_is_one_family_of_both_chapters_chapter_5_with_its_two_values() -> None:
    """Chapter 5's step_time has the step at 1 s timed from the step (as its metrics always
    were), and keeps its place in the hypotheses' names."""
    pendulum = [h.name for h in hypotheses.family(["step_time"], 1)]
    assert pendulum == ["literal", "step_time=one_second", "step_time=one_second_from_step"]
    cstr = [h.name for h in hypotheses.family(["zn_rule", "step_time"], 2)]
    assert "zn_rule=pi+step_time=one_second_from_step" in cstr and len(cstr) == 1 + 5 + 1 + 5 * 1
    assert {name.split("step_time=")[1] for name in cstr if "step_time" in name} == {"one_second_from_step"}
    assert [f for f in hypotheses.OPTIONS if f in hypotheses.FAMILIES] == list(hypotheses.FAMILIES)
    assert [f for f in hypotheses.OPTIONS if f in hypotheses.CSTR_FAMILIES] == list(hypotheses.CSTR_FAMILIES)
    for family in set(hypotheses.FAMILIES) & set(hypotheses.CSTR_FAMILIES):  # one meaning per value
        for value, option in hypotheses.CSTR_FAMILIES[family].items():
            assert hypotheses.FAMILIES[family][value] is option is hypotheses.OPTIONS[family][value]


@pytest.mark.parametrize("options", [(("lag", "first_order"), ("disturbance_entry", "input"))])
def test_an_actuator_lag_filters_the_controller_forces_not_an_input_disturbance(
    options: tuple[tuple[str, str], ...],
) -> None:
    """Loop elements act in config order: with the disturbance entering at the inputs, the lag
    comes before it whichever option is applied first."""
    raw = {
        "controllers": {},
        "uncertainty": {"noise": {"kind": "noise"}, "d": {"kind": "disturbance", "amplitude": 20.0}},
    }
    for order in (options, options[::-1]):
        out = copy.deepcopy(raw)
        for family, value in order:
            hypotheses.OPTIONS[family][value].change(out, {"tau": 0.01}, ["F"])
        assert list(out["uncertainty"]) == ["noise", "actuator_lag", "d"]
        assert out["uncertainty"]["d"]["entry"] == "input"
    out = copy.deepcopy(raw)
    hypotheses.OPTIONS["lag"]["first_order"].change(out, {"tau": 0.01}, ["F"])
    assert list(out["uncertainty"]) == ["noise", "d", "actuator_lag"]  # a disturbance on the accelerations

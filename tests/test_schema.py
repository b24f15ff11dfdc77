"""The JSON Schema of an experiment config (nlcx.schema) against the configs and nlcx.config.build."""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from jsonschema import Draft202012Validator

from nlcx import config
from nlcx.errors import ConfigError
from nlcx.schema import experiment_schema

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


@pytest.fixture(scope="module")
def validator() -> Draft202012Validator:
    schema = experiment_schema()
    Draft202012Validator.check_schema(schema)  # a well-formed draft 2020-12 schema
    return Draft202012Validator(schema)


def _resolved(path: Path) -> dict[str, Any]:
    return config.interpolate(config.read_config(path))


def _builds(raw: dict[str, Any]) -> bool:
    """Whether nlcx accepts ``raw`` as an experiment (the sweep section is checked by nlcx.sweeps)."""
    from nlcx.sweeps import SweepSection

    try:
        config.build({k: v for k, v in raw.items() if k != "sweep"})
        if "sweep" in raw:
            SweepSection.model_validate(raw["sweep"])
    except (ConfigError, ValueError):
        return False
    return True


def _experiment_configs() -> list[Path]:
    """The YAML files under configs/ that nlcx.config.build accepts once resolved (not the
    fragments they extend, nor the other tools' files)."""
    found = []
    for path in sorted(CONFIGS.rglob("*.yaml")):
        try:
            raw = _resolved(path)
        except ConfigError:
            continue
        if {"name", "plant", "controllers"} <= set(raw) and _builds(raw):
            found.append(path)
    return found


EXPERIMENTS = _experiment_configs()


def test_the_configs_are_found() -> None:
    names = {p.relative_to(CONFIGS).as_posix() for p in EXPERIMENTS}
    assert {"x_error_ags.yaml", "cstr_nonlinear.yaml", "sweeps/robustness.yaml", "thesis/ch5/fig_5_15.yaml"} <= names
    assert len(EXPERIMENTS) > 80


@pytest.mark.parametrize("path", EXPERIMENTS, ids=[p.relative_to(CONFIGS).as_posix() for p in EXPERIMENTS])
def test_every_experiment_config_is_valid(validator: Draft202012Validator, path: Path) -> None:
    """The resolved config (extends merged, ${...} replaced) and the file as written
    (extends, vars and ${...} themselves) are both valid."""
    errors = [f"{list(e.absolute_path)}: {e.message[:200]}" for e in validator.iter_errors(_resolved(path))]
    assert errors == []
    written = [f"{list(e.absolute_path)}: {e.message[:200]}" for e in validator.iter_errors(config.read_yaml(path))]
    assert written == []


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def apply(raw: dict[str, Any]) -> None:
        *parents, key = path.split(".")
        node = raw
        for part in parents:
            node = node.setdefault(part, {})
        node[key] = value

    return apply


def _drop(path: str) -> Callable[[dict[str, Any]], None]:
    def apply(raw: dict[str, Any]) -> None:
        *parents, key = path.split(".")
        node = raw
        for part in parents:
            node = node[part]
        del node[key]

    return apply


LOOP = "controllers.proposed.loops.x"
#: (id, change to configs/x_error_ags.yaml resolved): each one nlcx.config.build refuses.
INVALID = [
    ("unknown_top_level_key", _set("colour", "red")),
    ("unknown_section_key", _set("simulation.t_final", 30.0)),
    ("bad_integrator", _set("simulation.integrator", "rk45")),
    ("negative_t_end", _set("simulation.t_end", -1.0)),
    ("unknown_plant", _set("plant.name", "x_pendulm")),
    ("unknown_plant_param", _set("plant.params.Mass", 1.0)),
    ("another_plants_param", _set("plant.params.k1", 1.0)),
    ("bad_param", _set("plant.params.M", -1.0)),
    ("unknown_controller_kind", _set("controllers.proposed.kind", "pdi")),
    ("controller_without_kind", _drop("controllers.proposed.kind")),
    ("unknown_schedule_kind", _set(f"{LOOP}.schedule.kind", "error_agz")),
    ("incomplete_schedule", _drop(f"{LOOP}.schedule.rate")),
    ("unknown_schedule_key", _set(f"{LOOP}.schedule.kp.mid", 1.0)),
    ("unknown_tuner", _set("controllers.proposed.tune", {"kind": "zn"})),
    ("unknown_reference_kind", _set("reference.x.kind", "ramp")),
    ("uncertainty_label_without_kind", _set("uncertainty.wind", {"amplitude": 1.0})),
    ("unknown_uncertainty_key", _set("uncertainty.friction", {"mu": 0.1})),
    ("missing_name", _drop("name")),
    ("bad_sweep", _set("sweep", {"grid": {"seed": [1]}, "batch_size": 0})),
]


@pytest.mark.parametrize("change", [c[1] for c in INVALID], ids=[c[0] for c in INVALID])
def test_what_nlcx_refuses_the_schema_rejects(validator: Draft202012Validator, change: Callable[..., None]) -> None:
    raw = _resolved(CONFIGS / "x_error_ags.yaml")
    assert validator.is_valid(raw) and _builds(raw)
    changed = copy.deepcopy(raw)
    change(changed)
    assert not _builds(changed)  # nlcx refuses it ...
    assert not validator.is_valid(changed)  # ... and so does the schema


VALID = [
    ("uncertainty_label_is_its_kind", _set("uncertainty.friction", {"model": "simple"})),
    ("tuned_schedule_left_to_the_tuner", _set("controllers.proposed.tune", [{"kind": "ziegler_nichols"}])),
    ("another_plant", _set("plant", {"name": "cstr", "params": {"k1": 50.0}, "x0": {"C_A": 3.0}})),
]


@pytest.mark.parametrize("change", [c[1] for c in VALID], ids=[c[0] for c in VALID])
def test_what_nlcx_accepts_the_schema_accepts(validator: Draft202012Validator, change: Callable[..., None]) -> None:
    raw = copy.deepcopy(_resolved(CONFIGS / "x_error_ags.yaml"))
    change(raw)
    if "tune" not in raw["controllers"]["proposed"]:
        assert _builds(raw)
    assert validator.is_valid(raw), [e.message[:200] for e in validator.iter_errors(raw)]


def test_x0_names_the_states_of_its_plant(validator: Draft202012Validator) -> None:
    """The plant refuses an initial state it does not have when it is built; the schema knows
    each plant's states."""
    from nlcx import registry

    raw = copy.deepcopy(_resolved(CONFIGS / "x_error_ags.yaml"))
    pendulum = registry.plants.get("x_pendulum")
    params = pendulum.Params()
    for x0, valid in (({"theta": 0.1, "x_dot": 1.0}, True), ({"phi": 0.1}, False), ({"C_A": 1.0}, False)):
        raw["plant"]["x0"] = x0
        assert validator.is_valid(raw) is valid, x0
        if not valid:
            with pytest.raises(ConfigError, match="unknown state"):
                pendulum.build("x_pendulum", params, x0, {})


def test_a_tuned_schedule_must_still_name_a_schedule(validator: Draft202012Validator) -> None:
    raw = copy.deepcopy(_resolved(CONFIGS / "x_error_ags.yaml"))
    raw["controllers"]["proposed"]["tune"] = [{"kind": "ziegler_nichols"}]
    raw["controllers"]["proposed"]["loops"]["x"]["schedule"] = {"kind": "error_agz"}
    assert not validator.is_valid(raw)


def test_a_file_that_extends_another_need_not_name_the_experiment(validator: Draft202012Validator) -> None:
    assert validator.is_valid({"extends": "../plants/x.yaml", "title": "t", "simulation": {"t_end": "${vars.t}"}})
    assert not validator.is_valid({"title": "t"})  # no extends: name, plant and controllers are required
    assert not validator.is_valid({"extends": 3})

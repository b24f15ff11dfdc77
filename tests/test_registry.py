"""The registries check their plugins: ``register`` the name (and the form of a lazy entry point)
without importing anything, the first ``get`` that the plugin has every member of its kind's
protocol (:mod:`nlcx.protocols`), refusing one that lacks a member in one line that names it."""

from __future__ import annotations

import copy
import re
from collections.abc import Iterator
from typing import Any, Literal

import numpy as np
import pytest
from pydantic import BaseModel

from nlcx import config, registry
from nlcx.errors import ConfigError
from nlcx.protocols import (
    ControllerPlugin,
    PlantPlugin,
    ReferencePlugin,
    SchedulePlugin,
    TunerPlugin,
    UncertaintyPlugin,
    missing_members,
    protocol_members,
)
from nlcx.references.base import ReferenceConfig, SignalPlan

#: Each kind's protocol and what it declares, written out here from what the engine and the
#: config loader call on a plugin of that kind (not read from nlcx.protocols).
DECLARED = {
    "plants": (PlantPlugin, ("Params", "states", "inputs", "outputs"), ("build",)),
    "controllers": (ControllerPlugin, ("Config",), ("normalize", "build")),
    "schedules": (SchedulePlugin, ("Config", "gains"), ("pack",)),
    "uncertainties": (UncertaintyPlugin, ("Config",), ("apply",)),
    "references": (ReferencePlugin, ("Config",), ("values", "signal_plan")),
    "tuners": (TunerPlugin, ("Config",), ("tune",)),
}
KINDS = list(DECLARED)


def fresh(kind: str) -> registry.Registry[Any]:
    """An empty registry of ``kind``'s protocol, in an entry-point group no package fills."""
    reg = registry.ALL[kind]
    return registry.Registry(reg.kind, "nlcx.test-no-such-group", reg.protocol)


def stand_in(kind: str, without: str = "", **replaced: Any) -> object:
    """A plugin of ``kind`` that subclasses nothing: the members of the first built-in plugin of
    that kind copied onto a plain class, but ``without``, and with ``replaced`` set."""
    builtin = type(registry.ALL[kind].get(registry.ALL[kind].names()[0]))
    attributes, methods = DECLARED[kind][1:]
    namespace = {name: builtin.__dict__.get(name, getattr(builtin, name)) for name in (*attributes, *methods)}
    namespace.pop(without, None)
    return type(f"StandIn_{kind}", (), {**namespace, **replaced})()


def test_each_registry_holds_its_kinds_protocol() -> None:
    assert {kind: reg.protocol for kind, reg in registry.ALL.items()} == {k: v[0] for k, v in DECLARED.items()}


@pytest.mark.parametrize("kind", KINDS)
def test_the_protocol_declares_what_the_engine_calls(kind: str) -> None:
    protocol, attributes, methods = DECLARED[kind]
    assert protocol_members(protocol) == (attributes, methods)


@pytest.mark.parametrize("kind", KINDS)
def test_every_built_in_plugin_satisfies_its_protocol(kind: str) -> None:
    reg = registry.ALL[kind]
    names = reg.names()
    assert names
    for name in names:
        plugin = reg.get(name)
        assert missing_members(plugin, reg.protocol) == [], name
        assert reg.get(name) is plugin  # loaded and checked once


@pytest.mark.parametrize("kind", KINDS)
def test_a_plugin_that_subclasses_nothing_is_accepted(kind: str) -> None:
    reg = fresh(kind)
    plugin = stand_in(kind)
    reg.register("structural", plugin)
    assert reg.get("structural") is plugin


@pytest.mark.parametrize(
    ("kind", "member"), [(kind, member) for kind, (_, attrs, methods) in DECLARED.items() for member in attrs + methods]
)
def test_a_plugin_lacking_a_member_is_refused_in_one_line(kind: str, member: str) -> None:
    reg = fresh(kind)
    reg.register("partial", stand_in(kind, without=member))
    with pytest.raises(ConfigError) as caught:
        reg.get("partial", path="somewhere.kind")
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith("config error: somewhere.kind = 'partial': ")
    assert f"lacks {member}, which every {reg.kind} plugin has" in message
    assert f"nlcx.protocols.{DECLARED[kind][0].__name__}" in message
    with pytest.raises(ConfigError):  # a refused plugin is not kept: every get refuses it
        reg.get("partial")


def test_a_method_that_is_not_callable_and_a_config_that_is_not_a_model_are_named() -> None:
    reg = fresh("references")
    reg.register("odd", stand_in("references", values=3.0, Config=dict))
    with pytest.raises(ConfigError, match=r"lacks Config \(not a pydantic model class\), values \(not callable\)"):
        reg.get("odd")


def test_a_lazy_entry_point_is_imported_and_checked_on_first_get_only() -> None:
    reg = fresh("tuners")
    reg.register("missing_module", "nlcx_no_such_package.tuners:Tuner")  # nothing is imported yet
    reg.register("not_a_tuner", "nlcx.errors:NlcxError")
    assert reg.names() == ["missing_module", "not_a_tuner"]
    with pytest.raises(ModuleNotFoundError):
        reg.get("missing_module")
    with pytest.raises(ConfigError) as caught:
        reg.get("not_a_tuner")
    assert "(nlcx.errors:NlcxError) lacks Config, tune, which every tuner plugin has" in str(caught.value)


def test_a_class_that_needs_arguments_is_refused_in_one_line() -> None:
    reg = fresh("references")
    reg.register("plan", SignalPlan)  # a dataclass whose kind is required
    with pytest.raises(ConfigError, match="cannot be made without arguments") as caught:
        reg.get("plan", path="reference.x.kind")
    assert "\n" not in str(caught.value)


def test_a_refused_plugin_can_be_replaced_by_one_that_conforms() -> None:
    reg = fresh("schedules")
    reg.register("ags", stand_in("schedules", without="pack"))
    with pytest.raises(ConfigError):
        reg.get("ags")
    complete = stand_in("schedules")
    reg.register("ags", complete, replace=True)
    assert reg.get("ags") is complete


@pytest.mark.parametrize("name", ["", "two words", "x:y", "_private", "3d", "a/b", "é"])
def test_register_refuses_a_name_a_config_cannot_write(name: str) -> None:
    reg = fresh("references")
    with pytest.raises(ConfigError, match="a plugin name") as caught:
        reg.register(name, "nlcx.references.basic:Step")
    assert "\n" not in str(caught.value)
    assert reg.names() == []


def test_register_refuses_a_name_that_is_not_a_string() -> None:
    with pytest.raises(ConfigError, match="a plugin name"):
        fresh("plants").register(3, "nlcx.plants.cstr:CSTR")


@pytest.mark.parametrize("name", ["step", "filtered_step", "dead-zone", "X2"])
def test_register_takes_names_of_letters_digits_underscores_and_hyphens(name: str) -> None:
    reg = fresh("references")
    reg.register(name, "nlcx.references.basic:Step")
    assert reg.names() == [name]


@pytest.mark.parametrize("entry_point", ["nlcx.references.basic Step", "module:", ":Step", "a..b:C", "a:b:c", ""])
def test_register_refuses_a_malformed_entry_point(entry_point: str) -> None:
    reg = fresh("references")
    with pytest.raises(ConfigError, match=re.escape("an entry point 'package.module:attribute'")):
        reg.register("step", entry_point)
    assert reg.names() == []


class _HalfConfig(BaseModel):
    kind: Literal["half"] = "half"


class _HalfController:
    """A controller that forgot ``normalize``."""

    Config = _HalfConfig

    def build(self, *args: Any, **kwargs: Any) -> Any:
        raise AssertionError("never built")


@pytest.fixture
def half_controller() -> Iterator[None]:
    registry.controllers.register("half", _HalfController)
    try:
        yield
    finally:
        registry.controllers._entries.pop("half")
        registry.controllers._loaded.pop("half", None)


def test_a_config_naming_a_nonconforming_plugin_is_refused_at_its_kind(
    half_controller: None, x_error_raw: dict[str, Any]
) -> None:
    raw = copy.deepcopy(x_error_raw)
    raw["controllers"]["proposed"] = {"kind": "half"}
    with pytest.raises(ConfigError) as caught:
        config.build(raw)
    assert str(caught.value) == (
        "config error: controllers.proposed.kind = 'half': the controller registered as 'half' lacks normalize, "
        "which every controller plugin has (nlcx.protocols.ControllerPlugin)"
    )


def test_a_reference_that_subclasses_nothing_is_taken_by_the_config_loader(x_error_raw: dict[str, Any]) -> None:

    class RampConfig(ReferenceConfig):
        kind: Literal["ramp"] = "ramp"
        slope: float = 0.0

    class Ramp:
        Config = RampConfig

        def values(self, cfg: RampConfig, t: np.ndarray) -> np.ndarray:
            return cfg.slope * t

        def signal_plan(self, cfg: RampConfig) -> SignalPlan:
            return SignalPlan("tracking")

    registry.references.register("ramp", Ramp)
    try:
        raw = copy.deepcopy(x_error_raw)
        raw["reference"]["x"] = {"kind": "ramp", "slope": 0.5}
        exp = config.build(raw)
        assert isinstance(exp.references["x"].model, Ramp)
        assert exp.references["x"].config == RampConfig(slope=0.5)
        assert exp.references["theta"].config.model_dump() == {"kind": "constant", "value": 0.0}
    finally:
        registry.references._entries.pop("ramp")
        registry.references._loaded.pop("ramp", None)

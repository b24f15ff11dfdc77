"""Plugin registries, in the manner of gymnasium's ``register(id, entry_point)``.

A plugin is registered under the name the YAML uses, either as an object or as a lazy
``"package.module:attribute"`` string. Third-party packages add plugins through
``importlib.metadata`` entry points in the groups ``nlcx.plants``, ``nlcx.controllers``,
``nlcx.schedules``, ``nlcx.uncertainties``, ``nlcx.references`` and ``nlcx.tuners``; the entry
point's name is the registered name and its value the entry point, e.g. in a third party's
pyproject.toml::

    [project.entry-points."nlcx.plants"]
    furuta = "mypkg.furuta:FurutaPendulum"

Each registry holds one kind of plugin, typed by that kind's protocol (:mod:`nlcx.protocols`).
``register`` checks what it can without importing a lazy entry point (the name, and the form of
a ``"module:attribute"`` string); the first ``get`` of a plugin checks that it has every member
of its kind's protocol, and refuses it in one line naming what it lacks.
"""

from __future__ import annotations

import importlib
import json
import re
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, Generic, TypeVar, cast

from nlcx.errors import ConfigError, did_you_mean
from nlcx.protocols import (
    ControllerPlugin,
    PlantPlugin,
    ReferencePlugin,
    SchedulePlugin,
    TunerPlugin,
    UncertaintyPlugin,
    missing_members,
)

if TYPE_CHECKING:
    from pydantic import BaseModel

    from nlcx.plants.base import Signal

T = TypeVar("T")

#: A plugin's name: what a config writes after ``kind:`` (``name:`` for a plant).
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
#: A lazy entry point: ``package.module`` or ``package.module:attribute.attribute``.
_ENTRY_POINT = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*(:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*)?")


def load_entry_point(entry_point: str) -> object:
    """Import ``"package.module:attribute"`` and return the attribute."""
    module_name, _, attribute = entry_point.partition(":")
    obj: object = importlib.import_module(module_name)
    for part in filter(None, attribute.split(".")):
        obj = getattr(obj, part)
    return obj


class Registry(Generic[T]):
    """Names the YAML may use for one kind of plugin, mapped to their entry points.

    ``protocol`` is the kind's protocol (:mod:`nlcx.protocols`), which every plugin is checked
    against on its first load; ``T`` is the same protocol, as the type :meth:`get` returns."""

    def __init__(self, kind: str, group: str, protocol: type) -> None:
        self.kind = kind
        self.group = group
        self.protocol = protocol
        #: name -> its entry point: a ``"module:attribute"`` string, or the object or class itself.
        self._entries: dict[str, str | T | type[T]] = {}
        self._loaded: dict[str, T] = {}
        self._scanned = False

    def register(self, name: str, entry_point: str | T | type[T], *, replace: bool = False) -> None:
        """Register ``entry_point`` (an object, a class or a ``"module:attr"`` string) as ``name``.

        A ConfigError if ``name`` is not a plugin name (a letter, then letters, digits, ``_`` and
        ``-``) or a string ``entry_point`` is not of the form ``"package.module:attribute"``; the
        plugin itself is checked when it is first loaded (:meth:`get`)."""
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise ConfigError(self.group, name, "a plugin name: a letter, then letters, digits, '_' and '-'")
        if isinstance(entry_point, str) and not _ENTRY_POINT.fullmatch(entry_point):
            raise ConfigError(f"{self.group}.{name}", entry_point, "an entry point 'package.module:attribute'")
        if name in self._entries and not replace:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self._entries[name] = entry_point
        self._loaded.pop(name, None)

    def _scan_entry_points(self) -> None:
        if self._scanned:
            return
        self._scanned = True
        for ep in entry_points(group=self.group):
            if ep.name not in self._entries:
                self._entries[ep.name] = ep.value

    def names(self) -> list[str]:
        """Registered names in registration order (built-ins first, then entry points)."""
        self._scan_entry_points()
        return list(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self.names()

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def get(self, name: str, *, path: str = "") -> T:
        """The plugin registered as ``name`` (a class is instantiated once, without arguments).

        A ConfigError at ``path`` if nothing is registered under ``name``, or if the plugin
        lacks a member of its kind's protocol (checked once, when it is first loaded).
        """
        if name not in self.names():
            raise ConfigError(path, name, self.unknown_message(name))
        if name not in self._loaded:
            self._loaded[name] = self._load(name, path)
        return self._loaded[name]

    def _load(self, name: str, path: str) -> T:
        """The plugin registered as ``name``, imported, instantiated and checked against the protocol."""
        entry = self._entries[name]
        obj = load_entry_point(entry) if isinstance(entry, str) else entry
        where = path or self.group
        if isinstance(obj, type):
            try:
                obj = obj()
            except TypeError as exc:
                raise ConfigError(
                    where, name, f"{self._source(name)} cannot be made without arguments: {exc}"
                ) from None
        missing = missing_members(obj, self.protocol)
        if missing:
            raise ConfigError(
                where,
                name,
                f"{self._source(name)} lacks {', '.join(missing)}, which every {self.kind} plugin has "
                f"(nlcx.protocols.{self.protocol.__name__})",
            )
        return cast(T, obj)  # it has every member of the kind's protocol

    def _source(self, name: str) -> str:
        """'the <kind> registered as <name>', with its entry point when it was given as one."""
        entry = self._entries[name]
        return f"the {self.kind} registered as {name!r}" + (f" ({entry})" if isinstance(entry, str) else "")

    def unknown_message(self, name: object) -> str:
        """'unknown <kind>; allowed: ...' with a close match suggested when there is one."""
        names = self.names()
        message = f"unknown {self.kind}; allowed: {', '.join(sorted(names))}"
        message += did_you_mean(name, names)
        return message + (
            f"; one of your own: name its file in the config's imports: [my_{self.kind}s.py] (or --plugins FILE), "
            f"or install a package that declares it under the entry-point group {self.group}"
        )

    def describe(self) -> list[tuple[str, str]]:
        """(name, first line of the plugin's docstring) for ``nlcx list``."""
        rows = []
        for name in self.names():
            try:
                doc = (self.get(name).__doc__ or "").strip().splitlines()
                summary = doc[0] if doc else ""
            except Exception as exc:  # a broken third-party plugin must not break `list`
                summary = f"<failed to load: {exc}>"
            rows.append((name, summary))
        return rows

    def explain(self, name: str) -> PluginDoc:
        """What ``nlcx list KIND NAME`` shows of the plugin registered as ``name``: its signals
        (a plant's states, inputs and outputs) and the fields of its parameter model
        (``Params``, a plant's) or configuration model (``Config``, the other plugins'), with
        the models nested in them. A ConfigError if nothing is registered under ``name``."""
        plugin = self.get(name)
        model = getattr(plugin, "Params", None) or getattr(plugin, "Config", None)
        models = tuple(model_doc(m) for m in nested_models(model)) if model is not None else ()
        return PluginDoc(self.kind, name, _first_paragraph(plugin.__doc__), _signals(plugin), models)


@dataclass(frozen=True)
class FieldDoc:
    """One field of a plugin's model as ``nlcx list`` shows it."""

    name: str
    #: The annotation in Python's words, with its bounds (e.g. ``float > 0``).
    type: str
    #: The default as JSON, or ``required``.
    default: str
    #: The field's unit (``json_schema_extra={"unit": ...}``), empty if it has none.
    unit: str
    description: str


@dataclass(frozen=True)
class ModelDoc:
    """A pydantic model: its name, the first line of its docstring and its fields."""

    name: str
    summary: str
    fields: tuple[FieldDoc, ...]


@dataclass(frozen=True)
class PluginDoc:
    """A registered plugin as ``nlcx list KIND NAME`` shows it (see :meth:`Registry.explain`)."""

    kind: str
    name: str
    summary: str
    #: ("states" | "inputs" | "outputs", ((name, unit, label), ...)); empty but for plants.
    signals: tuple[tuple[str, tuple[tuple[str, str, str], ...]], ...]
    #: The plugin's parameter or configuration model first, then the models nested in it.
    models: tuple[ModelDoc, ...]


def _first_paragraph(doc: str | None) -> str:
    """A docstring's first paragraph on one line."""
    return " ".join((doc or "").strip().split("\n\n")[0].split())


def _signals(plugin: object) -> tuple[tuple[str, tuple[tuple[str, str, str], ...]], ...]:
    """A plant's states, inputs and outputs as (name, unit, label); its outputs may be given as
    the names of states."""
    states = tuple(getattr(plugin, "states", ()) or ())
    inputs = tuple(getattr(plugin, "inputs", ()) or ())
    by_name = {s.name: s for s in (*states, *inputs)}
    outputs = tuple(by_name.get(o, o) if isinstance(o, str) else o for o in getattr(plugin, "outputs", ()) or ())
    groups = (("states", states), ("inputs", inputs), ("outputs", outputs))
    return tuple((group, tuple(_signal_row(s) for s in signals)) for group, signals in groups if signals)


def _signal_row(signal: Signal | str) -> tuple[str, str, str]:
    if isinstance(signal, str):
        return signal, "", ""
    return str(signal.name), str(getattr(signal, "unit", "")), str(getattr(signal, "label", ""))


def nested_models(model: type[BaseModel]) -> list[type[BaseModel]]:
    """``model`` and every pydantic model its fields' annotations name, depth first, once each."""
    from pydantic import BaseModel

    found: list[type[BaseModel]] = []

    def visit(annotation: object) -> None:
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            if annotation in found:
                return
            found.append(annotation)
            for info in annotation.model_fields.values():
                visit(info.annotation)
            return
        for arg in typing.get_args(annotation):
            visit(arg)

    visit(model)
    return found


def model_doc(model: type[BaseModel]) -> ModelDoc:
    """The fields of the pydantic ``model`` with their type, default, unit and description."""
    fields = []
    for name, info in model.model_fields.items():
        extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
        bounds = " ".join(_bounds(info.metadata))
        fields.append(
            FieldDoc(
                name=name,
                type=f"{type_text(info.annotation)} {bounds}".strip(),
                default="required"
                if info.is_required()
                else _default_text(info.get_default(call_default_factory=True)),
                unit=str(extra.get("unit", "")),
                description=" ".join((info.description or "").split()),
            )
        )
    return ModelDoc(model.__name__, _first_paragraph(model.__doc__), tuple(fields))


_BOUNDS = (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="), ("min_length", "min length"),
           ("max_length", "max length"))  # fmt: skip


def _bounds(metadata: list[object]) -> list[str]:
    """A field's constraints (pydantic's ``Field(gt=0)`` and the like) as ``> 0``."""
    words = []
    for item in metadata:
        for attribute, word in _BOUNDS:
            value = getattr(item, attribute, None)
            if value is not None:
                words.append(f"{word} {value}")
    return words


def type_text(annotation: object) -> str:
    """An annotation as Python spells it, shortened: ``float``, ``'abs' | 'signed'``,
    ``dict[str, LoopConfig]``, ``float | None`` (pydantic's markers such as SerializeAsAny left out)."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if annotation is type(None):
        return "None"
    if origin is typing.Literal:
        return " | ".join(repr(a) for a in args)
    if origin is typing.Annotated:
        return type_text(args[0])
    if origin is typing.Union or origin is types.UnionType:
        return " | ".join(type_text(a) for a in args)
    if origin is not None:
        name = getattr(origin, "__name__", str(origin))
        return f"{name}[{', '.join('...' if a is Ellipsis else type_text(a) for a in args)}]"
    if annotation is Any:
        return "Any"
    if isinstance(annotation, type):
        return annotation.__name__
    return str(annotation).replace("typing.", "")


def _default_text(value: object) -> str:
    """A default as JSON (a model as the mapping of its fields)."""
    from pydantic import BaseModel

    if isinstance(value, BaseModel):
        value = value.model_dump(mode="json")
    return json.dumps(value, default=str, ensure_ascii=False)


plants: Registry[PlantPlugin] = Registry("plant", "nlcx.plants", PlantPlugin)
controllers: Registry[ControllerPlugin] = Registry("controller", "nlcx.controllers", ControllerPlugin)
schedules: Registry[SchedulePlugin] = Registry("gain schedule", "nlcx.schedules", SchedulePlugin)
uncertainties: Registry[UncertaintyPlugin] = Registry("uncertainty", "nlcx.uncertainties", UncertaintyPlugin)
references: Registry[ReferencePlugin] = Registry("reference", "nlcx.references", ReferencePlugin)
tuners: Registry[TunerPlugin] = Registry("tuner", "nlcx.tuners", TunerPlugin)

#: Every registry by its kind in the plural; each holds plugins of its own protocol.
ALL: dict[
    str,
    Registry[PlantPlugin]
    | Registry[ControllerPlugin]
    | Registry[SchedulePlugin]
    | Registry[UncertaintyPlugin]
    | Registry[ReferencePlugin]
    | Registry[TunerPlugin],
] = {
    "plants": plants,
    "controllers": controllers,
    "schedules": schedules,
    "uncertainties": uncertainties,
    "references": references,
    "tuners": tuners,
}

#: Each kind of :data:`ALL` in the singular (``nlcx list plant`` is ``nlcx list plants``).
SINGULAR: dict[str, str] = {
    "plants": "plant",
    "controllers": "controller",
    "schedules": "schedule",
    "uncertainties": "uncertainty",
    "references": "reference",
    "tuners": "tuner",
}


def kind_named(text: str) -> str | None:
    """The kind of :data:`ALL` that ``text`` names in the plural or the singular, else None."""
    if text in ALL:
        return text
    return next((kind for kind, singular in SINGULAR.items() if singular == text), None)


def register_builtins() -> None:
    """Register nlcx's own plugins (idempotent)."""
    if "x_pendulum" in plants._entries:
        return
    plants.register("x_pendulum", "nlcx.plants.x_pendulum:XPendulum")
    plants.register("xy_pendulum", "nlcx.plants.xy_pendulum:XYPendulum")
    plants.register("xz_pendulum", "nlcx.plants.xz_pendulum:XZPendulum")
    plants.register("xyz_pendulum", "nlcx.plants.xyz_pendulum:XYZPendulum")
    plants.register("transfer_function", "nlcx.plants.transfer_function:TransferFunction")
    plants.register("cstr", "nlcx.plants.cstr:CSTR")
    controllers.register("pid", "nlcx.controllers.pid:MultiLoopPID")
    controllers.register("open_loop", "nlcx.controllers.open_loop:OpenLoop")
    controllers.register("single_neuron", "nlcx.controllers.neuron:SingleNeuron")
    controllers.register("preview", "nlcx.controllers.preview:Preview")
    controllers.register("state_feedback", "nlcx.controllers.feedback:StateFeedback")
    controllers.register("lqr", "nlcx.controllers.feedback:LQR")
    controllers.register("pole_placement", "nlcx.controllers.feedback:PolePlacement")
    controllers.register("sliding_mode", "nlcx.controllers.sliding_mode:SlidingMode")
    schedules.register("constant", "nlcx.controllers.schedules:Constant")
    schedules.register("time_ags", "nlcx.controllers.schedules:TimeAGS")
    schedules.register("error_ags", "nlcx.controllers.schedules:ErrorAGS")
    schedules.register("fuzzy", "nlcx.controllers.fuzzy:Fuzzy")
    schedules.register("anfis", "nlcx.controllers.anfis:ANFIS")
    uncertainties.register("disturbance", "nlcx.uncertainty.disturbance:Disturbance")
    uncertainties.register("noise", "nlcx.uncertainty.noise:Noise")
    uncertainties.register("friction", "nlcx.uncertainty.friction:Friction")
    uncertainties.register("actuator_lag", "nlcx.uncertainty.actuator_lag:ActuatorLag")
    uncertainties.register("actuator_saturation", "nlcx.uncertainty.actuator_saturation:ActuatorSaturation")
    references.register("constant", "nlcx.references.basic:ConstantReference")
    references.register("step", "nlcx.references.basic:Step")
    references.register("filtered_step", "nlcx.references.basic:FilteredStep")
    references.register("sine", "nlcx.references.basic:Sine")
    tuners.register("ziegler_nichols", "nlcx.tuning.ziegler_nichols:ZieglerNichols")
    tuners.register("ga", "nlcx.tuning.ga:GATuner")
    tuners.register("anfis", "nlcx.tuning.anfis_tuner:AnfisTuner")


register_builtins()

"""The JSON Schema of an experiment config (``nlcx schema``), for an editor to complete and check YAML.

The schema is built from the section models of :mod:`nlcx.config` (and the ``sweep`` section
of :mod:`nlcx.sweeps`) and from the model of every registered plugin, so that it knows what
:func:`nlcx.config.build` accepts:

- ``plant.name`` is a registered plant; its ``params`` are checked by that plant's parameter
  model and the keys of ``x0`` are its states (``if``/``then`` on the name);
- each controller, gain schedule (``loops.<loop>.schedule``), tuner (``tune``), uncertainty
  and reference is one of the registered models of its kind (``oneOf``, told apart by a
  required ``kind``); an uncertainty whose label is a registered name may leave ``kind`` out,
  as the config allows;
- every model forbids unknown keys, and each field carries its description, default and,
  where it has one, its ``unit``.

A config file may also hold what :func:`nlcx.config.read_config` and
:func:`nlcx.config.interpolate` resolve before validation: ``extends`` (then the file need not
name ``name``, ``plant`` and ``controllers`` itself), ``vars``, and a ``"${dotted.key}"``
string in place of any value. What the schema cannot say (a settled ``extends`` file whose
sections are completed by its parents, checks that span sections such as a loop's signal
being an output of the plant) is left to ``nlcx validate``.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from typing import Any

from pydantic import BaseModel
from pydantic.json_schema import models_json_schema

from nlcx import registry

__all__ = ["DIALECT", "experiment_schema", "schema_text"]

#: The JSON Schema dialect of the schema (pydantic's).
DIALECT = "https://json-schema.org/draft/2020-12/schema"
#: A JSON Schema (or part of one) as pydantic makes it: nested mappings and lists.
Schema = dict[str, Any]
#: A string holding an interpolation, ``"${vars.gains}"``, which stands for any value.
INTERPOLATION: Schema = {
    "type": "string",
    "pattern": r"\$\{[^}]+\}",
    "description": "A reference to another key, ${dotted.key}, replaced by a copy of its value before validation.",
}
#: The union definition of each kind of plugin section keyed on ``kind``.
_UNIONS = {
    "controllers": "controller",
    "schedules": "schedule",
    "uncertainties": "uncertainty",
    "references": "reference",
    "tuners": "tuner",
}


def _plugin_model(kind: str, name: str) -> type[BaseModel]:
    """The model that validates a plugin's section: a plant's ``Params``, the others' ``Config``."""
    plugin = registry.ALL[kind].get(name)
    model: type[BaseModel] = getattr(plugin, "Params" if kind == "plants" else "Config")
    return model


def _definitions() -> tuple[Schema, dict[type, str]]:
    """Every model's schema in one ``$defs`` (pydantic names each once, qualifying the names
    two models share) and the definition name of each model."""
    from nlcx.config import ExperimentSection, PlantSection
    from nlcx.controllers.schedules import ScheduleConfig
    from nlcx.sweeps import SweepSection

    models: list[type[BaseModel]] = [ExperimentSection, PlantSection, SweepSection, ScheduleConfig]
    for kind, reg in registry.ALL.items():
        models += [_plugin_model(kind, name) for name in reg.names()]
    unique = list(dict.fromkeys(models))
    refs, top = models_json_schema([(m, "validation") for m in unique], ref_template="#/$defs/{model}")
    names = {model: ref["$ref"].rsplit("/", 1)[1] for (model, _), ref in refs.items()}
    return top["$defs"], names


def _ref(name: str) -> Schema:
    return {"$ref": f"#/$defs/{name}"}


def _notes(schema: Schema) -> Schema:
    """The annotations of ``schema`` that an editor shows (title, description, default)."""
    return {k: schema[k] for k in ("title", "description", "default") if k in schema}


def _union(kind: str, names: dict[type, str], tuned: dict[str, str] | None = None) -> Schema:
    """One of the registered models of ``kind``, each with its ``kind`` required and fixed to
    its registered name; ``tuned``: the definition that replaces a model's when the section
    has ``tune`` (see :func:`_tuned_copies`)."""
    members = []
    for name in registry.ALL[kind].names():
        model = names[_plugin_model(kind, name)]
        member: Schema = {"properties": {"kind": {"const": name}}, "required": ["kind"]}
        if tuned and model in tuned:
            member.update({"if": {"required": ["tune"]}, "then": {"allOf": [_ref(tuned[model])]}})
            member["else"] = {"allOf": [_ref(model)]}
        else:
            member["allOf"] = [_ref(model)]
        members.append(member)
    return {"oneOf": members, "description": f"A registered {registry.ALL[kind].kind} (nlcx list {kind}), by its kind."}


def _refs(node: object) -> set[str]:
    """The definitions ``node`` refers to directly."""
    if isinstance(node, list):
        return set().union(*(_refs(item) for item in node))
    if not isinstance(node, dict):
        return set()
    found = {node["$ref"].rsplit("/", 1)[1]} if isinstance(node.get("$ref"), str) else set()
    return found.union(*(_refs(value) for value in node.values()))


def _rename_refs(node: object, renamed: dict[str, str]) -> None:
    """Every reference in ``node`` to a definition of ``renamed`` pointed at its new name."""
    if isinstance(node, list):
        for item in node:
            _rename_refs(item, renamed)
    elif isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.rsplit("/", 1)[1] in renamed:
            node["$ref"] = f"#/$defs/{renamed[ref.rsplit('/', 1)[1]]}"
        for value in node.values():
            _rename_refs(value, renamed)


def _tuned_copies(defs: Schema, controllers: list[str]) -> dict[str, str]:
    """A tuned controller's gain schedules are completed by its tuners before they are
    validated (:func:`nlcx.config.controller_section`): a copy of each definition from which
    ``schedule`` can be reached, in which a schedule need only name its kind. Returns the
    copy's name of each controller definition (of ``controllers``) that has one."""
    below = {name: _refs(schema) for name, schema in defs.items()}
    reaching = {"schedule"}
    while True:  # the definitions that refer to one that reaches ``schedule``, until none is added
        more = {name for name, refs in below.items() if refs & reaching} - reaching
        if not more:
            break
        reaching |= more
    renamed = {name: f"{name}__tuned" for name in reaching}
    renamed["schedule"] = "schedule_tuned"
    for name in reaching - {"schedule"}:
        defs[renamed[name]] = copy.deepcopy(defs[name])
        _rename_refs(defs[renamed[name]], renamed)
    defs["schedule_tuned"] = {
        "type": "object",
        "properties": {"kind": {"enum": registry.schedules.names()}},
        "required": ["kind"],
        "description": "A gain schedule whose numbers the controller's tuners fill in (nlcx list schedules).",
    }
    return {name: renamed[name] for name in controllers if name in reaching}


def _plant(defs: Schema, names: dict[type, str]) -> None:
    """``plant``: a registered name; the parameters and initial states of the plant it names."""
    from nlcx.config import PlantSection

    section = defs[names[PlantSection]]
    plants = registry.plants.names()
    section["properties"]["name"] = _or_interpolation({**_notes(section["properties"]["name"]), "enum": plants})
    cases = []
    for name in plants:
        states = [s.name for s in getattr(registry.plants.get(name), "states", ())]
        then: Schema = {"params": _or_interpolation(_ref(names[_plugin_model("plants", name)]))}
        if states:
            then["x0"] = _or_interpolation({"type": "object", "propertyNames": {"enum": states}})
        cases.append(
            {"if": {"properties": {"name": {"const": name}}, "required": ["name"]}, "then": {"properties": then}}
        )
    section["allOf"] = cases


def _replace_refs(node: object, old: str, new: Schema) -> None:
    """Every use of the definition ``old`` in ``node`` replaced by ``new``; an ``anyOf`` that
    offered it beside any mapping (``dict[str, Any] | ScheduleConfig``) keeps only ``new``."""
    if isinstance(node, list):
        for item in node:
            _replace_refs(item, old, new)
        return
    if not isinstance(node, dict):
        return
    target = f"#/$defs/{old}"
    options = node.get("anyOf")
    if isinstance(options, list) and {"$ref": target} in options:
        rest = [o for o in options if o != {"$ref": target} and o != {"type": "object", "additionalProperties": True}]
        del node["anyOf"]
        node.update(new if not rest else {"anyOf": [*rest, new]})
    if node.get("$ref") == target:
        del node["$ref"]
        node.update(new)
    for value in node.values():
        _replace_refs(value, old, new)


def _plugin_sections(root: Schema, defs: Schema, names: dict[type, str]) -> None:
    """The plugin sections of the root as unions of the registered models of their kind."""
    from nlcx.controllers.schedules import ScheduleConfig

    for kind, union in _UNIONS.items():
        if kind != "controllers":
            defs[union] = _union(kind, names)
    defs["tune"] = {
        "anyOf": [_ref("tuner"), {"type": "array", "items": _ref("tuner")}],
        "description": "Tuners applied to the controller before it is built, in order (nlcx list tuners).",
    }
    controllers = list(dict.fromkeys(names[_plugin_model("controllers", n)] for n in registry.controllers.names()))
    for name in controllers:
        defs[name]["properties"]["tune"] = _ref("tune")
    _replace_refs(defs, names[ScheduleConfig], _ref("schedule"))
    del defs[names[ScheduleConfig]]
    defs["controller"] = _union("controllers", names, _tuned_copies(defs, controllers))
    props = root["properties"]
    props["controllers"] = {**_notes(props["controllers"]), "type": "object", "minProperties": 1}
    props["controllers"]["additionalProperties"] = _ref("controller")
    props["reference"] = {**_notes(props["reference"]), "type": "object", "additionalProperties": _ref("reference")}
    by_label = {
        name: {"anyOf": [{"allOf": [_ref(names[_plugin_model("uncertainties", name)])]}, _ref("uncertainty")]}
        for name in registry.uncertainties.names()
    }  # a label that is a registered name is the default kind
    props["uncertainty"] = {**_notes(props["uncertainty"]), "type": "object", "properties": by_label}
    props["uncertainty"]["additionalProperties"] = _ref("uncertainty")


def _file_keys(root: Schema, names: dict[type, str]) -> None:
    """What a config file holds besides the experiment: ``extends``, ``vars``, ``sweep``; and
    ``name``, ``plant`` and ``controllers`` are required unless the file extends another."""
    from nlcx.sweeps import SweepSection

    props = root["properties"]
    props["extends"] = {
        "anyOf": [{"type": "string"}, {"type": "array", "items": {"type": "string"}}],
        "description": "Config files (paths relative to this one) merged in order under this file's keys.",
    }
    props["vars"] = {"type": "object", "description": "Named values that other keys refer to as ${vars.name}."}
    props["sweep"] = {**_ref(names[SweepSection]), "description": "The variants of a sweep (nlcx sweep)."}
    required = root.pop("required", [])
    root["anyOf"] = [{"required": ["extends"]}, {"required": required}]


def _walk_values(node: object, wrap: Callable[[Schema], Schema]) -> None:
    """Apply ``wrap`` to every schema of a value in ``node``: a property's, a mapping's values'
    (``additionalProperties``), a list's items'."""
    if isinstance(node, list):
        for item in node:
            _walk_values(item, wrap)
        return
    if not isinstance(node, dict):
        return
    for value in node.values():
        _walk_values(value, wrap)
    if isinstance(node.get("properties"), dict):
        node["properties"] = {k: wrap(v) for k, v in node["properties"].items()}
    for key in ("additionalProperties", "items"):
        if isinstance(node.get(key), dict):
            node[key] = wrap(node[key])
    if isinstance(node.get("prefixItems"), list):
        node["prefixItems"] = [wrap(v) for v in node["prefixItems"]]


def _or_interpolation(schema: Schema) -> Schema:
    """``schema``, or a string holding an interpolation; the annotations stay on the outside."""
    return {**_notes(schema), "anyOf": [schema, _ref("interpolation")]}


def experiment_schema() -> Schema:
    """The JSON Schema (draft 2020-12) of an experiment config file, with every registered plugin.

    Returns
    -------
    dict
        The schema, ready for :func:`json.dumps`; see the module's docstring for what it checks.
    """
    from nlcx.config import ExperimentSection

    defs, names = _definitions()
    root = defs.pop(names[ExperimentSection])
    _plugin_sections(root, defs, names)
    _file_keys(root, names)
    _walk_values(root, _or_interpolation)
    _walk_values(defs, _or_interpolation)
    _plant(defs, names)  # after the values are wrapped: its conditions test the plant's name itself
    defs["interpolation"] = copy.deepcopy(INTERPOLATION)
    head = {"$schema": DIALECT, "title": "nlcx experiment config"}
    return {**head, **{k: v for k, v in root.items() if k != "title"}, "$defs": defs}


def schema_text(schema: Schema) -> str:
    """``schema`` as the text ``nlcx schema`` writes: JSON indented by two spaces, a final newline."""
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"

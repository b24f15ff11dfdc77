"""Validation of a composed, overridden and interpolated config into an :class:`Experiment`.

:func:`build` validates the generic sections by the models of :mod:`nlcx.config.sections`,
then each plugin section (plant parameters, controllers and their tuners, uncertainties,
references) by the model of the plugin its ``name``/``kind`` selects in :mod:`nlcx.registry`.
Every problem is reported as one :class:`~nlcx.errors.ConfigError` line naming the key path,
the value and what is allowed. ``build(raw, like=...)`` takes over the sections of an
experiment validated before whose raw mapping is unchanged (a sweep's variants).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Generic, Protocol, TypeVar

from pydantic import BaseModel

from nlcx import registry
from nlcx.config.sections import ExperimentSection
from nlcx.errors import MISSING, ConfigError
from nlcx.validation import join, validate_model

if TYPE_CHECKING:
    from nlcx.plants.base import PlantParams
    from nlcx.protocols import ControllerPlugin, PlantPlugin, ReferencePlugin, TunerPlugin, UncertaintyPlugin


class _Configured(Protocol):
    """A plugin with a configuration model (every kind but the plants)."""

    @property
    def Config(self) -> type[BaseModel]: ...


#: The protocol of a plugin section's kind (:mod:`nlcx.protocols`).
P = TypeVar("P", bound=_Configured)


@dataclass(frozen=True)
class PluginSection(Generic[P]):
    """A plugin section resolved to its registered model and validated configuration."""

    label: str
    kind: str
    model: P
    #: An instance of the plugin's ``Config``.
    config: BaseModel
    #: Tuners applied to a controller before it is built (``tune:``), in order.
    tuners: tuple[PluginSection[TunerPlugin], ...] = ()


@dataclass(frozen=True)
class Experiment:
    """A fully validated experiment configuration."""

    raw: dict[str, object]
    section: ExperimentSection
    plant_model: PlantPlugin
    plant_params: PlantParams
    controllers: tuple[PluginSection[ControllerPlugin], ...]
    uncertainties: tuple[PluginSection[UncertaintyPlugin], ...]
    references: dict[str, PluginSection[ReferencePlugin]]
    #: Whether its interpolation could read the process (``--allow-env``); recorded in the manifest.
    allow_env: bool = False

    @property
    def name(self) -> str:
        return self.section.name

    def resolved(self) -> dict[str, object]:
        """The configuration with every default filled in, as written to config.yaml."""
        sec = self.section
        return {
            **({"imports": list(sec.imports)} if sec.imports else {}),
            "name": sec.name,
            "title": sec.title,
            "seed": sec.seed,
            "plant": {
                "name": sec.plant.name,
                "params": self.plant_params.model_dump(),
                "x0": dict(sec.plant.x0),
            },
            "controllers": {
                c.label: {
                    **c.config.model_dump(),
                    **({"tune": [t.config.model_dump() for t in c.tuners]} if c.tuners else {}),
                }
                for c in self.controllers
            },
            "uncertainty": {u.label: u.config.model_dump() for u in self.uncertainties},
            "reference": {k: r.config.model_dump() for k, r in self.references.items()},
            "simulation": sec.simulation.model_dump(),
            "metrics": {**sec.metrics.model_dump(), "rise_limits": list(sec.metrics.rise_limits)},
            "outputs": sec.outputs.model_dump(),
        }


def _plugin(
    reg: registry.Registry[P], label: str, data: object, path: str, default_kind: str | None = None
) -> PluginSection[P]:
    """Resolve ``data['kind']`` in ``reg`` and validate ``data`` with that plugin's model."""
    if not isinstance(data, dict):
        raise ConfigError(path, data, "must be a mapping of keys to values")
    kind = data.get("kind", default_kind)
    if kind is None:
        raise ConfigError(join(path, "kind"), MISSING, f"required; allowed: {', '.join(reg.names())}")
    if not isinstance(kind, str):
        raise ConfigError(join(path, "kind"), kind, f"must be a name; allowed: {', '.join(reg.names())}")
    model = reg.get(kind, path=join(path, "kind"))
    cfg = validate_model(model.Config, {**data, "kind": kind}, path)
    return PluginSection(label=label, kind=kind, model=model, config=cfg)


def controller_section(label: str, data: object, path: str) -> PluginSection[ControllerPlugin]:
    """A controller section validated by its registered model, with its tuners."""
    if isinstance(data, dict) and "tune" in data:
        data = dict(data)
        tune = data.pop("tune")
        tune = [tune] if isinstance(tune, dict) else tune
        if not isinstance(tune, list):
            raise ConfigError(join(path, "tune"), tune, "must be a tuner mapping or a list of them")
        tuners = tuple(_plugin(registry.tuners, str(i), t, join(path, "tune", str(i))) for i, t in enumerate(tune))
    else:
        tuners = ()
    c = _plugin(registry.controllers, label, data, path)
    # a tuned controller's nested sections (e.g. its schedule) are completed by its tuners and
    # validated after them (engine.prepare)
    config = c.config if tuners else c.model.normalize(c.config, path)
    return PluginSection(c.label, c.kind, c.model, config, tuners)


def build(raw: dict[str, object], like: Experiment | None = None, allow_env: bool = False) -> Experiment:
    """Validate a raw config mapping (after overrides).

    ``like`` is an experiment validated before, e.g. a sweep's base: its sections whose raw
    mapping equals ``raw``'s (top-level sections; controllers, uncertainties and references one
    by one) are taken over instead of validated again. Validation is deterministic, so the
    result equals ``build(raw)``; a sweep variant that changes a few numbers re-validates only
    the sections holding them. ``allow_env`` is recorded: whether ``raw`` was interpolated
    with every resolver on (:func:`nlcx.config.interpolate`).
    """
    same = _unchanged(raw, like)
    section = validate_model(ExperimentSection, _with_validated_sections(raw, like, same), "")
    plant_model = registry.plants.get(section.plant.name, path="plant.name")
    if like is not None and "plant" in same:
        plant_params = like.plant_params
    else:
        plant_params = validate_model(plant_model.Params, section.plant.params, "plant.params")
    before_controllers = _plugins_by_label(like, "controllers", like.controllers) if like is not None else {}
    before_uncertainties = _plugins_by_label(like, "uncertainty", like.uncertainties) if like is not None else {}
    before_references = _plugins_by_label(like, "reference", like.references.values()) if like is not None else {}
    controllers = tuple(
        _reused(before_controllers, raw, ("controllers", label))
        or controller_section(label, data, join("controllers", label))
        for label, data in section.controllers.items()
    )
    uncertainties = tuple(
        _reused(before_uncertainties, raw, ("uncertainty", label))
        or _plugin(registry.uncertainties, label, data, join("uncertainty", label), default_kind=label)
        for label, data in section.uncertainty.items()
    )
    references = {
        signal: _reused(before_references, raw, ("reference", signal))
        or _plugin(registry.references, signal, data, join("reference", signal))
        for signal, data in section.reference.items()
    }
    return Experiment(
        raw=raw,
        section=section,
        plant_model=plant_model,
        plant_params=plant_params,
        controllers=controllers,
        uncertainties=uncertainties,
        references=references,
        allow_env=allow_env or (like is not None and like.allow_env),
    )


#: Top-level sections validated as a model of their own, which ``build(like=...)`` takes over.
_MODEL_SECTIONS = ("plant", "simulation", "metrics", "outputs")


def _unchanged(raw: dict[str, object], like: Experiment | None) -> set[str]:
    """The top-level keys of ``raw`` whose value equals the one ``like`` was built from."""
    if like is None:
        return set()
    return {key for key, value in raw.items() if key in like.raw and like.raw[key] == value}


def _with_validated_sections(raw: dict[str, object], like: Experiment | None, same: set[str]) -> dict[str, object]:
    """``raw`` with its unchanged model sections replaced by ``like``'s validated ones (pydantic
    takes a validated instance as it is)."""
    if like is None:
        return raw
    return {**raw, **{key: getattr(like.section, key) for key in _MODEL_SECTIONS if key in same}}


def _plugins_by_label(
    exp: Experiment, key: str, plugins: Iterable[PluginSection[P]]
) -> dict[str, tuple[object, PluginSection[P]]]:
    """label -> (the raw mapping it was validated from, the validated plugin), of section ``key``."""
    section = exp.raw.get(key, {})  # a mapping: ``exp`` was validated from it
    return {
        plugin.label: (section.get(plugin.label) if isinstance(section, dict) else None, plugin) for plugin in plugins
    }


def _reused(
    before: dict[str, tuple[object, PluginSection[P]]], raw: dict[str, object], key: tuple[str, str]
) -> PluginSection[P] | None:
    """The plugin validated before from a raw mapping equal to ``raw``'s at ``key``, if any."""
    old = before.get(key[1])
    if old is None or old[0] is None:
        return None
    section = raw[key[0]]  # a mapping: ``raw`` was validated
    if not isinstance(section, dict) or section[key[1]] != old[0]:
        return None
    return old[1]

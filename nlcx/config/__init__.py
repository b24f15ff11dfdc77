"""Experiment configuration: YAML -> typed, validated model, with overrides in Hydra's grammar.

Every default lives in the section models (:mod:`nlcx.config.sections`) or in a plugin's own
model. Every problem is reported as one :class:`~nlcx.errors.ConfigError` line naming the key
path, the value and what is allowed. A config is read in four steps (:func:`load`), one module
each:

1. **Composition** (:func:`read_config`, :mod:`nlcx.config.composition`): the YAML file is
   parsed, and the files its ``extends:`` key names are merged under its own keys by
   :func:`deep_merge` (a plugin section whose ``kind`` changes is replaced whole).
2. **Overrides** (:func:`apply_overrides`, :mod:`nlcx.config.overrides`), in Hydra's override
   grammar: ``key=value`` sets a key (new or not), ``+key=value`` adds a key that must not exist
   yet, ``++key=value`` adds or sets, ``~key`` deletes a key that must exist and ``~key=value``
   deletes it only when it holds that value. Keys are dotted paths; values are parsed as YAML.
3. **Interpolation** (:func:`interpolate`, :mod:`nlcx.config.interpolation`) by OmegaConf's
   rules: ``"${a.b}"`` is replaced by a copy of that key's value, ``"gain_${a.b}"`` by a string,
   and references nest and chain; then the free ``vars`` section is dropped.
4. **Validation** (:func:`build`, :mod:`nlcx.config.building`): the generic sections by their
   models, then each plugin section (plant parameters, controllers, gain schedules,
   uncertainties, references) by the model of the plugin its ``name``/``kind`` selects.
"""

from __future__ import annotations

from pathlib import Path

from nlcx.config.building import Experiment, PluginSection, build, controller_section
from nlcx.config.composition import deep_merge, read_config, read_yaml
from nlcx.config.interpolation import Interpolated, interpolate
from nlcx.config.overrides import OVERRIDE_FORMS, Override, apply_overrides, parse_override, set_values
from nlcx.config.sections import (
    ExperimentSection,
    MetricsSection,
    OutputsSection,
    PlantSection,
    Section,
    SimulationSection,
)
from nlcx.plugins import load_config_imports

__all__ = [
    "OVERRIDE_FORMS",
    "Experiment",
    "ExperimentSection",
    "Interpolated",
    "MetricsSection",
    "OutputsSection",
    "Override",
    "PlantSection",
    "PluginSection",
    "Section",
    "SimulationSection",
    "apply_overrides",
    "build",
    "controller_section",
    "deep_merge",
    "interpolate",
    "load",
    "parse_override",
    "read_config",
    "read_yaml",
    "set_values",
]


def load(path: str | Path, overrides: list[str] | None = None, *, allow_env: bool = False) -> Experiment:
    """Read, override, interpolate and validate an experiment config (the four steps above),
    its plugins imported before it is validated (:func:`nlcx.plugins.load_config_imports`);
    ``allow_env``: every OmegaConf resolver on, ``oc.env`` included (:func:`interpolate`)."""
    raw = load_config_imports(apply_overrides(read_config(path), overrides or []))
    return build(interpolate(raw, allow_env=allow_env), allow_env=allow_env)

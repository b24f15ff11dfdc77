"""Experiment configuration: YAML -> typed, validated model, with overrides in Hydra's grammar.

Every default lives in the pydantic models below or in a plugin's own model. Loading is two
stages: the generic sections first, then each plugin section (plant parameters, controllers,
gain schedules, uncertainties, references) by the model of the plugin its ``name``/``kind``
selects. Every problem is reported as one :class:`~nlcx.errors.ConfigError` line naming the
key path, the value and what is allowed.

A config is read in four steps (:func:`load`):

1. **Composition** (:func:`read_config`): YAML is parsed by PyYAML (``yaml.safe_load``; its
   numbers are the ones the configs were written for) and the files named by ``extends:`` are
   merged under the file's own keys by :func:`deep_merge`. The merge is written out here rather
   than done by ``OmegaConf.merge`` because of its one rule OmegaConf has no place for: a plugin
   section whose ``kind`` changes is replaced whole, not merged key by key. Merging the plain
   mappings also costs a small fraction of converting each file to OmegaConf's containers and
   back.
2. **Overrides** (:func:`apply_overrides`), in Hydra's override grammar: ``key=value`` sets a
   key (new or not), ``+key=value`` adds a key that must not exist yet, ``++key=value`` adds or
   sets, ``~key`` deletes a key that must exist and ``~key=value`` deletes it only when it holds
   that value. Keys are dotted paths; values are parsed as YAML.
3. **Interpolation** (:func:`interpolate`) by OmegaConf's rules: ``"${a.b}"`` is replaced by a
   copy of that key's value (a number, a mapping, a list), ``"gain_${a.b}"`` by a string, and
   references nest and chain; then the free ``vars`` section is dropped. The reference that
   takes a whole value and names an absolute key (``"${vars.gains}"``, the only kind the configs
   use) is resolved by a short walk here, to the same result; OmegaConf resolves every other
   kind, and reports every failure (a missing key, a circular reference). The walk exists for
   speed: a sweep interpolates its base once per batch of variants, and a variant that sets a
   referenced key (one of ``vars``, say) is interpolated in full, so this step runs thousands
   of times where converting to and from OmegaConf's containers would cost more than building
   the variant does.
4. **Validation** (:func:`build`) by the section models below and the plugins' models.
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, cast

import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nlcx import registry
from nlcx.errors import MISSING, ConfigError
from nlcx.validation import join, validate_model

if TYPE_CHECKING:
    from omegaconf.errors import OmegaConfBaseException


class Section(BaseModel):
    """Base of the section models: unknown keys are errors.

    Each field's ``description`` (with its ``unit`` in the JSON schema where it has one) is what
    the configuration reference documents.
    """

    model_config = ConfigDict(extra="forbid")


class PlantSection(Section):
    """The plant: a registered model by name, its parameters and its initial state.

    The parameters are validated by the plant's own parameter model, which holds their defaults
    and units.
    """

    name: str = Field(description="Registered plant name (``nlcx list plants``).")
    params: dict[str, Any] = Field(
        default={}, description="Parameter overrides; the defaults come from the plant's parameter model."
    )
    x0: dict[str, float] = Field(
        default={}, description="Initial state by state name, in the state's units; unlisted states start at 0."
    )


class SimulationSection(Section):
    """Time grid, integrator and stability bounds of a run.

    The controllers are sampled at every integration step, so ``dt`` is also the sampling
    period; ``t_end`` must be a whole number of steps.
    """

    t_end: float = Field(20.0, gt=0, description="Final time, s.", json_schema_extra={"unit": "s"})
    dt: float = Field(
        1e-3,
        gt=0,
        description="Integration step and controller sampling period, s.",
        json_schema_extra={"unit": "s"},
    )
    integrator: Literal["rk4", "heun", "euler"] = Field("rk4", description="Fixed-step explicit Runge-Kutta method.")
    bounds: dict[str, float] = Field(
        default={},
        description=(
            "Bound on |state| by state name, in the state's units: a run stops as unstable when a state "
            "exceeds its bound or becomes non-finite (plants add defaults, e.g. |theta| <= pi/2 for the pendulums)."
        ),
    )

    @field_validator("bounds")
    @classmethod
    def _positive_bounds(cls, bounds: dict[str, float]) -> dict[str, float]:
        for key, value in bounds.items():
            if not value > 0:
                raise ValueError(f"bound of {key} must be > 0")
        return bounds


class MetricsSection(Section):
    """Definitions of the step-response metrics, see docs/metrics.md.

    The settling band and the rise limits are fractions of the step (step signals) or of the
    peak deviation (regulated signals); the steady-state window is in seconds.
    """

    settling_band: float = Field(
        0.02,
        gt=0,
        lt=1,
        description=(
            "Settling band as a fraction of the step size (step signals) or of the peak deviation (regulated signals)."
        ),
    )
    rise_limits: tuple[float, float] = Field(
        (0.1, 0.9), description="Rise time between these fractions of the step, low and high."
    )
    ss_window: float = Field(
        1.0,
        gt=0,
        description="Window at the end of the run over which the steady-state value is averaged, s.",
        json_schema_extra={"unit": "s"},
    )
    regulation_abs_tol: float = Field(
        0.0, ge=0, description="Absolute floor of the settling band of a regulated signal, in the signal's units."
    )

    @field_validator("rise_limits")
    @classmethod
    def _ordered(cls, limits: tuple[float, float]) -> tuple[float, float]:
        lo, hi = limits
        if not 0 <= lo < hi <= 1:
            raise ValueError("rise_limits must satisfy 0 <= low < high <= 1")
        return limits


class OutputsSection(Section):
    """What a run writes into its run directory besides metrics.csv and config.yaml."""

    dir: str | None = Field(None, description="Run directory; default results/<name>. ``--out`` overrides it.")
    timeseries: bool = Field(True, description="Write the time series (every sample of every controller).")
    timeseries_format: Literal["csv", "parquet"] = Field(
        "csv",
        description=(
            "File of the time series: timeseries.csv, or timeseries.parquet (binary, every float exact, zstd: "
            "about 40 % of the CSV's size and a third of its writing time; for long or many runs)."
        ),
    )
    figure: bool = Field(True, description="Write the thesis-style figure (figure.png).")
    gains_figure: bool = Field(
        False,
        description=(
            "Also write gains.png: every input and every logged gain against time, one panel each "
            "(off by default: it is slow to draw when there are many panels)."
        ),
    )
    figure_inputs: bool = Field(False, description="Add an axes per plant input to figure.png, below the outputs.")
    figure_metrics: list[str] = Field(
        default_factory=list, description="Metrics quoted in figure.png's legend, e.g. [ise, control_effort]."
    )


class ExperimentSection(Section):
    """A whole experiment: one plant, the controllers compared on it, and how it is run.

    The plugin sections (``controllers``, ``uncertainty``, ``reference``) hold raw mappings here;
    :func:`build` validates each by the model of the plugin its ``kind`` selects.
    """

    name: str = Field(
        pattern=r"^[A-Za-z0-9_.\-]+$",
        description="Experiment name (letters, digits, _, . and -); the default run directory is results/<name>.",
    )
    title: str | None = Field(None, description="Figure title (e.g. the thesis's caption).")
    seed: int = Field(0, ge=0, description="Root of numpy.random.SeedSequence for everything random in the run.")
    plant: PlantSection = Field(description="The plant and its parameters.")
    controllers: dict[str, dict[str, Any]] = Field(
        min_length=1, description="Controllers compared side by side, by label (e.g. conventional, proposed)."
    )
    uncertainty: dict[str, dict[str, Any]] = Field(
        default={}, description="Uncertainties by label; each has ``kind`` (default: the label)."
    )
    reference: dict[str, dict[str, Any]] = Field(
        default={}, description="References by signal name; outputs not listed are regulated to 0."
    )
    simulation: SimulationSection = Field(
        default_factory=SimulationSection, description="Time grid, integrator and stability bounds."
    )
    metrics: MetricsSection = Field(default_factory=MetricsSection, description="Definitions of the metrics.")
    outputs: OutputsSection = Field(default_factory=OutputsSection, description="What the run directory holds.")


@dataclass(frozen=True)
class PluginSection:
    """A plugin section resolved to its registered model and validated configuration."""

    label: str
    kind: str
    model: Any
    config: Any
    #: Tuners applied to a controller before it is built (``tune:``), in order.
    tuners: tuple[PluginSection, ...] = ()


@dataclass(frozen=True)
class Experiment:
    """A fully validated experiment configuration."""

    raw: dict[str, Any]
    section: ExperimentSection
    plant_model: Any
    plant_params: Any
    controllers: tuple[PluginSection, ...]
    uncertainties: tuple[PluginSection, ...]
    references: dict[str, PluginSection]

    @property
    def name(self) -> str:
        return self.section.name

    def resolved(self) -> dict[str, Any]:
        """The configuration with every default filled in, as written to config.yaml."""
        sec = self.section
        return {
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


#: What an override may look like (Hydra's override grammar).
OVERRIDE_FORMS = (
    "an override must look like section.key=value (set), +section.key=value (add a new key), "
    "++section.key=value (add or set), ~section.key or ~section.key=value (delete)"
)


@dataclass(frozen=True)
class Override:
    """One override in Hydra's grammar (see :func:`parse_override`)."""

    #: ``set`` (key=value), ``add`` (+key=value), ``force`` (++key=value) or ``delete`` (~key).
    action: Literal["set", "add", "force", "delete"]
    #: The dotted key, split at its dots.
    key: tuple[str, ...]
    #: The value parsed as YAML; for a delete, the value the key must hold (MISSING: any value).
    value: Any
    #: The override as written.
    text: str

    @property
    def dotted(self) -> str:
        """The key as written, ``section.key``."""
        return ".".join(self.key)


_PREFIXES: tuple[tuple[str, Literal["set", "add", "force", "delete"]], ...] = (
    ("++", "force"),
    ("+", "add"),
    ("~", "delete"),
)


def parse_override(text: str) -> Override:
    """Parse one override in Hydra's grammar.

    Parameters
    ----------
    text
        ``key=value``, ``+key=value``, ``++key=value``, ``~key`` or ``~key=value``; the key is a
        dotted path (``simulation.t_end``), the value is parsed as YAML (empty: null).

    Returns
    -------
    Override
        The action, the key split at its dots and the parsed value.

    Raises
    ------
    ConfigError
        The override has none of these forms, or its value is not valid YAML.
    """
    body = text.lstrip()
    action: Literal["set", "add", "force", "delete"] = "set"
    for prefix, name in _PREFIXES:
        if body.startswith(prefix):
            action, body = name, body[len(prefix) :]
            break
    key, sep, value = body.partition("=")
    key = key.strip()
    parts = tuple(key.split("."))
    if (not sep and action != "delete") or not key or key[0] in "+~" or not all(parts):
        raise ConfigError("", text, OVERRIDE_FORMS)
    if not sep:
        return Override(action, parts, MISSING, text)
    try:
        parsed = yaml.safe_load(value) if value.strip() else None
    except yaml.YAMLError as exc:
        raise ConfigError(key, value, f"not valid YAML: {exc.problem}") from None
    return Override(action, parts, parsed, text)


def apply_overrides(raw: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """A deep copy of ``raw`` with each override (Hydra's grammar, :func:`parse_override`) applied in order.

    ``key=value`` and ``++key=value`` set the key whether it exists or not (creating the
    mappings above it); ``+key=value`` adds a key and is an error where it exists;
    ``~key`` deletes a key and is an error where it does not exist; ``~key=value`` also
    requires the key to hold that value.
    """
    data = copy.deepcopy(raw)
    for text in overrides:
        data = _apply(data, parse_override(text))
    return data


def _apply(data: dict[str, Any], override: Override) -> dict[str, Any]:
    """``data`` with one override applied (the mappings on the key's path copied)."""
    if override.action in ("set", "force"):
        return set_values(data, [(list(override.key), override.value)])
    found, current = _find(data, override.key)
    if override.action == "add":
        if found:
            raise ConfigError(
                override.dotted,
                current,
                "already set; +key=value adds a new key only (key=value or ++key=value sets it)",
            )
        return set_values(data, [(list(override.key), override.value)])
    if not found:
        raise ConfigError(override.dotted, MISSING, "not in the config, so ~key cannot delete it")
    if override.value is not MISSING and not _same(current, override.value):
        raise ConfigError(
            override.dotted, current, f"{override.text.strip()} deletes it only where its value is {override.value!r}"
        )
    return _without(data, override.key)


def _find(data: dict[str, Any], key: tuple[str, ...]) -> tuple[bool, Any]:
    """(whether ``key`` is in ``data``, its value or None)."""
    node: Any = data
    for part in key:
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _same(current: Any, value: Any) -> bool:
    """Equal values, where a boolean equals only a boolean (``True == 1`` in Python)."""
    return isinstance(current, bool) == isinstance(value, bool) and current == value


def _without(data: dict[str, Any], key: tuple[str, ...]) -> dict[str, Any]:
    """A copy of ``data`` without the (existing) ``key``; only the mappings on its path are copied."""
    out = dict(data)
    node = out
    for part in key[:-1]:
        node[part] = dict(node[part])
        node = node[part]
    del node[key[-1]]
    return out


def set_values(raw: dict[str, Any], values: list[tuple[list[str], Any]]) -> dict[str, Any]:
    """A copy of ``raw`` with each (key path, value) set; only the mappings on the paths are
    copied, the rest is shared with ``raw`` (treat both as read-only afterwards)."""
    data = dict(raw)
    for parts, value in values:
        node = data
        for i, part in enumerate(parts[:-1]):
            child = node.get(part)
            if child is None:
                child = {}
            if not isinstance(child, dict):
                raise ConfigError(".".join(parts[: i + 1]), child, "is not a mapping, so it has no sub-keys")
            child = node[part] = dict(child)
            node = child
        node[parts[-1]] = copy.deepcopy(value)
    return data


def deep_merge(base: dict[str, Any], top: dict[str, Any]) -> dict[str, Any]:
    """``top`` over ``base``: mappings merge key by key, anything else replaces.

    A plugin section whose ``kind`` changes (e.g. a step reference replaced by a sine) is
    replaced whole, since the two kinds have different keys.
    """
    out = copy.deepcopy(base)
    for key, value in top.items():
        old = out.get(key)
        changes_kind = (
            isinstance(old, dict) and isinstance(value, dict) and value.get("kind", old.get("kind")) != old.get("kind")
        )
        if isinstance(value, dict) and isinstance(old, dict) and not changes_kind:
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def read_config(path: str | Path, _seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """Read a config file, first merging the files its ``extends`` key names.

    ``extends`` is a path or a list of paths relative to the file; they are merged in order
    and the file's own keys go on top (see :func:`deep_merge`).
    """
    path = Path(path).resolve()
    if path in _seen:
        raise ConfigError("extends", str(path), "circular extends")
    data = read_yaml(path)
    parents = data.pop("extends", [])
    if isinstance(parents, str):
        parents = [parents]
    if not isinstance(parents, list) or not all(isinstance(p, str) for p in parents):
        raise ConfigError("extends", parents, "must be a file path or a list of file paths")
    merged: dict[str, Any] = {}
    for parent in parents:
        merged = deep_merge(merged, read_config(path.parent / parent, (*_seen, path)))
    return deep_merge(merged, data)


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Parse a YAML file with ``yaml.safe_load``; it must hold a mapping."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("", str(path), "config file not found")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        raise ConfigError("", str(path), f"not valid YAML{where}: {getattr(exc, 'problem', exc)}") from None
    if not isinstance(data, dict):
        raise ConfigError("", str(path), "a config file must hold a mapping of sections")
    return data


#: A key part that OmegaConf's interpolation grammar and a plain mapping lookup read alike.
_KEY = r"[A-Za-z_][A-Za-z0-9_\-]*"
#: A reference to an absolute dotted key, ``${a.b.c}``.
_REFERENCE = re.compile(rf"\$\{{({_KEY}(?:\.{_KEY})*)\}}")
#: OmegaConf's marker of a missing value; a reference to it is an error.
_MISSING_VALUE = "???"


class _NotDirectError(Exception):
    """The direct walk of :func:`interpolate` stops: OmegaConf resolves the config (or reports its error)."""


def interpolate(raw: dict[str, Any]) -> dict[str, Any]:
    """Resolve every ``${...}`` reference by OmegaConf's rules, then drop ``vars``.

    ``"${dotted.key}"`` is replaced by a copy of that key's value, ``"x_${a}"`` by a string,
    and references chain and nest. ``vars`` is a free section for named values that other
    keys refer to, e.g. the conventional gains shared by the x and y loops of the thesis's
    pendulums.

    Raises
    ------
    ConfigError
        One line naming the key that holds the failing reference: it refers to a key that does
        not exist, is part of a circular reference, or is not a valid interpolation.
    """
    try:
        out = _resolved_directly(raw)
    except _NotDirectError:
        out = _resolved_by_omegaconf(raw)
    out.pop("vars", None)
    return out


def _resolved_directly(raw: dict[str, Any]) -> dict[str, Any]:
    """``raw`` with each whole-value reference to an absolute key (``"${a.b}"``) replaced by its
    resolved value, as OmegaConf resolves it; :class:`_NotDirectError` for any other reference
    and for any reference that does not resolve (OmegaConf then resolves it or reports it)."""

    def lookup(path: str, trail: tuple[str, ...]) -> Any:
        if path in trail:
            raise _NotDirectError
        node: Any = raw
        for part in path.split("."):
            if not isinstance(node, dict) or part not in node:
                raise _NotDirectError
            node = node[part]
        if isinstance(node, str) and node == _MISSING_VALUE:
            raise _NotDirectError
        return resolve(node, (*trail, path))

    def resolve(node: Any, trail: tuple[str, ...]) -> Any:
        if isinstance(node, dict):
            return {k: resolve(v, trail) for k, v in node.items()}
        if isinstance(node, list):
            return [resolve(v, trail) for v in node]
        if isinstance(node, str) and "${" in node:
            match = _REFERENCE.fullmatch(node)
            if match is None:
                raise _NotDirectError
            return lookup(match.group(1), trail)
        return node

    return resolve(raw, ())


def _resolved_by_omegaconf(raw: dict[str, Any]) -> dict[str, Any]:
    """``raw`` resolved by ``OmegaConf.to_container(..., resolve=True)``: plain mappings and lists
    again, every other value (PyYAML's numbers included) as it was."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        resolved = OmegaConf.to_container(OmegaConf.create(raw, flags={"allow_objects": True}), resolve=True)
    except OmegaConfBaseException as exc:
        raise _interpolation_error(raw, exc) from None
    return cast(dict[str, Any], resolved)


def _interpolation_error(raw: dict[str, Any], exc: OmegaConfBaseException) -> ConfigError:
    """OmegaConf's error as one line: the key holding the reference, its value and the problem."""
    where = getattr(exc, "full_key", None) or ""
    parts = [index or key for index, key in re.findall(r"\[(\d+)\]|([^.\[\]]+)", where)]
    value = _raw_value(raw, parts)
    lines = str(getattr(exc, "msg", None) or exc).splitlines()
    problem = lines[0] if lines else type(exc).__name__
    if missing := re.fullmatch(r"Interpolation key '(.*)' not found", problem):
        return ConfigError(".".join(parts), value, f"refers to {missing.group(1)}, a key that does not exist")
    if problem in ("Recursive interpolation detected", "Interpolation to parent node detected"):
        return ConfigError(".".join(parts), value, "circular reference: the value refers back to itself")
    return ConfigError(".".join(parts), value, f"cannot be interpolated: {problem}")


def _raw_value(raw: dict[str, Any], parts: list[str]) -> Any:
    """The value at a key path whose list indices are digits, or MISSING."""
    node: Any = raw
    for part in parts:
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return MISSING
    return node


def _reference_targets(node: Any) -> set[tuple[str, ...]]:
    """The key paths that the ``${...}`` references anywhere in ``node`` refer to; the empty path
    (every key) for a reference whose target is not an absolute dotted key (a relative or
    nested reference, a resolver)."""
    if isinstance(node, dict):
        return set().union(*(_reference_targets(v) for v in node.values()))
    if isinstance(node, list):
        return set().union(*(_reference_targets(v) for v in node))
    if isinstance(node, str) and "${" in node:
        targets = {tuple(path.split(".")) for path in _REFERENCE.findall(node)}
        return targets | {()} if "${" in _REFERENCE.sub("", node) else targets
    return set()


@dataclass(frozen=True)
class Interpolated:
    """A raw config interpolated once, for the many configs that set a few values on it (a
    sweep's variants): :meth:`resolve` gives exactly ``interpolate(set_values(raw, values))``,
    without interpolating the whole config again when no value can change what a reference
    resolves to."""

    raw: dict[str, Any]
    resolved: dict[str, Any]
    targets: frozenset[tuple[str, ...]]

    @classmethod
    def of(cls, raw: dict[str, Any]) -> Interpolated:
        return cls(raw, interpolate(raw), frozenset(_reference_targets(raw)))

    def resolve(self, values: list[tuple[list[str], Any]]) -> dict[str, Any]:
        """``interpolate(set_values(raw, values))``: the values set on the interpolated config
        when each is independent of interpolation (:meth:`_independent`), else the full path.
        Both share unchanged parts with ``raw`` or ``resolved`` (treat them as read-only)."""
        if all(self._independent(parts, value) for parts, value in values):
            return set_values(self.resolved, values)
        return interpolate(set_values(self.raw, values))

    def _independent(self, parts: list[str], value: Any) -> bool:
        """Whether setting ``value`` at ``parts`` commutes with interpolation: the value holds
        no reference; no reference points at, into or above the key (one whose target is not
        an absolute dotted key, a relative or nested reference, points above every key); the
        key is not in ``vars`` (which interpolation drops); and the raw config holds a mapping
        (or nothing) at every key above it, as :func:`set_values` requires (else the full path
        reports it)."""
        key = tuple(parts)
        if key[0] == "vars" or _reference_targets(value):
            return False
        if any(target[: len(key)] == key or key[: len(target)] == target for target in self.targets):
            return False
        node: Any = self.raw
        for part in key[:-1]:
            node = node.get(part)
            if node is None:
                return True
            if not isinstance(node, dict):
                return False
        return True


def load(path: str | Path, overrides: list[str] | None = None) -> Experiment:
    """Read, override, interpolate and validate an experiment config."""
    return build(interpolate(apply_overrides(read_config(path), overrides or [])))


def _plugin(
    reg: registry.Registry[Any], label: str, data: Any, path: str, default_kind: str | None = None
) -> PluginSection:
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


def controller_section(label: str, data: Any, path: str) -> PluginSection:
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


def build(raw: dict[str, Any], like: Experiment | None = None) -> Experiment:
    """Validate a raw config mapping (after overrides).

    ``like`` is an experiment validated before, e.g. a sweep's base: its sections whose raw
    mapping equals ``raw``'s (top-level sections; controllers, uncertainties and references one
    by one) are taken over instead of validated again. Validation is deterministic, so the
    result equals ``build(raw)``; a sweep variant that changes a few numbers re-validates only
    the sections holding them.
    """
    same = _unchanged(raw, like)
    section = validate_model(ExperimentSection, _with_validated_sections(raw, like, same), "")
    plant_model = registry.plants.get(section.plant.name, path="plant.name")
    if like is not None and "plant" in same:
        plant_params = like.plant_params
    else:
        plant_params = validate_model(plant_model.Params, section.plant.params, "plant.params")
    before = _plugins_by_key(like) if like is not None else {}
    controllers = tuple(
        _reused(before, raw, ("controllers", label)) or controller_section(label, data, join("controllers", label))
        for label, data in section.controllers.items()
    )
    uncertainties = tuple(
        _reused(before, raw, ("uncertainty", label))
        or _plugin(registry.uncertainties, label, data, join("uncertainty", label), default_kind=label)
        for label, data in section.uncertainty.items()
    )
    references = {
        signal: _reused(before, raw, ("reference", signal))
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
    )


#: Top-level sections validated as a model of their own, which ``build(like=...)`` takes over.
_MODEL_SECTIONS = ("plant", "simulation", "metrics", "outputs")


def _unchanged(raw: dict[str, Any], like: Experiment | None) -> set[str]:
    """The top-level keys of ``raw`` whose value equals the one ``like`` was built from."""
    if like is None:
        return set()
    return {key for key, value in raw.items() if key in like.raw and like.raw[key] == value}


def _with_validated_sections(raw: dict[str, Any], like: Experiment | None, same: set[str]) -> dict[str, Any]:
    """``raw`` with its unchanged model sections replaced by ``like``'s validated ones (pydantic
    takes a validated instance as it is)."""
    if like is None:
        return raw
    return {**raw, **{key: getattr(like.section, key) for key in _MODEL_SECTIONS if key in same}}


def _plugins_by_key(exp: Experiment) -> dict[tuple[str, str], tuple[Any, PluginSection]]:
    """(section, label) -> (the raw mapping it was validated from, the validated plugin)."""
    found: dict[tuple[str, str], tuple[Any, PluginSection]] = {}
    for key, plugins in (
        ("controllers", exp.controllers),
        ("uncertainty", exp.uncertainties),
        ("reference", tuple(exp.references.values())),
    ):
        for plugin in plugins:
            found[(key, plugin.label)] = (exp.raw.get(key, {}).get(plugin.label), plugin)
    return found


def _reused(
    before: dict[tuple[str, str], tuple[Any, PluginSection]], raw: dict[str, Any], key: tuple[str, str]
) -> PluginSection | None:
    """The plugin validated before from a raw mapping equal to ``raw``'s at ``key``, if any."""
    old = before.get(key)
    if old is None or old[0] is None or raw[key[0]][key[1]] != old[0]:
        return None
    return old[1]

"""Experiment configuration: YAML -> typed, validated model, with ``key=value`` overrides.

Every default lives in the pydantic models below or in a plugin's own model. Loading is two
stages: the generic sections first, then each plugin section (plant parameters, controllers,
gain schedules, uncertainties, references) by the model of the plugin its ``name``/``kind``
selects. Every problem is reported as one :class:`~nlcx.errors.ConfigError` line naming the
key path, the value and what is allowed.
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nlcx import registry
from nlcx.errors import MISSING, ConfigError
from nlcx.validation import join, validate_model


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid")


class PlantSection(Section):
    #: Registered plant name (``nlcx list plants``).
    name: str
    #: Parameter overrides; defaults come from the plant's parameter model.
    params: dict[str, Any] = {}
    #: Initial state by state name; unlisted states start at 0.
    x0: dict[str, float] = {}


class SimulationSection(Section):
    #: Final time, s.
    t_end: float = Field(20.0, gt=0)
    #: Integration step and controller sampling period, s.
    dt: float = Field(1e-3, gt=0)
    #: Fixed-step explicit Runge-Kutta method.
    integrator: Literal["rk4", "heun", "euler"] = "rk4"
    #: A run stops as unstable when |state| exceeds its bound (plants add defaults, e.g.
    #: |theta| <= pi/2 for the pendulums) or becomes non-finite.
    bounds: dict[str, float] = {}

    @field_validator("bounds")
    @classmethod
    def _positive_bounds(cls, bounds: dict[str, float]) -> dict[str, float]:
        for key, value in bounds.items():
            if not value > 0:
                raise ValueError(f"bound of {key} must be > 0")
        return bounds


class MetricsSection(Section):
    """Metric definitions, see docs/metrics.md."""

    #: Settling band as a fraction of the step size (step signals) or of the peak
    #: deviation (regulated signals).
    settling_band: float = Field(0.02, gt=0, lt=1)
    #: Rise time between these fractions of the step.
    rise_limits: tuple[float, float] = (0.1, 0.9)
    #: Window at the end of the run over which the steady-state value is averaged, s.
    ss_window: float = Field(1.0, gt=0)
    #: Absolute floor of the settling band of a regulated signal, in its units.
    regulation_abs_tol: float = Field(0.0, ge=0)

    @field_validator("rise_limits")
    @classmethod
    def _ordered(cls, limits: tuple[float, float]) -> tuple[float, float]:
        lo, hi = limits
        if not 0 <= lo < hi <= 1:
            raise ValueError("rise_limits must satisfy 0 <= low < high <= 1")
        return limits


class OutputsSection(Section):
    #: Run directory; default results/<name>. ``--out`` overrides it.
    dir: str | None = None
    #: Write the time series (every sample of every controller).
    timeseries: bool = True
    #: Its file: timeseries.csv, or timeseries.parquet (binary, every float exact, zstd:
    #: ~40 % of the CSV's size and a third of its writing time; for long or many runs).
    timeseries_format: Literal["csv", "parquet"] = "csv"
    #: Write the thesis-style figure (figure.png).
    figure: bool = True
    #: Also write gains.png: every input and every logged gain against time (one panel each;
    #: off by default because it costs about a second per twenty panels).
    gains_figure: bool = False
    #: Add an axes per plant input to figure.png (below the outputs).
    figure_inputs: bool = False
    #: Metrics quoted in figure.png's legend, e.g. [ise, control_effort].
    figure_metrics: list[str] = Field(default_factory=list)


class ExperimentSection(Section):
    name: str = Field(pattern=r"^[A-Za-z0-9_.\-]+$")
    #: Figure title (e.g. the thesis's caption).
    title: str | None = None
    #: Root of numpy.random.SeedSequence for everything random in the run.
    seed: int = Field(0, ge=0)
    plant: PlantSection
    #: Controllers compared side by side, by label (e.g. conventional, proposed).
    controllers: dict[str, dict[str, Any]] = Field(min_length=1)
    #: Uncertainties by label; each has ``kind`` (default: the label).
    uncertainty: dict[str, dict[str, Any]] = {}
    #: References by signal name; outputs not listed are regulated to 0.
    reference: dict[str, dict[str, Any]] = {}
    simulation: SimulationSection = Field(default_factory=SimulationSection)
    metrics: MetricsSection = Field(default_factory=MetricsSection)
    outputs: OutputsSection = Field(default_factory=OutputsSection)


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


def parse_override(text: str) -> tuple[list[str], Any]:
    """``a.b.c=value`` -> (["a", "b", "c"], value parsed as YAML)."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip() or any(not part for part in key.strip().split(".")):
        raise ConfigError("", text, "an override must look like section.key=value")
    try:
        parsed = yaml.safe_load(value) if value.strip() else None
    except yaml.YAMLError as exc:
        raise ConfigError(key.strip(), value, f"not valid YAML: {exc.problem}") from None
    return key.strip().split("."), parsed


def apply_overrides(raw: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """A deep copy of ``raw`` with each ``dotted.key=value`` override set (Hydra style)."""
    return set_values(copy.deepcopy(raw), [parse_override(text) for text in overrides])


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


_REFERENCE = re.compile(r"\$\{([A-Za-z0-9_.\-]+)\}")


def interpolate(raw: dict[str, Any]) -> dict[str, Any]:
    """Replace every value ``"${dotted.key}"`` by a copy of that key's value, then drop ``vars``.

    ``vars`` is a free section for named values that other keys refer to, e.g. the
    conventional gains shared by the x and y loops of the thesis's pendulums.
    """

    def lookup(path: str, trail: tuple[str, ...]) -> Any:
        if path in trail:
            raise ConfigError(path, "${" + path + "}", "circular reference")
        node: Any = raw
        for part in path.split("."):
            if not isinstance(node, dict) or part not in node:
                raise ConfigError(
                    trail[-1] if trail else path, "${" + path + "}", "refers to a key that does not exist"
                )
            node = node[part]
        return resolve(node, (*trail, path))

    def resolve(node: Any, trail: tuple[str, ...]) -> Any:
        if isinstance(node, dict):
            return {k: resolve(v, trail) for k, v in node.items()}
        if isinstance(node, list):
            return [resolve(v, trail) for v in node]
        if isinstance(node, str) and (match := _REFERENCE.fullmatch(node.strip())):
            return copy.deepcopy(lookup(match.group(1), trail))
        return node

    out = resolve(raw, ())
    out.pop("vars", None)
    return out


def _reference_targets(node: Any) -> set[tuple[str, ...]]:
    """The key paths that the ``"${dotted.key}"`` values anywhere in ``node`` refer to."""
    if isinstance(node, dict):
        return set().union(*(_reference_targets(v) for v in node.values()))
    if isinstance(node, list):
        return set().union(*(_reference_targets(v) for v in node))
    if isinstance(node, str) and (match := _REFERENCE.fullmatch(node.strip())):
        return {tuple(match.group(1).split("."))}
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
        no reference; no reference points at, into or above the key; the key is not in
        ``vars`` (which interpolation drops); and the raw config holds a mapping (or nothing)
        at every key above it, as :func:`set_values` requires (else the full path reports it)."""
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

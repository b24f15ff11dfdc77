"""The claims table, ``nlcx/thesis/data/claims.yaml``: read, and refused where it is inconsistent.

Two sections. ``thresholds``: every named limit, once, with its value, unit and what it
decides. ``claims``: one entry per statement of the thesis about one plant (a pendulum of
chapters 2-4, the CSTR of chapter 5), in the order of ``claims.csv``, with

- ``id``, ``chapter``, ``pendulum`` (the plant, as ``claims.csv`` names it: x, xy, xz, xyz,
  cstr);
- ``source`` (what ``claims.csv`` cites: "Table 2.3", "Fig. 2.9", ...) and ``claim`` (our
  paraphrase, the ``claim`` column);
- ``section`` and ``quote``: the thesis's own words and the section they stand in (sentences
  not adjacent in the thesis are joined by " [...] "; a claim the thesis states only in a
  table quotes the table's caption);
- ``checks``: each a ``kind`` (:data:`nlcx.thesis.claims.checks.KINDS`), the ``run`` (or runs)
  of the thesis tables and figures it reads, and, where the kind does not fix them, its
  ``controllers``, ``signals`` and ``metric``, and ``than`` (the controllers it compares
  them with); ``thresholds`` names its limits; ``evidence: false`` leaves its numbers out of
  the claim's evidence (it still decides the verdict);
- optionally ``all_or_nothing: true``: the claim is ``yes`` when every check holds and ``no``
  otherwise, never ``partly``.

:func:`parse` refuses, with one line naming the key, the value and what is allowed, an
unknown kind or key, a threshold named but not declared or declared but never named, a run
that is not one of the claim's plant and chapter, or not what its kind reads (the schedule
and mode of a pendulum's run; Table 5.8 or Fig. 5.19), a controller or metric its kind
cannot read, an empty source, claim, section or quote, and a repeated id.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import yaml

from nlcx.errors import MISSING, ConfigError, NlcxError
from nlcx.thesis import catalog
from nlcx.thesis.catalog import FigureSpec, TableSpec
from nlcx.thesis.claims.checks import KINDS, Check, Kind

#: The table as the package ships it.
FILENAME = "claims.yaml"
#: The plants of each chapter, in the order of their claims.
CHAPTER_PLANTS = {2: ("x",), 3: ("xy", "xz"), 4: ("xyz",), 5: ("cstr",)}
CLAIM_KEYS = ("id", "chapter", "pendulum", "source", "claim", "section", "quote", "checks", "all_or_nothing")
CHECK_KEYS = ("kind", "run", "controllers", "signals", "metric", "than", "thresholds", "evidence")
THRESHOLD_KEYS = ("value", "unit", "description")
REFERENCE = re.compile(r"(Table|Fig\.) \d+\.\d+")
#: What a check's ``run`` may name.
RUNS = "a metrics table or a result figure of chapters 2-4 (e.g. Table 2.3, Fig. 2.9), Table 5.8 or a CSTR figure"


@dataclass(frozen=True)
class Threshold:
    """A named limit of the checks: its value, unit ("" for a ratio) and what it decides."""

    name: str
    value: float
    unit: str
    description: str


@dataclass(frozen=True)
class Claim:
    """One statement of the thesis about one plant, and the checks that decide it
    (``all_or_nothing``: yes or no, never partly)."""

    id: str
    chapter: int
    pendulum: str
    source: str
    text: str
    section: str
    quote: str
    checks: tuple[Check, ...]
    all_or_nothing: bool = False


@dataclass(frozen=True)
class ClaimTable:
    """The named thresholds and the claims, in the order of ``claims.csv``."""

    thresholds: Mapping[str, Threshold]
    claims: tuple[Claim, ...]

    def limits(self, check: Check) -> dict[str, float]:
        """The check's thresholds by the roles its kind gives them."""
        roles = KINDS[check.kind].thresholds
        return {role: self.thresholds[name].value for role, name in zip(roles, check.thresholds, strict=True)}


@cache
def thesis_runs() -> dict[str, FigureSpec | TableSpec]:
    """The runs behind each thesis reference a claim may read: "Fig. 2.4" and "Table 2.3" -> the
    stabilisation or tracking figure of chapters 2-4 whose run each shows (a metrics table
    shows its figure's run); "Fig. 5.19" -> that CSTR figure, "Table 5.8" -> the table (one run
    per tuning method). The specs' config paths are relative to the configs' root."""
    figures = {f"Fig. {f.figure}": f for f in catalog.figures(Path()) if f.kind == "response"}
    by_config = {f.configs[0]: f for f in figures.values()}
    tables = {f"Table {t.table}": by_config[t.configs[0]] for t in catalog.tables(Path()) if t.kind == "metrics"}
    cstr = {f"Table {t.table}": t for t in catalog.tables(Path()) if t.kind == "cstr_metrics"}
    return figures | tables | cstr


@cache
def claim_table() -> ClaimTable:
    """The claims table the package ships (``nlcx/thesis/data/claims.yaml``)."""
    return parse((catalog.DATA / FILENAME).read_text(encoding="utf-8"), FILENAME)


def parse(text: str, origin: str = FILENAME) -> ClaimTable:
    """A claims table from its YAML ``text``; ``origin`` names it in the error messages."""
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise NlcxError(f"{origin}: not valid YAML: {' '.join(str(exc).split())}") from None
    fields = _fields(origin, raw, ("thresholds", "claims"), ())
    declared = _mapping(f"{origin}:thresholds", fields["thresholds"])
    thresholds = {name: _threshold(f"{origin}:thresholds.{name}", name, spec) for name, spec in declared.items()}
    entries = fields["claims"]
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{origin}:claims", entries, "a non-empty list of claims")
    claims = tuple(_claim(f"{origin}:claims[{i}]", entry, thresholds) for i, entry in enumerate(entries))
    _refuse_repeated_ids(origin, claims)
    _refuse_unused_thresholds(origin, thresholds, claims)
    return ClaimTable(thresholds, claims)


def _fields(path: str, raw: object, required: tuple[str, ...], optional: tuple[str, ...]) -> dict[str, object]:
    """The keys of a mapping, every ``required`` one present and none but these."""
    raw = _mapping(path, raw)
    for key in raw:
        if key not in required + optional:
            raise ConfigError(f"{path}.{key}", raw[key], f"unknown key; allowed: {', '.join(required + optional)}")
    for key in required:
        if key not in raw:
            raise ConfigError(f"{path}.{key}", MISSING, "required")
    return raw


def _mapping(path: str, raw: object) -> dict[str, object]:
    if not isinstance(raw, dict) or not raw:
        raise ConfigError(path, raw, "a non-empty mapping")
    return raw


def _text(path: str, value: object) -> str:
    """A non-empty text."""
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(path, value, "a non-empty text")
    return value


def _names(path: str, value: object) -> tuple[str, ...]:
    """A non-empty list of non-empty names."""
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
        raise ConfigError(path, value, "a non-empty list of names")
    return tuple(value)


def _threshold(path: str, name: str, raw: object) -> Threshold:
    fields = _fields(path, raw, ("value", "description"), ("unit",))
    value = fields["value"]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{path}.value", value, "a number (write 1.0e-3, not 1e-3)")
    unit = fields.get("unit", "")
    if not isinstance(unit, str):
        raise ConfigError(f"{path}.unit", unit, "a unit such as m or s")
    return Threshold(name, float(value), unit, _text(f"{path}.description", fields["description"]))


def _claim(path: str, raw: object, thresholds: Mapping[str, Threshold]) -> Claim:
    fields = _fields(path, raw, CLAIM_KEYS[:-1], CLAIM_KEYS[-1:])
    claim_id = _text(f"{path}.id", fields["id"])
    path = f"{path.rsplit('[', 1)[0]}[{claim_id}]"
    chapter, pendulum = fields["chapter"], fields["pendulum"]
    if chapter not in CHAPTER_PLANTS:
        raise ConfigError(f"{path}.chapter", chapter, f"a chapter with claims: {', '.join(map(str, CHAPTER_PLANTS))}")
    if pendulum not in CHAPTER_PLANTS[chapter]:
        raise ConfigError(f"{path}.pendulum", pendulum, f"a plant of chapter {chapter}: {CHAPTER_PLANTS[chapter]}")
    if not claim_id.startswith(f"{pendulum}-"):
        raise ConfigError(f"{path}.id", claim_id, f"an id starting with the pendulum, {pendulum}-")
    checks = fields["checks"]
    if not isinstance(checks, list) or not checks:
        raise ConfigError(f"{path}.checks", checks, "a non-empty list of checks")
    return Claim(
        id=claim_id,
        chapter=chapter,
        pendulum=pendulum,
        source=_text(f"{path}.source", fields["source"]),
        text=_text(f"{path}.claim", fields["claim"]),
        section=_text(f"{path}.section", fields["section"]),
        quote=_text(f"{path}.quote", fields["quote"]),
        checks=tuple(
            _check(f"{path}.checks[{i}]", entry, chapter, pendulum, thresholds) for i, entry in enumerate(checks)
        ),
        all_or_nothing=_flag(f"{path}.all_or_nothing", fields.get("all_or_nothing", False)),
    )


def _check(path: str, raw: object, chapter: int, pendulum: str, thresholds: Mapping[str, Threshold]) -> Check:
    fields = _fields(path, raw, ("kind", "run"), CHECK_KEYS[2:])
    name = fields["kind"]
    if name not in KINDS:
        raise ConfigError(f"{path}.kind", name, f"unknown kind of check; allowed: {', '.join(sorted(KINDS))}")
    kind = KINDS[name]
    runs = _runs(f"{path}.run", fields["run"], kind, chapter, pendulum)
    controllers = _controllers(f"{path}.controllers", fields.get("controllers"), kind)
    return Check(
        kind=name,
        runs=runs,
        controllers=controllers,
        signals=_signals(f"{path}.signals", fields.get("signals"), kind),
        metric=_metric(f"{path}.metric", fields.get("metric"), kind),
        thresholds=_threshold_names(f"{path}.thresholds", fields.get("thresholds", []), kind, thresholds),
        than=_than(f"{path}.than", fields.get("than"), kind, controllers),
        shown=_flag(f"{path}.evidence", fields.get("evidence", True)),
    )


def _plant_words(plant: str) -> str:
    """A plant as the error messages name it: "the x pendulum", "the CSTR"."""
    return "the CSTR" if plant == "cstr" else f"the {plant} pendulum"


def _runs(path: str, value: object, kind: Kind, chapter: int, pendulum: str) -> tuple[str, ...]:
    """The thesis tables and figures a check reads: one per schedule its kind compares, each a
    run of the claim's plant and chapter that its kind reads."""
    refs = tuple(value) if isinstance(value, list) else (value,)
    if len(refs) != len(kind.schedules):
        raise ConfigError(path, value, f"{kind.name} reads {len(kind.schedules)} run(s)")
    known = thesis_runs()
    for ref, schedule in zip(refs, kind.schedules, strict=True):
        if not isinstance(ref, str) or not REFERENCE.fullmatch(ref) or ref not in known:
            raise ConfigError(path, ref, RUNS)
        spec = known[ref]
        if (spec.chapter, spec.plant) != (chapter, pendulum):
            raise ConfigError(path, ref, f"a run of {_plant_words(pendulum)} (chapter {chapter})")
        if kind.reads or isinstance(spec, TableSpec) or spec.plant == "cstr":  # the CSTR's runs, each its kinds'
            if ref != kind.reads:
                raise ConfigError(path, ref, f"{kind.name} reads {kind.reads or 'a pendulum run'}")
            continue
        if schedule and spec.ags != schedule:
            raise ConfigError(path, ref, f"{kind.name} reads a {'-AGS then '.join(kind.schedules)}-AGS run")
        if kind.mode and spec.mode != kind.mode:
            raise ConfigError(path, ref, f"{kind.name} reads a {kind.mode} experiment")
    return refs


def _controllers(path: str, value: object, kind: Kind) -> tuple[str, ...]:
    """The controllers a check reads: its kind's, or (kinds that leave them open) those it names."""
    if kind.controllers is not None:
        if value is not None:
            raise ConfigError(path, value, f"{kind.name} reads {', '.join(kind.controllers)}; name none")
        return kind.controllers
    names = _names(path, value)
    if not set(names) <= set(kind.choices):
        raise ConfigError(path, value, f"controllers among {', '.join(kind.choices)}")
    return names


def _than(path: str, value: object, kind: Kind, controllers: tuple[str, ...]) -> tuple[str, ...]:
    """The controllers a check compares its own with: none, or (kinds that compare) others it names."""
    if not kind.rivals:
        if value is not None:
            raise ConfigError(path, value, f"{kind.name} compares with no other controllers; name none")
        return ()
    if value is None:
        raise ConfigError(path, MISSING, f"{kind.name} compares the check's controllers with others; name them")
    names = _names(path, value)
    others = [c for c in kind.choices if c not in controllers]
    if not set(names) <= set(others):
        raise ConfigError(path, value, f"controllers among {', '.join(others)} (not the check's own)")
    return names


def _flag(path: str, value: object) -> bool:
    """A yes/no key: true or false."""
    if not isinstance(value, bool):
        raise ConfigError(path, value, "true or false")
    return value


def _signals(path: str, value: object, kind: Kind) -> tuple[str, ...]:
    if not kind.signals:
        if value is not None:
            raise ConfigError(path, value, f"{kind.name} reads no signals; name none")
        return ()
    return _names(path, value)


def _metric(path: str, value: object, kind: Kind) -> str:
    """The metric a check reads: its kind's, or (kinds that leave it open) the one it names."""
    if kind.metric is not None:
        if value is not None:
            raise ConfigError(path, value, f"{kind.name} reads {kind.metric or 'the V̇ trace'}; name none")
        return kind.metric
    metric = _text(path, value)
    if kind.metrics and metric not in kind.metrics:
        raise ConfigError(path, metric, f"{kind.name} reads one of {', '.join(kind.metrics)}")
    return metric


def _threshold_names(path: str, value: object, kind: Kind, thresholds: Mapping[str, Threshold]) -> tuple[str, ...]:
    """Declared thresholds, one for each role of the kind."""
    names = tuple(value) if isinstance(value, list) else (value,)
    if len(names) != len(kind.thresholds):
        roles = ", ".join(kind.thresholds) or "none"
        raise ConfigError(path, value, f"{kind.name} takes {len(kind.thresholds)} threshold(s): {roles}")
    for name in names:
        if name not in thresholds:
            raise ConfigError(path, name, f"not a declared threshold; declared: {', '.join(thresholds)}")
    return names


def _refuse_repeated_ids(origin: str, claims: tuple[Claim, ...]) -> None:
    seen: set[str] = set()
    for claim in claims:
        if claim.id in seen:
            raise ConfigError(f"{origin}:claims[{claim.id}].id", claim.id, "an id no other claim has")
        seen.add(claim.id)


def _refuse_unused_thresholds(origin: str, thresholds: Mapping[str, Threshold], claims: tuple[Claim, ...]) -> None:
    used = {name for claim in claims for check in claim.checks for name in check.thresholds}
    for name, threshold in thresholds.items():
        if name not in used:
            raise ConfigError(f"{origin}:thresholds.{name}", threshold.value, "declared but named by no check")

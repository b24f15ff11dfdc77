"""Reproduction profiles: the loop hypothesis (and fitted values) every thesis experiment runs with.

A profile (``configs/thesis/profiles/<name>.yaml``) names a hypothesis of
:mod:`nlcx.thesis.hypotheses` by its options, the values it was fitted to (the conventional
gains and the hypothesis's own parameters, e.g. F_max) and the plants it applies to::

    name: saturation-clamping
    hypothesis: {saturation: clamping}
    values: {vars.conventional.angle.kp: 80.1, ..., F_max: 24.5}
    plants: [x_pendulum, xy_pendulum, xz_pendulum, xyz_pendulum]
    source: nlcx identify configs/identify/pendulum_all.yaml (rank 1 by validation)
    chapter5: {hypothesis: {zn_rule: pessen}, values: {}}   # Table 5.8's experiments

``literal`` is the default loop: no option, no value, every experiment exactly as its config.
``nlcx reproduce --profile NAME`` runs every figure, table and claim under a profile; without
``--profile`` it runs under :func:`default_name`: ``selected`` when the identification study's
rule (:func:`rule_selects`) chose it, ``literal`` otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, field_validator

from nlcx import config as cfg
from nlcx import safe_yaml
from nlcx.errors import ConfigError
from nlcx.thesis import hypotheses
from nlcx.validation import validate_model

#: The rule fixed before the identification study's first fit: the selected hypothesis becomes
#: the default profile when it lowers the literal loop's validation error by at least this share.
MIN_VALIDATION_GAIN = 0.10

PENDULUMS = ["x_pendulum", "xy_pendulum", "xz_pendulum", "xyz_pendulum"]
#: The plants of chapter 5's experiments (a profile's ``chapter5`` part applies to them).
CHAPTER5_PLANTS = ("transfer_function", "cstr")


def _check_options(options: dict[str, str], families: dict[str, dict[str, Any]]) -> dict[str, str]:
    for family, value in options.items():
        if family not in families or value not in families[family]:
            allowed = ", ".join(f"{f}={v}" for f, vs in families.items() for v in vs)
            raise ValueError(f"unknown option {family}={value}; allowed: {allowed}")
    return options


class Chapter5Part(BaseModel):
    """The hypothesis every chapter-5 experiment (Table 5.8, the CSTR) runs under."""

    model_config = ConfigDict(extra="forbid")
    hypothesis: dict[str, str] = Field(default_factory=dict)
    #: The hypothesis's fitted parameters (e.g. u_max).
    values: dict[str, float] = Field(default_factory=dict)

    @field_validator("hypothesis")
    @classmethod
    def _options(cls, options: dict[str, str]) -> dict[str, str]:
        return _check_options(options, hypotheses.CSTR_FAMILIES)


class Profile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    #: Non-default option values by family (empty: the literal loop).
    hypothesis: dict[str, str] = Field(default_factory=dict)
    #: Fitted values: conventional gains (vars.*) and the hypothesis's free parameters.
    values: dict[str, float] = Field(default_factory=dict)
    #: Plants whose experiments the profile changes; the others run as configured.
    plants: list[str] = Field(default_factory=lambda: list(PENDULUMS))
    #: Chapter 5's hypothesis (its experiments' plants: the transfer function, the reactor).
    chapter5: Chapter5Part = Chapter5Part()
    source: str = ""
    #: Whether the rule fixed before the study (:func:`rule_selects`) made this profile the
    #: default of ``nlcx reproduce``.
    default: bool = False

    @field_validator("hypothesis")
    @classmethod
    def _options(cls, options: dict[str, str]) -> dict[str, str]:
        return _check_options(options, hypotheses.FAMILIES)

    @property
    def literal(self) -> bool:
        return not (self.hypothesis or self.values or self.chapter5.hypothesis or self.chapter5.values)

    def as_hypothesis(self) -> hypotheses.Hypothesis:
        return hypotheses.from_options(self.hypothesis)


def rule_selects(selected: Mapping[str, Any], literal: Mapping[str, Any]) -> bool:
    """Whether the selected hypothesis replaces the literal loop as the default profile.

    The rule, fixed before the study's first fit: the selected hypothesis (rank 1 by
    validation error) lowers the literal loop's validation median relative error by at least
    :data:`MIN_VALIDATION_GAIN` of it, and does not lower its validation direction agreement.
    The test tables play no part. ``selected`` and ``literal`` are rows of the study's
    ``ranking.csv``.
    """
    gain = 1.0 - float(selected["validation_median_rel_error"]) / float(literal["validation_median_rel_error"])
    agrees = float(selected["validation_direction_agreement"]) >= float(literal["validation_direction_agreement"])
    return gain >= MIN_VALIDATION_GAIN and agrees


def final_round_selects(final: Mapping[str, Any], current: Mapping[str, Any]) -> bool:
    """Whether the final round's rank 1 replaces the current selected hypothesis.

    The rule, pre-registered with configs/identify/final_round.yaml: the same rule as
    :func:`rule_selects`, with the current selected hypothesis (the study's rank 1) in the
    place of the literal loop. ``final`` and ``current`` are rows of the round's ranking.csv.
    """
    return rule_selects(final, current)


def default_name(root: Path) -> str:
    """The profile ``nlcx reproduce`` runs without ``--profile``: ``selected`` where
    ``root/profiles/selected.yaml`` records that the rule chose it (``default: true``),
    ``literal`` otherwise."""
    chosen = (root / "profiles" / "selected.yaml").is_file() and load("selected", root).default
    return "selected" if chosen else "literal"


def load(name: str, root: Path) -> Profile:
    """The profile ``name`` (a file in ``root/profiles/`` or a path to a YAML file)."""
    path = Path(name) if name.endswith((".yaml", ".yml")) else root / "profiles" / f"{name}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in (root / "profiles").glob("*.yaml"))
        raise ConfigError("--profile", name, f"no such profile; allowed: {', '.join(known)}")
    return validate_model(Profile, safe_yaml.load_file(path) or {}, "")


def experiment(path: Path, overrides: list[str], profile: Profile | None) -> cfg.Experiment:
    """The experiment of config ``path`` under ``profile`` (none or literal: as configured)."""
    if profile is None or profile.literal:
        return cfg.load(path, overrides)
    raw = cfg.apply_overrides(cfg.read_config(path), overrides)
    plant = (raw.get("plant") or {}).get("name")
    if plant in profile.plants:
        return apply(raw, profile.as_hypothesis(), profile.values)
    if plant in CHAPTER5_PLANTS and (profile.chapter5.hypothesis or profile.chapter5.values):
        return apply(raw, hypotheses.from_options(profile.chapter5.hypothesis), profile.chapter5.values)
    return cfg.build(cfg.interpolate(raw))


def plant_inputs(raw: dict[str, Any]) -> list[str]:
    """The input names of the plant of ``raw`` (a config before interpolation)."""
    return [s.name for s in cfg.build(cfg.interpolate(raw)).plant_model.inputs]


def apply(
    raw: dict[str, Any],
    hyp: hypotheses.Hypothesis,
    values: dict[str, float],
    inputs: list[str] | None = None,
    metrics: dict[str, Any] | None = None,
) -> cfg.Experiment:
    """``raw`` (a config before interpolation) with the fitted ``values`` set and ``hyp``'s
    options applied, validated; ``inputs``: the plant's inputs if known (a saturation limits
    them), ``metrics``: other metric definitions (e.g. the rise limits)."""
    gains = [(k.split("."), float(v)) for k, v in values.items() if k.startswith("vars.")]
    resolved = cfg.interpolate(cfg.set_values(raw, gains))
    changed = hyp.apply(resolved, values, inputs if inputs is not None else plant_inputs(raw))
    if metrics:
        changed["metrics"] = {**changed.get("metrics", {}), **metrics}
    return cfg.build(changed)

"""A sweep's plan: the ``sweep:`` section, its expansion into variants, and the hash that identifies each.

The variants are the product grid x zip x random (:func:`expand`); each variant's ``seed`` is
spawned with ``numpy.random.SeedSequence`` from the sweep seed. A variant's hash
(:func:`variant_hash`) is what a rerun compares to skip the variants already done.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from nlcx import config as cfg
from nlcx.errors import ConfigError
from nlcx.metrics.names import METRIC_UNITS
from nlcx.validation import validate_model


class Distribution(BaseModel):
    """A random parameter: uniform [low, high] or +-relative x base, normal, log-uniform, choice."""

    model_config = ConfigDict(extra="forbid")
    dist: Literal["uniform", "normal", "loguniform", "choice"]
    low: float | None = None
    high: float | None = None
    #: For uniform: draw from [base (1 - relative), base (1 + relative)] around the config's value.
    relative: float | None = Field(None, gt=0)
    mean: float | None = None
    std: float | None = Field(None, gt=0)
    values: list[Any] | None = None

    @model_validator(mode="after")
    def _complete(self) -> Distribution:
        need = {
            "uniform": self.relative is not None or (self.low is not None and self.high is not None),
            "loguniform": self.low is not None and self.high is not None and 0 < self.low < self.high,
            "normal": self.mean is not None and self.std is not None,
            "choice": bool(self.values),
        }
        if not need[self.dist]:
            hints = {
                "uniform": "low and high, or relative",
                "loguniform": "0 < low < high",
                "normal": "mean and std",
                "choice": "a non-empty list of values",
            }
            raise ValueError(f"a {self.dist} distribution needs {hints[self.dist]}")
        return self


class RandomSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    n: int = Field(ge=1)
    params: dict[str, Distribution] = Field(min_length=1)


class SweepSection(BaseModel):
    model_config = ConfigDict(extra="forbid")
    seed: int = Field(0, ge=0)
    grid: dict[str, list[Any]] = Field(default_factory=dict)
    zip: dict[str, list[Any]] = Field(default_factory=dict)
    random: RandomSpec | None = None
    batch_size: int = Field(64, ge=1)
    timeseries: bool = False
    #: The metrics metrics.csv keeps (names of :data:`nlcx.metrics.names.METRIC_UNITS`); None: all.
    metrics: list[str] | None = Field(None, min_length=1)

    @model_validator(mode="after")
    def _zip_lengths(self) -> SweepSection:
        lengths = {len(v) for v in self.zip.values()}
        if len(lengths) > 1:
            raise ValueError(f"zip lists must have the same length, got {sorted(lengths)}")
        for key, values in self.grid.items():
            if not values:
                raise ValueError(f"grid list of {key} is empty")
        unknown = [m for m in self.metrics or [] if m not in METRIC_UNITS]
        if unknown:
            raise ValueError(f"unknown metric {unknown[0]!r} in metrics; allowed: {', '.join(METRIC_UNITS)}")
        return self


@dataclass(frozen=True)
class Variant:
    """One point of a sweep: its index, the values it sets and its spawned seed."""

    index: int
    values: dict[str, Any]
    seed: int

    def overrides(self) -> list[str]:
        """The variant as ``key=value`` overrides (what ``--dry-run`` prints)."""
        return [f"{key}={json.dumps(value)}" for key, value in self.values.items()] + [f"seed={self.seed}"]

    def settings(self) -> list[tuple[list[str], Any]]:
        """The variant as (key path, value) pairs for :func:`nlcx.config.set_values`."""
        return [(key.split("."), value) for key, value in self.values.items()] + [(["seed"], self.seed)]

    def resolve(self, base: cfg.Interpolated) -> dict[str, Any]:
        """The variant's raw config: the base with its values and seed set, interpolated (the
        base interpolated once, :class:`nlcx.config.Interpolated`)."""
        return base.resolve(self.settings())


def _lookup(raw: dict[str, Any], key: str) -> Any:
    node: Any = raw
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ConfigError(
                f"sweep.random.params.{key}", None, "relative needs the key to have a value in the config"
            )
        node = node[part]
    return node


def _draw(dist: Distribution, base: Any, n: int, rng: np.random.Generator) -> list[Any]:
    # Distribution._complete has checked that the parameters each distribution reads are set.
    if dist.dist == "uniform":
        if dist.relative is not None:
            lo, hi = float(base) * (1 - dist.relative), float(base) * (1 + dist.relative)
        else:
            assert dist.low is not None and dist.high is not None
            lo, hi = float(dist.low), float(dist.high)
        return [float(v) for v in rng.uniform(min(lo, hi), max(lo, hi), n)]
    if dist.dist == "loguniform":
        assert dist.low is not None and dist.high is not None
        return [float(v) for v in np.exp(rng.uniform(math.log(dist.low), math.log(dist.high), n))]
    if dist.dist == "normal":
        assert dist.mean is not None and dist.std is not None
        return [float(v) for v in rng.normal(dist.mean, dist.std, n)]
    values = dist.values or []
    return [values[i] for i in rng.integers(0, len(values), n)]


def expand(spec: SweepSection, base_raw: dict[str, Any]) -> list[Variant]:
    """The variants of ``spec``: grid x zip x random, each with a spawned seed."""
    grid_keys = list(spec.grid)
    grid_points = [dict(zip(grid_keys, combo, strict=True)) for combo in itertools.product(*spec.grid.values())]
    zip_keys = list(spec.zip)
    n_zip = len(next(iter(spec.zip.values()))) if spec.zip else 1
    zip_points = [{k: spec.zip[k][i] for k in zip_keys} for i in range(n_zip)]
    if spec.random is not None:
        root = np.random.SeedSequence(spec.seed)
        rng = np.random.default_rng(root.spawn(1)[0])
        draws = {}
        for key, dist in spec.random.params.items():
            base = _lookup(base_raw, key) if dist.relative is not None else None
            draws[key] = _draw(dist, base, spec.random.n, rng)
        random_points = [{k: draws[k][i] for k in draws} for i in range(spec.random.n)]
    else:
        random_points = [{}]
    combos = [{**g, **z, **r} for g in grid_points for z in zip_points for r in random_points]
    children = np.random.SeedSequence(spec.seed).spawn(len(combos) + 1)[1:]
    return [
        Variant(index=i, values=values, seed=int(child.generate_state(1)[0]))
        for i, (values, child) in enumerate(zip(combos, children, strict=True))
    ]


def config_hash(raw: Any) -> str:
    """A stable hash of a config (canonical JSON)."""
    text = json.dumps(raw, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def variant_hash(base_digest: str, variant: Variant) -> str:
    """What identifies a variant's result for resuming: the hash of its base config (before
    interpolation, so a change anywhere in it counts) with the values and seed it sets; the
    variant's resolved config is a function of exactly these."""
    return config_hash({"base": base_digest, "values": variant.values, "seed": variant.seed})


def load(
    path: str | Path | Mapping[str, Any], overrides: list[str] | None = None
) -> tuple[dict[str, Any], SweepSection, Any]:
    """(base raw config without ``sweep``, the sweep spec, the validated base experiment) of a
    config file, or of a raw config mapping as a file holds it (:func:`nlcx.sweep`)."""
    raw_config = copy.deepcopy(dict(path)) if isinstance(path, Mapping) else cfg.read_config(path)
    raw = cfg.apply_overrides(raw_config, overrides or [])
    sweep_raw = raw.pop("sweep", None)
    if sweep_raw is None:
        raise ConfigError("sweep", None, "this config has no sweep section (use `nlcx run` for a single experiment)")
    spec = validate_model(SweepSection, sweep_raw, "sweep")
    base = cfg.build(cfg.interpolate(raw))
    return raw, spec, base


def plan(base_raw: dict[str, Any], spec: SweepSection) -> tuple[list[Variant], list[str]]:
    """The variants and the hash of each one's resolved config."""
    variants = expand(spec, cfg.interpolate(base_raw))
    # the metrics kept are part of what a variant's result is (a rerun keeping others recomputes)
    base_digest = config_hash(base_raw if spec.metrics is None else {"base": base_raw, "metrics": spec.metrics})
    return variants, [variant_hash(base_digest, v) for v in variants]

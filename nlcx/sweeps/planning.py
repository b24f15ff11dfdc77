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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from nlcx import config as cfg
from nlcx.config.interpolation import check_resolvers
from nlcx.errors import ConfigError
from nlcx.metrics.names import METRIC_UNITS
from nlcx.plugins import load_config_imports
from nlcx.sweeps.seeds import spawned_seeds
from nlcx.validation import validate_model


class Distribution(BaseModel):
    """A random parameter: uniform [low, high] or +-relative x base, normal, log-uniform, choice."""

    model_config = ConfigDict(extra="forbid")
    dist: Literal["uniform", "normal", "loguniform", "choice"] = Field(
        description="The distribution: uniform (low and high, or relative), normal (mean and std), "
        "loguniform (0 < low < high) or choice (values)."
    )
    low: float | None = Field(None, description="Lower end of a uniform or loguniform range.")
    high: float | None = Field(None, description="Upper end of a uniform or loguniform range.")
    relative: float | None = Field(
        None,
        gt=0,
        description="For uniform: draw from [base (1 - relative), base (1 + relative)] around the config's value.",
    )
    mean: float | None = Field(None, description="Mean of a normal distribution.")
    std: float | None = Field(None, gt=0, description="Standard deviation of a normal distribution.")
    values: list[object] | None = Field(None, description="For choice: the values drawn from, each equally likely.")

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
    n: int = Field(ge=1, description="Number of seeded draws (variants of the random part).")
    params: dict[str, Distribution] = Field(
        min_length=1, description="The distribution of each varied key, by dotted key (e.g. plant.params.l)."
    )


class SweepSection(BaseModel):
    model_config = ConfigDict(extra="forbid")
    seed: int = Field(
        0, ge=0, description="Root of numpy.random.SeedSequence from which each variant's seed is spawned."
    )
    grid: dict[str, list[object]] = Field(
        default_factory=dict, description="Values of each dotted key, combined as a cartesian product."
    )
    zip: dict[str, list[object]] = Field(
        default_factory=dict, description="Lists of values of equal length, taken together position by position."
    )
    random: RandomSpec | None = Field(None, description="Seeded random draws of some keys.")
    batch_size: int = Field(64, ge=1, description="Variants per kernel call and per result file.")
    timeseries: bool = Field(False, description="Write every variant's time series (timeseries/variant_NNNNNN.csv).")
    metrics: list[str] | None = Field(
        None,
        min_length=1,
        description="The metrics the metrics table keeps by name (see the metrics reference); null: all.",
    )
    format: Literal["parquet", "csv"] = Field(
        "parquet",
        description="The tables sweep and metrics as Parquet datasets (sweep.parquet/, metrics.parquet/) or CSV "
        "files (sweep.csv, metrics.csv).",
    )
    columnar: bool = Field(
        True,
        description="true: variants that differ only in numbers are run from columns, the others config by "
        "config; false: always config by config.",
    )

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
    values: Mapping[str, object]
    seed: int

    def overrides(self) -> list[str]:
        """The variant as ``key=value`` overrides (what ``--dry-run`` prints)."""
        return [f"{key}={json.dumps(value)}" for key, value in self.values.items()] + [f"seed={self.seed}"]

    def settings(self) -> list[tuple[list[str], object]]:
        """The variant as (key path, value) pairs for :func:`nlcx.config.set_values`."""
        return [(key.split("."), value) for key, value in self.values.items()] + [(["seed"], self.seed)]

    def resolve(self, base: cfg.Interpolated) -> dict[str, object]:
        """The variant's raw config: the base with its values and seed set, interpolated (the
        base interpolated once, :class:`nlcx.config.Interpolated`)."""
        return base.resolve(self.settings())


def _lookup(raw: Mapping[str, object], key: str) -> object:
    node: object = raw
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ConfigError(
                f"sweep.random.params.{key}", None, "relative needs the key to have a value in the config"
            )
        node = node[part]
    return node


def _draw(dist: Distribution, base: Any, n: int, rng: np.random.Generator) -> list[object] | np.ndarray:
    """``n`` draws of ``dist``: an array of floats, or the chosen values of a choice (``base``: the
    config's value of the key, read as a number, for a relative range)."""
    # Distribution._complete has checked that the parameters each distribution reads are set.
    if dist.dist == "uniform":
        if dist.relative is not None:
            lo, hi = float(base) * (1 - dist.relative), float(base) * (1 + dist.relative)
        else:
            assert dist.low is not None and dist.high is not None
            lo, hi = float(dist.low), float(dist.high)
        return rng.uniform(min(lo, hi), max(lo, hi), n)
    if dist.dist == "loguniform":
        assert dist.low is not None and dist.high is not None
        return np.exp(rng.uniform(math.log(dist.low), math.log(dist.high), n))
    if dist.dist == "normal":
        assert dist.mean is not None and dist.std is not None
        return rng.normal(dist.mean, dist.std, n)
    values = dist.values or []
    return [values[i] for i in rng.integers(0, len(values), n)]


def _draws(spec: SweepSection, base_raw: Mapping[str, object]) -> dict[str, list[object] | np.ndarray]:
    """The random section's draws, key by key from one generator spawned from the sweep seed."""
    if spec.random is None:
        return {}
    root = np.random.SeedSequence(spec.seed)
    rng = np.random.default_rng(root.spawn(1)[0])
    draws = {}
    for key, dist in spec.random.params.items():
        base = _lookup(base_raw, key) if dist.relative is not None else None
        draws[key] = _draw(dist, base, spec.random.n, rng)
    return draws


def _listed(values: list[object] | np.ndarray) -> list[object]:
    return values.tolist() if isinstance(values, np.ndarray) else values


def expand(spec: SweepSection, base_raw: Mapping[str, object]) -> list[Variant]:
    """The variants of ``spec``: grid x zip x random, each with a spawned seed."""
    grid_keys = list(spec.grid)
    grid_points = [dict(zip(grid_keys, combo, strict=True)) for combo in itertools.product(*spec.grid.values())]
    zip_keys = list(spec.zip)
    n_zip = len(next(iter(spec.zip.values()))) if spec.zip else 1
    zip_points = [{k: spec.zip[k][i] for k in zip_keys} for i in range(n_zip)]
    if spec.random is not None:
        draws = {k: _listed(v) for k, v in _draws(spec, base_raw).items()}
        random_points = [{k: draws[k][i] for k in draws} for i in range(spec.random.n)]
    else:
        random_points = [{}]
    combos = [{**g, **z, **r} for g in grid_points for z in zip_points for r in random_points]
    seeds = spawned_seeds(spec.seed, 1, len(combos)).tolist()
    return [
        Variant(index=i, values=values, seed=seed) for i, (values, seed) in enumerate(zip(combos, seeds, strict=True))
    ]


def _column(values: Sequence[object] | np.ndarray) -> np.ndarray | None:
    """Values as a column: floats, or integers where every value is one; None where a value is
    not a number (a text, a mapping, a bool) or integers and floats mix."""
    if isinstance(values, np.ndarray):
        return values
    kinds = {type(v) for v in values}
    if kinds == {int}:
        return np.array(values, dtype=np.int64)
    if kinds == {float}:
        return np.array(values, dtype=np.float64)
    return None


def numeric(spec: SweepSection) -> bool:
    """Whether every value ``spec`` varies is a number (its plan can be expanded as columns,
    :func:`expand_columns`), told from the section alone."""
    listed = [*spec.grid.values(), *spec.zip.values()]
    if spec.random is not None:
        listed += [d.values or [] for d in spec.random.params.values() if d.dist == "choice"]
    return all(_column(values) is not None for values in listed)


@dataclass(frozen=True)
class ColumnPlan:
    """A plan as columns: the values of each varied key and each variant's seed, by variant
    index, as :func:`expand` gives them (the same values, in the same order)."""

    columns: dict[str, np.ndarray]
    seeds: np.ndarray

    @property
    def n(self) -> int:
        return int(self.seeds.size)

    def values(self, index: int) -> dict[str, float]:
        """Variant ``index``'s values, as Python numbers (int or float)."""
        return {key: column[index].item() for key, column in self.columns.items()}

    def variant(self, index: int) -> Variant:
        return Variant(index=index, values=self.values(index), seed=int(self.seeds[index]))


def expand_columns(spec: SweepSection, base_raw: Mapping[str, object]) -> ColumnPlan | None:
    """The variants of ``spec`` as columns (:class:`ColumnPlan`), without a Python object per
    variant; None when a varied value is not a number or a key is varied twice."""
    keys = [*spec.grid, *spec.zip, *(spec.random.params if spec.random else {})]
    if len(set(keys)) != len(keys):
        return None
    lengths = [len(v) for v in spec.grid.values()]
    n_grid = math.prod(lengths)
    n_zip = len(next(iter(spec.zip.values()))) if spec.zip else 1
    n_random = spec.random.n if spec.random is not None else 1
    raw_columns: dict[str, np.ndarray | None] = {}
    for k, (key, values) in enumerate(spec.grid.items()):
        col = _column(values)
        raw_columns[key] = None if col is None else np.repeat(
            np.tile(col, math.prod(lengths[:k])), math.prod(lengths[k + 1 :]) * n_zip * n_random
        )  # fmt: skip
    for key, values in spec.zip.items():
        col = _column(values)
        raw_columns[key] = None if col is None else np.tile(np.repeat(col, n_random), n_grid)
    for key, draws in _draws(spec, base_raw).items():
        col = _column(draws)
        raw_columns[key] = None if col is None else np.tile(col, n_grid * n_zip)
    if any(col is None for col in raw_columns.values()):
        return None
    n = n_grid * n_zip * n_random
    columns = {key: col for key, col in raw_columns.items() if col is not None}
    return ColumnPlan(columns, spawned_seeds(spec.seed, 1, n).astype(np.int64))


def config_hash(raw: object) -> str:
    """A stable hash of a config (canonical JSON)."""
    text = json.dumps(raw, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def variant_hash(base_digest: str, variant: Variant) -> str:
    """What identifies a variant's result for resuming: the hash of its base config (before
    interpolation, so a change anywhere in it counts) with the values and seed it sets; the
    variant's resolved config is a function of exactly these."""
    return config_hash({"base": base_digest, "values": variant.values, "seed": variant.seed})


def load(
    path: str | Path | Mapping[str, object], overrides: list[str] | None = None, *, allow_env: bool = False
) -> tuple[dict[str, object], SweepSection, cfg.Experiment]:
    """(base raw config without ``sweep``, the sweep spec, the validated base experiment) of a
    config file, or of a raw config mapping as a file holds it (:func:`nlcx.sweep`).

    Unless ``allow_env``, a resolver that reads the process is refused here, anywhere in the
    config, the sweep section included (:func:`nlcx.config.interpolation.check_resolvers`):
    the sweep's later interpolations of the base and its variants then have every resolver on."""
    raw_config = copy.deepcopy(dict(path)) if isinstance(path, Mapping) else cfg.read_config(path)
    raw = load_config_imports(cfg.apply_overrides(raw_config, overrides or []))
    if not allow_env:
        check_resolvers(raw)
    sweep_raw = raw.pop("sweep", None)
    if sweep_raw is None:
        raise ConfigError("sweep", None, "this config has no sweep section (use `nlcx run` for a single experiment)")
    spec = validate_model(SweepSection, sweep_raw, "sweep")
    base = cfg.build(cfg.interpolate(raw, allow_env=True), allow_env=allow_env)
    return raw, spec, base


def base_digest(base_raw: Mapping[str, object], spec: SweepSection) -> str:
    """The hash of what every variant's result depends on besides its values and seed: the base
    config and the metrics kept (a rerun keeping other metrics recomputes)."""
    return config_hash(base_raw if spec.metrics is None else {"base": base_raw, "metrics": spec.metrics})


def plan(base_raw: dict[str, object], spec: SweepSection) -> tuple[list[Variant], list[str]]:
    """The variants and the hash of each one's resolved config."""
    variants = expand(spec, cfg.interpolate(base_raw, allow_env=True))  # checked by load
    digest = base_digest(base_raw, spec)
    return variants, [variant_hash(digest, v) for v in variants]

"""A sweep's variants as runs (:meth:`nlcx.SweepResult.trajectories`): each one's config rebuilt
from the sweep directory as the sweep built it, its time series read where the sweep recorded
them, else the variant run again and checked against the sweep's metrics of it.

The sweep directory's config.yaml holds the base config, interpolated, with the resolved
``sweep:`` section; the plan expanded from it (:func:`nlcx.sweeps.planning.expand`) gives each
variant's values and seed, and setting them on the base (:meth:`~nlcx.sweeps.planning.Variant.resolve`)
gives the config the sweep's batch built (:mod:`nlcx.sweeps.batches`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, cast

from nlcx import compiled_cache, manifest, plugins, runtime, safe_yaml
from nlcx.errors import ConfigError, NlcxError

if TYPE_CHECKING:
    import pandas as pd

    from nlcx.config import Experiment, Interpolated
    from nlcx.results import Result
    from nlcx.sweeps.planning import Variant


@dataclass(frozen=True)
class Plan:
    """A sweep directory's base config (interpolated once), its base experiment and its variants."""

    interpolated: Interpolated
    base: Experiment
    variants: dict[int, Variant]
    timeseries: bool


class SweptTables(Protocol):
    """What :func:`variant_results` reads of a sweep (:class:`nlcx.sweep_results.SweepResult`):
    its tables of variants and metrics, and the directory it was written to."""

    variants: pd.DataFrame
    metrics: pd.DataFrame
    directory: Path | None


def variant_results(sweep: SweptTables, chosen: list[int], controller: str | None) -> dict[int, Result]:
    """Variant -> its :class:`~nlcx.results.Result` (:meth:`nlcx.SweepResult.trajectories`)."""
    from nlcx._numba_compat import quiet_first_class_functions

    directory = _directory(sweep)
    _check_chosen(sweep.variants, chosen)
    controllers = [str(c) for c in dict.fromkeys(sweep.metrics.controller)]
    if controller is not None and controller not in controllers:
        raise ConfigError(
            "controller", controller, f"not a controller of this sweep; allowed: {', '.join(controllers)}"
        )
    compiled_cache.ready()  # before the plant's model (and its compiled functions) is loaded
    plan = _plan(directory, chosen)
    out = {}
    with quiet_first_class_functions(), runtime.cache_access():
        for index in chosen:
            rows = sweep.metrics[sweep.metrics.variant == index]
            _check_seed(sweep.variants, plan.variants[index])
            result = _recorded(directory, plan, index, rows) if plan.timeseries else None
            if result is None:
                result = _run_again(plan, index, rows)
            out[index] = result if controller is None else _only(result, controller)
    return out


def _directory(sweep: SweptTables) -> Path:
    if sweep.directory is None or not (sweep.directory / "config.yaml").is_file():
        raise ConfigError(
            "directory", None if sweep.directory is None else str(sweep.directory),
            "a sweep written to a directory (nlcx.sweep(..., out=DIR), nlcx sweep --out DIR): its config.yaml "
            "determines each variant",
        )  # fmt: skip
    return sweep.directory


def _check_chosen(variants: pd.DataFrame, chosen: list[int]) -> None:
    known = set(variants.variant.tolist())
    for index in chosen:
        if index not in known:
            allowed = f"0 to {len(variants) - 1}" if len(variants) else "(none)"
            raise ConfigError("variants", index, f"not a variant of this sweep; allowed: {allowed}")
        row = variants[variants.variant == index].iloc[0]
        if str(row.get("status", "ok")) == "failed":
            raise ConfigError(
                "variants", index, f"this variant failed ({row.get('message', '')}); allowed: one that ran"
            )


def _check_seed(variants: pd.DataFrame, variant: Variant) -> None:
    """The variant the plan gives is the sweep's: the seed its table recorded."""
    recorded = int(variants[variants.variant == variant.index].seed.iloc[0])
    if recorded != variant.seed:
        raise NlcxError(
            f"trajectories: variant {variant.index} of the plan in config.yaml has seed {variant.seed}, the sweep "
            f"recorded {recorded}; allowed: the sweep directory as the sweep wrote it"
        )


def _plan(directory: Path, chosen: list[int]) -> Plan:
    """The sweep directory's plan: config.yaml (checked against the manifest) expanded as the sweep did."""
    from nlcx import config as cfg
    from nlcx.sweeps import planning

    record = manifest.verify(directory, ["config.yaml"])
    raw = safe_yaml.load_file(directory / "config.yaml")
    if not isinstance(raw, dict):
        raise manifest.IntegrityError(directory / "config.yaml", "not a mapping of sections", "the config nlcx wrote")
    base_raw, spec, base = planning.load(raw, allow_env=bool(record.get("allow_env", False)))
    plugins.load(cast("list[str]", base_raw.get(plugins.IMPORTS, [])))  # as load_config_imports resolved them
    interpolated_raw = cfg.interpolate(base_raw, allow_env=True)
    columns = planning.expand_columns(spec, interpolated_raw) if planning.numeric(spec) else None
    if columns is not None:
        variants = {i: columns.variant(i) for i in chosen}
    else:
        every = planning.expand(spec, interpolated_raw)
        variants = {i: every[i] for i in chosen}
    return Plan(cfg.Interpolated.of(base_raw, allow_env=True), base, variants, spec.timeseries)


def _experiment(plan: Plan, index: int) -> Experiment:
    """The variant's experiment, built as the sweep's batch built it."""
    from nlcx import config as cfg

    return cfg.build(plan.variants[index].resolve(plan.interpolated), like=plan.base)


def _recorded(directory: Path, plan: Plan, index: int, rows: pd.DataFrame) -> Result | None:
    """The variant's result from its recorded time series and the sweep's rows (None without a file)."""
    from nlcx.results import Result
    from nlcx.run_files import metrics_frame, read_timeseries

    files = sorted((directory / "timeseries").glob(f"variant_{index:06d}.*"))
    if not files:
        return None
    manifest.verify_file(files[0])
    exp = _experiment(plan, index)
    sec = exp.section
    plant = exp.plant_model.build(sec.plant.name, exp.plant_params, sec.plant.x0, sec.simulation.bounds)
    metrics = metrics_frame(rows.drop(columns="variant"))
    statuses = {c: "ok" for c in metrics.controller}
    for c, status in zip(metrics.controller, metrics.status, strict=True):
        if status != "ok":
            statuses[c] = status
    return Result(
        name=exp.name, config=exp.resolved(), metrics=metrics, statuses=statuses,
        trajectories=read_timeseries(files[0]), outputs=[(s.name, s.unit, s.label) for s in plant.outputs],
        signals={"states": plant.state_names, "inputs": plant.input_names, "output_matrix": plant.C.tolist()},
    )  # fmt: skip


def _run_again(plan: Plan, index: int, rows: pd.DataFrame) -> Result:
    """The variant run again, its metrics checked against the sweep's rows of it."""
    from nlcx import engine
    from nlcx.results import Result

    (run,) = engine.evaluate([engine.prepare(_experiment(plan, index))], record_logs=True)
    result = Result.from_engine(run)
    _check_metrics(index, result.metrics, rows)
    return result


def _check_metrics(index: int, ours: pd.DataFrame, sweeps: pd.DataFrame) -> None:
    """Every row of the sweep's for the variant has the same value (bit for bit) and status in ``ours``."""
    again = {
        (c, s, m): (v, st)
        for c, s, m, v, st in zip(ours.controller, ours.signal, ours.metric, ours.value, ours.status, strict=True)
    }
    columns = (sweeps.controller, sweeps.signal, sweeps.metric, sweeps.value, sweeps.status)
    for c, s, m, v, st in zip(*columns, strict=True):
        key = (str(c), str(s), str(m))
        value, status = again.get(key, (math.nan, "missing"))
        same = (value == v or (math.isnan(value) and math.isnan(v))) and status == str(st)
        if not same:
            raise NlcxError(
                f"trajectories: variant {index} run again gives {key} = {value!r} ({status}), the sweep has "
                f"{float(v)!r} ({st}); allowed: a sweep whose config.yaml determines its variants (no varied key "
                "that another key referred to)"
            )


def _only(result: Result, controller: str) -> Result:
    """``result`` with one controller's run."""
    from nlcx.results import Result

    trajectories = {controller: result.trajectory(controller)}
    return Result(
        name=result.name, config=result.config, metrics=result.metrics[result.metrics.controller == controller]
        .reset_index(drop=True), statuses={controller: result.status(controller)}, trajectories=trajectories,
        outputs=result._outputs, signals=result._signals,
    )  # fmt: skip

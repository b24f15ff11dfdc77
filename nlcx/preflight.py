"""Checks of an experiment before it runs, each failing with one line that names the key.

- every configured reference is followed by a controller (or measured): a reference that
  drives nothing is a mistake in the config, not something to ignore;
- a plant's inputs and outputs have distinct names (metrics.csv rows are keyed by them);
- a step reference's time leaves the run at least two samples to measure it by;
- the arrays of the run fit in memory: the estimate is made before anything is allocated.
"""

from __future__ import annotations

import functools
import math
import os
import time
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING

from nlcx.controllers.base import ControllerInstance
from nlcx.errors import ConfigError
from nlcx.plants.base import Plant

if TYPE_CHECKING:
    from nlcx.config.building import PluginSection
    from nlcx.protocols import ReferencePlugin

BYTES_PER_VALUE = 8
#: Fraction of the available memory a run may plan to use (metrics and plots need the rest).
MEMORY_SHARE = 0.8


def check_signal_names(plant: Plant) -> None:
    """Inputs and outputs of ``plant`` must not share a name (nor repeat one)."""
    seen: dict[str, str] = {}
    for kind, names in (("input", plant.input_names), ("output", plant.output_names)):
        for name in names:
            if name in seen:
                key = next((f"plant.params.{k}" for k, v in plant.params.items() if v == name), "plant.name")
                raise ConfigError(
                    key,
                    name,
                    f"{plant.name} has an {seen[name]} and an {kind} named {name!r}; "
                    "inputs and outputs need distinct names (metrics are keyed by signal)",
                )
            seen[name] = kind


def check_reference_times(references: Mapping[str, PluginSection[ReferencePlugin]], t_end: float, dt: float) -> None:
    """A step reference (or any measured as one) must step at a sample that leaves at least two
    samples of the run after it: its time at most ``t_end - dt``."""
    latest = t_end - dt
    for signal, ref in references.items():
        plan = ref.model.signal_plan(ref.config)
        if plan.kind == "step" and plan.t_step > latest + 1e-9 * dt:
            raise ConfigError(
                f"reference.{signal}.time",
                plan.t_step,
                f"too late to measure a step response: simulation.t_end = {t_end:g} s with dt = {dt:g} s; "
                f"allowed: 0 <= time <= {latest:g}",
            )


def check_references(
    configured: Iterable[str],
    references: Mapping[str, PluginSection[ReferencePlugin]],
    plant: Plant,
    controllers: list[ControllerInstance],
) -> None:
    """Every configured reference must be read by a controller (``reference.<signal>``)."""
    followed = {s for c in controllers for s in c.reference_signals}
    for signal in configured:
        if signal in followed:
            continue
        readers = ", ".join(f"{c.label} ({c.kind}): {', '.join(c.reference_signals) or 'none'}" for c in controllers)
        what = "input" if signal in plant.input_names else "output"
        raise ConfigError(
            f"reference.{signal}",
            references[signal].kind,
            f"no controller reads a reference on {what} {signal}, so it would drive nothing and no metric "
            f"would measure it; the controllers read: {readers}",
        )


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (MemAvailable on Linux), None if unknown;
    read at most once a second (a sweep prepares hundreds of variants a second)."""
    return _available_memory(int(time.monotonic()))


@functools.lru_cache(maxsize=1)
def _available_memory(second: int) -> int | None:
    """:func:`available_memory` read in the given second of the monotonic clock."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def run_bytes(n_samples: int, n_stages: int, plant: Plant, channels: Iterable[int], copies: int = 1) -> int:
    """Bytes of the arrays a run allocates: the time grid and Runge-Kutta stage times, and per
    controller its states, inputs and friction forces plus ``channels`` more values
    (references, logs), each sampled ``n_samples`` times; ``copies`` such runs at once (a
    sweep's batch on each worker). A lower bound: the metrics' temporaries come on top."""
    n, n_u = len(plant.states), len(plant.inputs)
    per_sample = 1 + n_stages + sum(n + 2 * n_u + k for k in channels)
    return n_samples * per_sample * BYTES_PER_VALUE * copies


def check_memory(needed: int, key: str, value: object, advice: str, limit: int | None = None) -> None:
    """Refuse a run whose arrays (``needed`` bytes) would not fit in memory, naming ``key``."""
    limit = available_memory() if limit is None else limit
    if limit is None or needed <= MEMORY_SHARE * limit:
        return
    raise ConfigError(
        key,
        value,
        f"the run's arrays need about {_gib(needed)}, more than {MEMORY_SHARE:.0%} of the "
        f"{_gib(limit)} of memory available; {advice}",
    )


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.3g} GiB" if n_bytes >= 2**30 else f"{n_bytes / 2**20:.3g} MiB"


def samples(t_end: float, dt: float) -> int:
    """Samples of a run, t_0 .. t_K with K = t_end / dt."""
    return max(1, math.floor(t_end / dt + 0.5)) + 1

"""Preparing an experiment: its plant, references, time grid, perturbations and closed loops.

:func:`nlcx.engine.prepare` builds a :class:`Prepared` from a validated experiment with the
parts here (its controllers, which tuners may fill in by simulating, are built there);
:func:`items_of` turns it into the closed loops the kernel simulates.
"""

from __future__ import annotations

import functools
import json
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from nlcx import preflight, registry
from nlcx.config import Experiment
from nlcx.controllers.base import ControllerInstance
from nlcx.errors import ConfigError
from nlcx.plants.base import Plant
from nlcx.uncertainty.base import Element, Hooks

if TYPE_CHECKING:
    from pydantic import BaseModel

    from nlcx.protocols import ReferencePlugin


class Tableau(NamedTuple):
    """The Butcher tableau of an explicit Runge-Kutta method: coefficients a (s, s), weights b (s,)."""

    a: np.ndarray
    b: np.ndarray


#: Butcher tableaus of the fixed-step explicit Runge-Kutta methods (``simulation.integrator``).
TABLEAUS: dict[str, Tableau] = {
    "euler": Tableau(a=np.zeros((1, 1)), b=np.array([1.0])),
    "heun": Tableau(a=np.array([[0.0, 0.0], [1.0, 0.0]]), b=np.array([0.5, 0.5])),
    "rk4": Tableau(
        a=np.array([[0.0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1.0, 0]]),
        b=np.array([1.0, 2.0, 2.0, 1.0]) / 6.0,
    ),
}


class Reference(NamedTuple):
    """A signal's reference: its registered model and the model's configuration."""

    model: ReferencePlugin
    #: An instance of the model's ``Config``.
    config: BaseModel


@dataclass(frozen=True)
class TimeGrid:
    """Sampling instants t_k = k dt, k = 0..K, and the Runge-Kutta stage times."""

    dt: float
    t: np.ndarray
    stage_times: np.ndarray

    @property
    def n_steps(self) -> int:
        return self.t.size - 1


@functools.lru_cache(maxsize=32)
def time_grid(t_end: float, dt: float, integrator: str) -> TimeGrid:
    """The grid of ``t_end / dt`` steps; t_end must be a whole number of steps (cached: read-only)."""
    n_steps = round(t_end / dt)
    if n_steps < 1 or abs(n_steps * dt - t_end) > 1e-9 * max(1.0, t_end):
        raise ConfigError(
            "simulation.t_end",
            t_end,
            f"must be a whole number (>= 1) of steps dt = {dt} (t_end/dt = {t_end / dt:.6g})",
        )
    c = TABLEAUS[integrator].a.sum(axis=1)
    t = np.arange(n_steps + 1) * dt
    return TimeGrid(dt=dt, t=t, stage_times=t[:-1, None] + c[None, :] * dt)


@dataclass
class Prepared:
    """Everything the kernel needs, built from an :class:`Experiment`."""

    experiment: Experiment
    plant: Plant
    controllers: list[ControllerInstance]
    references: dict[str, Reference]
    grid: TimeGrid
    hooks: Hooks
    seed_sequence: np.random.SeedSequence
    #: Rows of tuning.csv: what the tuners of each controller found.
    tuning: list[dict[str, object]] = field(default_factory=list)


def reference_models(exp: Experiment, plant: Plant) -> dict[str, Reference]:
    """The reference of each output and input; outputs without an entry are regulated to 0."""
    allowed = plant.output_names + plant.input_names
    refs: dict[str, Reference] = {}
    for signal, sec in exp.references.items():
        if signal not in allowed:
            raise ConfigError(
                f"reference.{signal}",
                sec.kind,
                f"not an output or input of {plant.name}; allowed: {', '.join(allowed)}",
            )
        refs[signal] = Reference(sec.model, sec.config)
    constant = registry.references.get("constant")
    for signal in allowed:
        refs.setdefault(signal, Reference(constant, constant.Config.model_validate({"kind": "constant", "value": 0.0})))
    return refs


def check_memory(exp: Experiment, plant: Plant, channels: list[int], copies: int = 1) -> None:
    """Stop before allocating when the run's arrays would not fit in memory (one line)."""
    sim = exp.section.simulation
    n_samples = preflight.samples(sim.t_end, sim.dt)
    needed = preflight.run_bytes(n_samples, len(TABLEAUS[sim.integrator].b), plant, channels, copies)
    advice = f"{n_samples:.3g} samples of dt = {sim.dt} s: shorten simulation.t_end or raise simulation.dt"
    if copies > 1:
        advice += f" ({copies} variants at once: a batch on each worker; fewer --jobs or a smaller sweep.batch_size)"
    preflight.check_memory(needed, "simulation.t_end", sim.t_end, advice)


def check_sweep_memory(exp: Experiment, copies: int) -> None:
    """The memory check of a sweep's ``copies`` concurrent variants of ``exp`` (no logs kept):
    states, inputs and every output and input as a reference channel per controller."""
    sec = exp.section
    plant = exp.plant_model.build(sec.plant.name, exp.plant_params, sec.plant.x0, sec.simulation.bounds)
    channels = [len(plant.outputs) + len(plant.inputs)] * len(exp.controllers)
    check_memory(exp, plant, channels, copies)


def perturbations(exp: Experiment, plant: Plant, grid: TimeGrid, seed_sequence: np.random.SeedSequence) -> Hooks:
    """What ``exp``'s uncertainties attach to the loop (:class:`~nlcx.uncertainty.base.Hooks`),
    each drawing from a generator of its own, spawned from ``seed_sequence`` in config order."""
    children = seed_sequence.spawn(len(exp.uncertainties))
    hooks = Hooks(plant=plant, t=grid.t, stage_times=grid.stage_times)
    for child, unc in zip(children, exp.uncertainties, strict=True):
        hooks.rng = np.random.default_rng(child)
        unc.model.apply(unc.config, hooks, f"uncertainty.{unc.label}")
    return hooks


class ReferenceCache:
    """Reference arrays r_k, kept so that the variants of a sweep that share their references
    share one (read-only) array, which the kernel then broadcasts.

    An array is keyed on its channels (each one's signal, time offset and reference
    configuration as sorted JSON) and the grid (dt, number of steps); at most ``size`` are
    kept, the least recently used dropped first."""

    def __init__(self, size: int = 64) -> None:
        self.size = size
        # keyed on ((signal, offset, configuration as JSON) of each channel, dt, steps)
        self._arrays: OrderedDict[tuple[tuple[tuple[str, float, str], ...], float, int], np.ndarray] = OrderedDict()

    def array(
        self, prepared: Prepared, signals: tuple[str, ...], offsets: tuple[float, ...] | None = None
    ) -> np.ndarray:
        """r_k for the given channels, shape (K+1, n_r); channel i is read at t + offsets[i]."""
        offsets = offsets or (0.0,) * len(signals)
        grid = prepared.grid
        specs = tuple(
            (s, off, json.dumps(prepared.references[s].config.model_dump(), sort_keys=True))
            for s, off in zip(signals, offsets, strict=True)
        )
        key = (specs, grid.dt, grid.n_steps)
        if key in self._arrays:
            self._arrays.move_to_end(key)
            return self._arrays[key]
        cols = [
            prepared.references[s].model.values(prepared.references[s].config, grid.t + off)
            for s, off in zip(signals, offsets, strict=True)
        ]
        array = np.ascontiguousarray(np.stack(cols, axis=-1) if cols else np.zeros((grid.t.size, 0)))
        array.flags.writeable = False  # shared by every variant that asks for the same channels
        self._arrays[key] = array
        if len(self._arrays) > self.size:
            self._arrays.popitem(last=False)
        return array

    def clear(self) -> None:
        """Drop every array."""
        self._arrays.clear()


#: The engine's reference arrays (:func:`reference_array`).
REFERENCES = ReferenceCache()


def reference_array(
    prepared: Prepared, signals: tuple[str, ...], offsets: tuple[float, ...] | None = None
) -> np.ndarray:
    """r_k for the given channels, shape (K+1, n_r); channel i is read at t + offsets[i]
    (shared through :data:`REFERENCES`)."""
    return REFERENCES.array(prepared, signals, offsets)


@dataclass
class Item:
    """One closed loop to simulate: a plant instance, a controller and what acts at its hook points."""

    plant: Plant
    controller: ControllerInstance
    ref: np.ndarray  # (K+1, n_r)
    dist: np.ndarray  # (K|1, s, n_d)
    dist_map: np.ndarray  # (n, n_d)
    elements: tuple[Element, ...] = ()
    element_data: np.ndarray | None = None  # (K+1, n_cols): the elements' time series side by side
    friction: np.ndarray | None = None  # (n_u, FRICTION_AXIS.size)


def items_of(prepared: Prepared) -> list[Item]:
    """The closed loops of one experiment: its plant under each of its controllers."""
    hooks = prepared.hooks
    dist, dist_map = hooks.dist_arrays()
    data = hooks.element_data()
    refs: dict[tuple[tuple[str, ...], tuple[float, ...] | None], np.ndarray] = {}
    out = []
    for c in prepared.controllers:
        key = (c.reference_signals, c.reference_offsets)
        if key not in refs:
            refs[key] = reference_array(prepared, c.reference_signals, c.reference_offsets)
        out.append(Item(prepared.plant, c, refs[key], dist[0], dist_map, tuple(hooks.elements), data, hooks.friction))
    return out

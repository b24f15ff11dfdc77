"""From validated experiments to closed-loop trajectories and metrics: the one pipeline.

:func:`evaluate` takes experiments (or prepared ones) through prepare -> simulate ->
measure. It assembles the numeric arrays the compiled kernel (:mod:`nlcx.kernel`) reads,
runs every closed loop of every experiment on one time grid through it (loops sharing
their equations and controller step go through one batched call) and measures all runs
together (:mod:`nlcx.metrics`). ``nlcx run``, sweeps, the calibration, the reproduction and
the tuners (through :class:`LoopSimulator`) all use it.
"""

from __future__ import annotations

import copy
import ctypes
import dataclasses
import functools
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from nlcx import metrics as m
from nlcx import preflight, registry
from nlcx.config import Experiment, MetricsSection, build, controller_section
from nlcx.controllers.base import ControllerInstance
from nlcx.errors import ConfigError
from nlcx.kernel.abi import (
    CALLBACK_SIG,
    CONTROLLER_SIG,
    ELEMENT_ENTRY,
    ELEMENT_SIG,
    HOOKS,
    RHS_SIG,
    STATUS_BOUND,
    STATUS_NONFINITE,
    callback_slots,
    element_slots,
)
from nlcx.kernel.friction import FA, FRICTION_AXIS, FRICTION_NONE, FRICTIONAL, FRICTIONLESS
from nlcx.plants.base import Plant, check_rows
from nlcx.references.base import MetricPlan
from nlcx.tuning.base import TuneContext
from nlcx.uncertainty.base import Element, Hooks

if TYPE_CHECKING:
    import pandas as pd

#: Butcher tableaus (A, b) of the fixed-step explicit Runge-Kutta methods.
TABLEAUS: dict[str, tuple[np.ndarray, np.ndarray]] = {
    "euler": (np.zeros((1, 1)), np.array([1.0])),
    "heun": (np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([0.5, 0.5])),
    "rk4": (
        np.array([[0.0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1.0, 0]]),
        np.array([1.0, 2.0, 2.0, 1.0]) / 6.0,
    ),
}


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
    a, _ = TABLEAUS[integrator]
    c = a.sum(axis=1)
    t = np.arange(n_steps + 1) * dt
    return TimeGrid(dt=dt, t=t, stage_times=t[:-1, None] + c[None, :] * dt)


@dataclass
class Run:
    """One controller's closed-loop run, truncated where it diverged."""

    controller: ControllerInstance
    status: str
    reason: str
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    r: np.ndarray
    #: Controller logs and friction forces (None when the simulation did not record them).
    log: np.ndarray | None
    friction: np.ndarray | None
    t_fail: float = math.nan

    @property
    def label(self) -> str:
        return self.controller.label


@dataclass
class Prepared:
    """Everything the kernel needs, built from an :class:`Experiment`."""

    experiment: Experiment
    plant: Plant
    controllers: list[ControllerInstance]
    references: dict[str, tuple[Any, Any]]
    grid: TimeGrid
    hooks: Hooks
    seed_sequence: np.random.SeedSequence
    #: Rows of tuning.csv: what the tuners of each controller found.
    tuning: list[dict[str, Any]] = field(default_factory=list)


@dataclass(frozen=True)
class MetricTable:
    """The long-form metric rows of experiments measured together: the column ``experiment``
    (an experiment's position in the measured list), then :data:`METRIC_COLUMNS`; each
    experiment's rows contiguous. The rows are computed when the runs are measured; the
    DataFrame (and the pandas import it needs) only when :attr:`frame` is first read. ``nlcx
    run`` never reads it: it writes metrics.csv from the rows (:attr:`Result.metric_rows`)."""

    rows: list[list[Any]]

    @functools.cached_property
    def frame(self) -> pd.DataFrame:
        import pandas as pd

        return pd.DataFrame(self.rows, columns=["experiment", *METRIC_COLUMNS])


@dataclass
class Result:
    """One experiment's runs and metrics. The metrics are a block of rows of a table shared
    by the experiments measured together (``rows``: the table and its row range), sliced
    out only when :attr:`metrics` is read (a sweep reads the shared tables instead)."""

    prepared: Prepared
    runs: list[Run]
    rows: tuple[MetricTable, int, int] | None = None
    timings: dict[str, float] = field(default_factory=dict)

    @functools.cached_property
    def metrics(self) -> pd.DataFrame:
        """Long-form metrics of the runs (columns :data:`METRIC_COLUMNS`)."""
        if self.rows is None:
            import pandas as pd

            return pd.DataFrame(columns=METRIC_COLUMNS)
        table, start, stop = self.rows
        return table.frame.iloc[start:stop][METRIC_COLUMNS].reset_index(drop=True)

    @property
    def metric_rows(self) -> list[list[Any]]:
        """The rows of :attr:`metrics` as lists of their :data:`METRIC_COLUMNS` values, without
        building a DataFrame."""
        if self.rows is None:
            return []
        table, start, stop = self.rows
        return [row[1:] for row in table.rows[start:stop]]


def _reference_models(exp: Experiment, plant: Plant) -> dict[str, tuple[Any, Any]]:
    """(model, config) per signal; outputs without an entry are regulated to 0."""
    allowed = plant.output_names + plant.input_names
    refs: dict[str, tuple[Any, Any]] = {}
    for signal, sec in exp.references.items():
        if signal not in allowed:
            raise ConfigError(
                f"reference.{signal}",
                sec.kind,
                f"not an output or input of {plant.name}; allowed: {', '.join(allowed)}",
            )
        refs[signal] = (sec.model, sec.config)
    constant = registry.references.get("constant")
    for signal in allowed:
        refs.setdefault(signal, (constant, constant.Config(kind="constant", value=0.0)))
    return refs


def _tuned_section(exp: Experiment, c: Any, plant: Plant, rows: list[dict[str, Any]]) -> Any:
    """The controller section of ``c`` after its tuners (in order) filled in its numbers."""
    if not c.tuners:
        return c
    path = f"controllers.{c.label}"
    ctx = TuneContext(
        plant=plant, label=c.label, path=path, dt=exp.section.simulation.dt, simulate=LoopSimulator(exp.raw)
    )
    data = c.config.model_dump()
    for tuner in c.tuners:
        data = tuner.model.tune(data, tuner.config, ctx)
    rows += ctx.rows
    return controller_section(c.label, data, path)


def _check_memory(exp: Experiment, plant: Plant, channels: list[int], copies: int = 1) -> None:
    """Stop before allocating when the run's arrays would not fit in memory (one line)."""
    sim = exp.section.simulation
    n_samples = preflight.samples(sim.t_end, sim.dt)
    needed = preflight.run_bytes(n_samples, len(TABLEAUS[sim.integrator][1]), plant, channels, copies)
    advice = f"{n_samples:.3g} samples of dt = {sim.dt} s: shorten simulation.t_end or raise simulation.dt"
    preflight.check_memory(needed, "simulation.t_end", sim.t_end, advice)


def check_sweep_memory(exp: Experiment, copies: int) -> None:
    """The memory check of a sweep's ``copies`` concurrent variants of ``exp`` (no logs kept):
    states, inputs and every output and input as a reference channel per controller."""
    sec = exp.section
    plant = exp.plant_model.build(sec.plant.name, exp.plant_params, sec.plant.x0, sec.simulation.bounds)
    channels = [len(plant.outputs) + len(plant.inputs)] * len(exp.controllers)
    _check_memory(exp, plant, channels, copies)


def prepare(exp: Experiment) -> Prepared:
    """Build the plant, controllers, references and perturbations of ``exp``."""
    sec = exp.section
    sim = sec.simulation
    plant = exp.plant_model.build(sec.plant.name, exp.plant_params, sec.plant.x0, sim.bounds)
    preflight.check_signal_names(plant)
    references = _reference_models(exp, plant)
    tuning: list[dict[str, Any]] = []
    controllers = []
    for c in exp.controllers:
        section = _tuned_section(exp, c, plant, tuning)
        controllers.append(section.model.build(c.label, section.config, plant, f"controllers.{c.label}", dt=sim.dt))
    preflight.check_references(exp.references, exp.references, plant, controllers)
    _check_memory(exp, plant, [len(c.reference_signals) + len(c.log_names) for c in controllers])
    grid = time_grid(sim.t_end, sim.dt, sim.integrator)
    seed_sequence = np.random.SeedSequence(sec.seed)
    # each uncertainty draws from a generator of its own, spawned in config order
    children = seed_sequence.spawn(len(exp.uncertainties))
    hooks = Hooks(plant=plant, t=grid.t, stage_times=grid.stage_times)
    for child, unc in zip(children, exp.uncertainties, strict=True):
        hooks.rng = np.random.default_rng(child)
        unc.model.apply(unc.config, hooks, f"uncertainty.{unc.label}")
    return Prepared(
        experiment=exp,
        plant=plant,
        controllers=controllers,
        tuning=tuning,
        references=references,
        grid=grid,
        hooks=hooks,
        seed_sequence=seed_sequence,
    )


def reference_array(
    prepared: Prepared, signals: tuple[str, ...], offsets: tuple[float, ...] | None = None
) -> np.ndarray:
    """r_k for the given channels, shape (K+1, n_r); channel i is read at t + offsets[i].

    Cached on the reference configuration and the grid, so the variants of a sweep that share
    their references share one (read-only) array, which the kernel then broadcasts.
    """
    offsets = offsets or (0.0,) * len(signals)
    grid = prepared.grid
    specs = tuple(
        (s, off, json.dumps(prepared.references[s][1].model_dump(), sort_keys=True))
        for s, off in zip(signals, offsets, strict=True)
    )
    key = (specs, grid.dt, grid.n_steps)
    cached = _REFERENCE_CACHE.get(key)
    if cached is None:
        t = grid.t
        cols = [
            prepared.references[s][0].values(prepared.references[s][1], t + off)
            for s, off in zip(signals, offsets, strict=True)
        ]
        cached = np.ascontiguousarray(np.stack(cols, axis=-1) if cols else np.zeros((t.size, 0)))
        if len(_REFERENCE_CACHE) > 64:
            _REFERENCE_CACHE.clear()
        _REFERENCE_CACHE[key] = cached
    return cached


_REFERENCE_CACHE: dict[tuple[Any, ...], np.ndarray] = {}


def _pad_rows(rows: list[np.ndarray]) -> np.ndarray:
    width = max(r.size for r in rows)
    out = np.zeros((len(rows), width))
    for i, r in enumerate(rows):
        out[i, : r.size] = r
    return out


def _failure_reason(plant: Plant, status: int, index: int, t_fail: float) -> str:
    n = len(plant.states)
    if status == STATUS_BOUND:
        name = plant.state_names[index]
        bound = plant.bounds[index]
        return f"diverged at t = {t_fail:.4g} s: |{name}| > {bound:.6g} (simulation.bounds)"
    if status == STATUS_NONFINITE:
        what = plant.state_names[index] if index < n else plant.input_names[index - n]
        return f"diverged at t = {t_fail:.4g} s: {what} became non-finite"
    return ""


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
    refs: dict[tuple[Any, ...], np.ndarray] = {}
    out = []
    for c in prepared.controllers:
        key = (c.reference_signals, c.reference_offsets)
        if key not in refs:
            refs[key] = reference_array(prepared, c.reference_signals, c.reference_offsets)
        out.append(Item(prepared.plant, c, refs[key], dist[0], dist_map, tuple(hooks.elements), data, hooks.friction))
    return out


def _element_arrays(group: list[Item]) -> tuple[tuple[Any, ...], tuple[np.ndarray, ...]]:
    """(function slots, (table, ep, es0, data)) of the loop elements of a group of items that
    share their element structure (hooks, functions and block sizes); rows are the items."""
    elements = group[0].elements
    functions = tuple(dict.fromkeys(e.function for e in elements))
    table = np.zeros((len(elements), ELEMENT_ENTRY.size))
    p_off = s_off = d_off = 0
    for i, e in enumerate(elements):
        table[i] = ELEMENT_ENTRY.pack(
            hook=HOOKS[e.hook], slot=functions.index(e.function),
            param_offset=p_off, state_offset=s_off, data_offset=d_off,
        )  # fmt: skip
        p_off += e.params.size
        s_off += e.state.size
        d_off += 0 if e.data is None else e.data.shape[1]
    ep = _pad_rows([np.concatenate([np.zeros(0), *(e.params for e in g.elements)]) for g in group])
    es = _pad_rows([np.concatenate([np.zeros(0), *(e.state for e in g.elements)]) for g in group])
    data = _stack([g.element_data for g in group], (1, d_off))
    return element_slots(functions), (table, ep, es, data)


def _stack(arrays: list[np.ndarray | None], empty_shape: tuple[int, ...]) -> np.ndarray:
    """Stack per-item arrays on a leading batch axis; one shared (or absent) array is broadcast."""
    first = arrays[0]
    if all(a is first for a in arrays):
        base = np.zeros(empty_shape) if first is None else first
        return np.ascontiguousarray(base[None])
    filled = [np.zeros(empty_shape) if a is None else a for a in arrays]
    # an axis of length 1 (e.g. no noise: one zero row for every sample) meets the others' length
    shape = tuple(max(sizes) for sizes in zip(*(a.shape for a in filled), strict=True))
    return np.ascontiguousarray(np.stack([np.broadcast_to(a, shape) for a in filled]))


def _has_friction(axes: np.ndarray | None) -> bool:
    """Whether an item's friction axes (FRICTION_AXIS rows) hold a friction model (as the kernel's
    :func:`nlcx.kernel.friction.has_friction` decides which rows take the friction path)."""
    return axes is not None and bool(np.any(axes[:, FA.model].astype(np.int64) != FRICTION_NONE))


def _group_key(item: Item) -> tuple[Any, ...]:
    c, plant = item.controller, item.plant
    elements = tuple((e.hook, id(e.function), e.params.size, e.state.size) for e in item.elements)
    data_width = 0 if item.element_data is None else item.element_data.shape[1]
    return (
        id(plant.rhs), id(c.step if c.general_step is None else c.general_step), tuple(id(f) for f in c.callbacks),
        len(plant.states), len(plant.inputs),
        plant.C.tobytes(), len(c.log_names), item.ref.shape, item.dist.shape, item.dist_map.tobytes(),
        elements, data_width,
    )  # fmt: skip


def _kernel_arrays(item: Item) -> tuple[np.ndarray | None, ...]:
    """Every array of an item the kernel reads (its functions are in :func:`_group_key`)."""
    c, plant = item.controller, item.plant
    elements = (a for e in item.elements for a in (e.params, e.state, e.data))
    return (plant.x0, plant.p, plant.bounds, c.cp, c.cs0, item.ref, item.dist, item.element_data, item.friction,
            *elements)  # fmt: skip


def _first_of_same_loop(items: list[Item], group_keys: list[tuple[Any, ...]]) -> list[int]:
    """``first[i]``: the first item whose closed loop is item i's (the same compiled functions,
    ``group_keys[i]``, and, bit for bit, the same arrays). The kernel's result for a variant does not depend on
    the batch around it, so such a loop is simulated once (an identification study's
    candidates share their proposed controller, a reproduction's figures their conventional
    runs). Arrays are compared by a SHA-1 of their bytes, each array object hashed once."""
    digests: dict[int, tuple[np.ndarray, tuple[Any, ...]]] = {}  # the array kept: its id stays its own

    def digest(a: np.ndarray | None) -> tuple[Any, ...] | None:
        if a is None:
            return None
        if id(a) not in digests:
            data = np.ascontiguousarray(a)
            digests[id(a)] = (a, (a.shape, a.dtype.str, hashlib.sha1(data, usedforsecurity=False).digest()))
        return digests[id(a)][1]

    first: dict[tuple[Any, ...], int] = {}
    return [
        first.setdefault((key, tuple(item.controller.log_names), *map(digest, _kernel_arrays(item))), i)
        for i, (item, key) in enumerate(zip(items, group_keys, strict=True))
    ]


class RecordArena:
    """Record arrays (X, U, logs, friction) handed out again once their runs are done with.

    A sweep batch's records are tens of MB. Fresh from ``np.empty`` for every batch, each of
    their pages costs the kernel a page fault and the operating system's zeroing when first
    written. A sweep worker lends a batch's records from its arena and, once the
    batch's metrics are written, :meth:`release` returns them: the next batch writes into the
    same memory. Only what the last batch used is kept."""

    def __init__(self) -> None:
        self._free: list[np.ndarray] = []
        self._lent: list[np.ndarray] = []

    def take(self, shape: tuple[int, ...]) -> np.ndarray:
        """An array of ``shape`` (its values undefined, as ``np.empty``'s)."""
        for i, a in enumerate(self._free):
            if a.shape == shape:
                a = self._free.pop(i)
                a.flags.writeable = True
                break
        else:
            a = np.empty(shape)
        self._lent.append(a)
        return a

    def release(self) -> None:
        """Every array lent so far may be handed out again: no run reading it is used after this."""
        self._free, self._lent = self._lent, []


#: glibc's mallopt parameters (malloc.h) and the values :func:`reuse_freed_memory` sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20
_TRIM_THRESHOLD = 128 << 20


@functools.cache
def reuse_freed_memory() -> bool:
    """Let this process's C allocator keep freed blocks of up to 32 MB for reuse (glibc only;
    elsewhere nothing changes). Returns whether it did.

    Measuring a batch forms rows of a few MB (outputs gathered from the records, errors, the
    terms of the trapezoidal sums). glibc serves a block that large by mapping fresh pages and
    unmaps it when freed, so every such temporary paid a page fault and the zeroing of each of
    its pages; a threshold of 32 MB (and a trim threshold of 128 MB, above which the top of the
    heap is returned to the system) keeps them in the heap. :func:`evaluate` calls it, so every
    process that measures runs (``nlcx run``, sweep workers, the reproduction's workers, tuners)
    keeps its freed blocks; it changes how much memory the process keeps, never a value."""
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return False
    except (ValueError, OSError):
        return False
    libc = ctypes.CDLL(None)
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD) and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))


def _record_arrays(
    group: list[Item], n_k: int, n_rec: int, empty: Callable[[tuple[int, ...]], np.ndarray]
) -> tuple[np.ndarray, ...]:
    """(X, U, LOG, FRIC) of a group of items: states and inputs at the n_k samples, controller
    logs and friction forces at n_rec (1: not recorded). The kernel writes every sample up to
    where a run stops; the rest is never read."""
    plant, n_b = group[0].plant, len(group)
    n_u = len(plant.inputs)
    return (
        empty((n_b, n_k, len(plant.states))), empty((n_b, n_k, n_u)),
        empty((n_b, n_rec, len(group[0].controller.log_names))), empty((n_b, n_rec, n_u)),
    )  # fmt: skip


def simulate_items(
    items: list[Item], grid: TimeGrid, integrator: str, record_logs: bool = True, arena: RecordArena | None = None
) -> list[Run]:
    """Integrate every item; items sharing plant equations and controller kind go through one
    batched kernel call (per-item parameters, states, references and perturbations), and an
    item whose closed loop equals an earlier one's shares that one's trajectory
    (:func:`_first_of_same_loop`; the trajectories are read-only).

    ``record_logs=False`` skips the controller logs and friction forces (``Run.log`` and
    ``Run.friction`` are None): a sweep that keeps only metrics does not need them. With an
    ``arena`` the records are its arrays (see :class:`RecordArena`)."""
    from nlcx.kernel.integrator import simulate  # loaded (or compiled) on first use: see load_kernel

    a, b = TABLEAUS[integrator]
    empty = np.empty if arena is None else arena.take
    keys = [_group_key(item) for item in items]
    first = _first_of_same_loop(items, keys)
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i, key in enumerate(keys):
        if first[i] == i:
            groups.setdefault(key, []).append(i)
    runs: list[Run | None] = [None] * len(items)
    n_k = grid.t.size
    for indices, step in _kernel_calls(list(groups.values()), items):
        group = [items[i] for i in indices]
        plant = group[0].plant
        check_rows(plant)
        n_u, n_b = len(plant.inputs), len(group)
        plants = [g.plant for g in group]
        X, U, LOG, FRIC = _record_arrays(group, n_k, n_k if record_logs else 1, empty)
        status = np.zeros(n_b, dtype=np.int64)
        n_valid = np.zeros(n_b, dtype=np.int64)
        fail_index = np.zeros(n_b, dtype=np.int64)
        element_fns, element_arrays = _element_arrays(group)
        simulate(
            plant.rhs,
            step,
            callback_slots(group[0].controller.callbacks),
            element_fns,
            (a, b),
            (
                np.ascontiguousarray(np.stack([q.x0 for q in plants])),
                _stack([q.p for q in plants], plant.p.shape),
                np.ascontiguousarray(plant.C),
                _stack([q.bounds for q in plants], plant.bounds.shape),
            ),
            (
                _pad_rows([g.controller.cp for g in group]),
                _pad_rows([g.controller.cs0 for g in group]),
                _stack([g.ref for g in group], group[0].ref.shape),
            ),
            element_arrays,
            (
                _stack([g.dist for g in group], group[0].dist.shape),
                np.ascontiguousarray(group[0].dist_map),
                _stack([g.friction for g in group], (n_u, FRICTION_AXIS.size)),
            ),
            grid.dt,
            (X, U, LOG, FRIC),
            (status, n_valid, fail_index),
            FRICTIONAL if any(_has_friction(g.friction) for g in group) else FRICTIONLESS,
        )
        for records in (X, U, LOG, FRIC):  # runs of identical loops share them
            records.flags.writeable = False
        for j, i in enumerate(indices):
            k = int(n_valid[j])
            t_fail = float(grid.t[k - 1] + grid.dt) if status[j] else math.nan
            runs[i] = Run(
                controller=group[j].controller,
                status="unstable" if status[j] else "ok",
                reason=_failure_reason(group[j].plant, int(status[j]), int(fail_index[j]), t_fail),
                t=grid.t[:k],
                x=X[j, :k],
                u=U[j, :k],
                r=group[j].ref[:k],
                log=LOG[j, :k] if record_logs else None,
                friction=FRIC[j, :k] if record_logs else None,
                t_fail=t_fail,
            )
    return _with_repeats(runs, items, first)


#: Rows a structure needs for a kernel call of its own (below, see :func:`_kernel_calls`).
_MIN_ROWS_PER_STEP = 8


def _kernel_calls(groups: list[list[int]], items: list[Item]) -> list[tuple[list[int], Any]]:
    """(items, controller step) of each kernel call. A group of items whose controllers share
    their kind but not their step (PIDs of different loop structures, each running the step
    compiled for its own, ``pid.step_for``) is split into a call per step when every step has
    at least :data:`_MIN_ROWS_PER_STEP` rows, and is otherwise one call of the kind's general
    step (the same arithmetic, so the same bits): a call's cost per time step, shared by its
    rows, outweighs the faster step for one or two rows (``nlcx run`` of a conventional PID
    against an AGS PID is faster as one call)."""
    calls: list[tuple[list[int], Any]] = []
    for indices in groups:
        by_step: dict[int, list[int]] = {}
        for i in indices:
            by_step.setdefault(id(items[i].controller.step), []).append(i)
        if len(by_step) == 1 or all(len(rows) >= _MIN_ROWS_PER_STEP for rows in by_step.values()):
            calls += [(rows, items[rows[0]].controller.step) for rows in by_step.values()]
        else:
            calls.append((indices, items[indices[0]].controller.general_step))
    return calls


def _with_repeats(runs: list[Run | None], items: list[Item], first: list[int]) -> list[Run]:
    """Every item's run: an item repeating the loop of item ``first[i]`` gets that run's
    trajectory under its own controller (label) and reference."""
    out = []
    for i, j in enumerate(first):
        source = runs[j]
        assert source is not None
        out.append(
            source
            if j == i
            else dataclasses.replace(source, controller=items[i].controller, r=items[i].ref[: source.t.size])
        )
    return out


METRIC_COLUMNS = ["controller", "signal", "metric", "value", "unit", "status", "note"]


def _unit(template: str, signal_unit: str) -> str:
    return template.replace("signal", signal_unit or "1").replace("input", signal_unit or "1")


def _signal_metrics(
    t: np.ndarray, y: np.ndarray, r: np.ndarray, plan: MetricPlan, cfg: MetricsSection
) -> dict[str, Any]:
    values: dict[str, Any] = {}
    if plan.kind == "step":
        values.update(
            m.step_response_metrics(
                t,
                y,
                t_step=plan.t_step,
                final=plan.final,
                band=cfg.settling_band,
                rise_limits=tuple(cfg.rise_limits),
                ss_window=cfg.ss_window,
            )
        )
    elif plan.kind == "regulation":
        values.update(
            m.regulation_metrics(
                t,
                y,
                reference=plan.final,
                band=cfg.settling_band,
                abs_tol=cfg.regulation_abs_tol,
                ss_window=cfg.ss_window,
            )
        )
    values.update(m.error_integrals(t, r - y, t0=plan.t_step))
    return values


_NAN_NOTES = {
    "settling_time": "did not settle within the run",
    "rise_time": "did not reach the upper rise level",
}


def _outputs(xs: list[np.ndarray], c_row: np.ndarray) -> np.ndarray:
    """y = x c for each state trajectory x, stacked (B, T); a row of C that selects one state
    (the usual case) is a gather, not a product."""
    (nonzero,) = np.nonzero(c_row)
    if nonzero.size == 1 and c_row[nonzero[0]] == 1.0:
        return np.stack([x[:, nonzero[0]] for x in xs])
    return np.stack([x @ c_row for x in xs])


def _reference_rows(columns: list[np.ndarray]) -> np.ndarray:
    """The references of runs as rows (B, T); one row (T,), broadcast, when every run reads the
    same samples (the variants of a sweep share their reference array)."""
    first = columns[0]
    key = (first.__array_interface__["data"][0], first.shape, first.strides)
    if all((c.__array_interface__["data"][0], c.shape, c.strides) == key for c in columns[1:]):
        return first
    return np.stack(columns)


def _blocks(members: list[int], n_samples: int) -> list[list[int]]:
    """``members`` in blocks of :func:`nlcx.metrics.rows_per_block` runs: the rows gathered for
    the metric functions (outputs, errors, inputs) are formed a block at a time, in memory
    that stays in cache (forming them for a whole batch at once costs more than the metrics
    themselves). Each row's metrics are the same whatever the block it is in."""
    size = m.rows_per_block(n_samples)
    return [members[k : k + size] for k in range(0, len(members), size)]


def _per_run(
    batch: Mapping[str, np.ndarray], members: list[int], signal: str
) -> dict[tuple[int, str], dict[str, float]]:
    """A metric function's batched result (name -> value per row) split by run: (run, signal)
    -> {name: value}, row k being run ``members[k]``."""
    return {(i, signal): {name: float(v[k]) for name, v in batch.items()} for k, i in enumerate(members)}


def _measured_outputs(run: Run, plant: Plant) -> list[str]:
    """Outputs of ``run`` that follow a reference (measured against it)."""
    return [s for s in dict.fromkeys(run.controller.reference_signals) if s in plant.output_names]


def _input_step(run: Run, plant: Plant, plans: dict[str, MetricPlan]) -> MetricPlan | None:
    """The earliest step on an input the controller applies (an open-loop step test), if any."""
    steps = [plans[s] for s in run.controller.reference_signals if s in plant.input_names and plans[s].kind == "step"]
    return min(steps, key=lambda plan: plan.t_step) if steps else None


def _tracking_values(
    plant: Plant, runs: list[Run], plans: list[dict[str, MetricPlan]], ok: list[int], cfg: MetricsSection
) -> dict[tuple[int, str], dict[str, float]]:
    """Metrics of each output that follows a reference, batched over runs sharing its plan."""
    groups: dict[tuple[str, MetricPlan, int], list[int]] = {}
    for i in ok:
        for s in _measured_outputs(runs[i], plant):
            groups.setdefault((s, plans[i][s], runs[i].t.size), []).append(i)
    values: dict[tuple[int, str], dict[str, float]] = {}
    for (s, plan, n_samples), group in groups.items():
        j = plant.output_names.index(s)
        for members in _blocks(group, n_samples):
            y = _outputs([runs[i].x for i in members], plant.C[j])
            r = _reference_rows([runs[i].r[:, runs[i].controller.reference_signals.index(s)] for i in members])
            batch = _signal_metrics(runs[members[0]].t, y, r, plan, cfg)
            values.update(_per_run(batch, members, s))
    return values


def _open_loop_values(
    plant: Plant, runs: list[Run], plans: list[dict[str, MetricPlan]], ok: list[int], cfg: MetricsSection
) -> dict[tuple[int, str], dict[str, float]]:
    """Step characteristics (:func:`nlcx.metrics.step_info`, MATLAB's ``stepinfo``) of every
    output not following a reference, after a step on an input, against its own final value."""
    groups: dict[tuple[str, float, int], list[int]] = {}
    for i in ok:
        step = _input_step(runs[i], plant, plans[i])
        if step is None:
            continue
        followed = _measured_outputs(runs[i], plant)
        for s in plant.output_names:
            if s not in followed:
                groups.setdefault((s, step.t_step, runs[i].t.size), []).append(i)
    values: dict[tuple[int, str], dict[str, float]] = {}
    for (s, t_step, n_samples), group in groups.items():
        for members in _blocks(group, n_samples):
            y = _outputs([runs[i].x for i in members], plant.C[plant.output_names.index(s)])
            batch = m.step_info(
                runs[members[0]].t, y, t_step=t_step, settling_band=cfg.settling_band,
                rise_limits=tuple(cfg.rise_limits),
            )  # fmt: skip
            values.update(_per_run(batch, members, s))
    return values


def _input_values(plant: Plant, runs: list[Run], ok: list[int]) -> dict[tuple[int, str], dict[str, float]]:
    """Effort metrics of every input, batched over runs of the same length."""
    by_length: dict[int, list[int]] = {}
    for i in ok:
        by_length.setdefault(runs[i].t.size, []).append(i)
    values: dict[tuple[int, str], dict[str, float]] = {}
    for n_samples, group in by_length.items():
        t = runs[group[0]].t
        for members in _blocks(group, n_samples):
            for j, name in enumerate(plant.input_names):
                batch = m.input_metrics(t, np.stack([runs[i].u[:, j] for i in members]))
                values.update(_per_run(batch, members, name))
    return values


def _metric_unit(name: str, signal_unit: str) -> str:
    return _unit(m.METRIC_UNITS.get(name) or m.STEP_INFO_UNITS.get(name, ""), signal_unit)


def measure_runs(
    plant: Plant, runs: list[Run], plans: list[dict[str, MetricPlan]], cfg: MetricsSection
) -> list[list[Any]]:
    """Long-form metric rows of runs on plants with ``plant``'s outputs and inputs.

    Outputs that follow a reference get the step / regulation / tracking metrics of their
    plan; with a step on an input the controller applies (``open_loop``), every other output
    gets its step characteristics against its own final value; every input gets its effort.
    The metrics of runs that completed are computed together, vectorised over the runs that
    share a plan (a sweep measures thousands of runs in a few calls). A row is the position
    of its run in ``runs``, then the values of :data:`METRIC_COLUMNS`.
    """
    ok = [i for i, r in enumerate(runs) if r.status == "ok"]
    values = {
        **_tracking_values(plant, runs, plans, ok, cfg),
        **_open_loop_values(plant, runs, plans, ok, cfg),
        **_input_values(plant, runs, ok),
    }
    rows: list[list[Any]] = []
    for i, run in enumerate(runs):
        label = run.label
        if run.status != "ok":
            rows.append([i, label, "all", "t_fail", run.t_fail, "s", run.status, run.reason])
            rows += [
                [i, label, s, "settling_time", math.nan, "s", run.status, run.reason]
                for s in _measured_outputs(run, plant)
            ]
            continue
        followed = _measured_outputs(run, plant)
        others = [s for s in plant.output_names if s not in followed]
        for s in [*followed, *others, *plant.input_names]:
            unit = plant.unit_of(s)
            for name, v in values.get((i, s), {}).items():
                note = _NAN_NOTES.get(name, "undefined") if math.isnan(v) else ""
                rows.append([i, label, s, name, v, _metric_unit(name, unit), "ok", note])
    return rows


def _controller_records(run: Run) -> list[dict[str, Any]]:
    """tuning.csv rows a controller reports itself: its records and its logs' final values."""
    c = run.controller
    rows = [{"controller": c.label, "tuner": "controller", "parameter": k, "value": v} for k, v in c.records.items()]
    if run.log is not None:
        rows += [
            {"controller": c.label, "tuner": "controller", "parameter": f"{name}.final",
             "value": float(run.log[-1, c.log_names.index(name)])}
            for name in c.final_logs
        ]  # fmt: skip
    return rows


def _metric_plans(prepared: Prepared) -> dict[str, MetricPlan]:
    return {s: model.metric_plan(cfg) for s, (model, cfg) in prepared.references.items()}


def _measure_all(prepared: list[Prepared], runs: list[list[Run]]) -> list[tuple[MetricTable, int, int] | None]:
    """Metrics of every experiment's runs as (shared table, first row, end row); experiments
    with the same plant signals and metric definitions are measured together (vectorised
    over all their runs). A shared table has the column ``experiment``, the position in
    ``prepared``; each experiment's rows are contiguous."""
    groups: dict[tuple[Any, ...], list[int]] = {}
    for e, p in enumerate(prepared):
        plant = p.plant
        key = (
            plant.name,
            tuple(plant.output_names),
            tuple(plant.input_names),
            p.experiment.section.metrics.model_dump_json(),
        )
        groups.setdefault(key, []).append(e)
    rows: list[tuple[MetricTable, int, int] | None] = [None] * len(prepared)
    for members in groups.values():
        owner = [e for e in members for _ in runs[e]]
        flat = [r for e in members for r in runs[e]]
        plans = [_metric_plans(prepared[e]) for e in owner]
        first = prepared[members[0]]
        table = MetricTable(measure_runs(first.plant, flat, plans, first.experiment.section.metrics))
        for row in table.rows:
            row[0] = owner[row[0]]  # the run's position in ``flat`` -> its experiment's in ``prepared``
        experiment = [row[0] for row in table.rows]
        bounds = np.searchsorted(experiment, members, side="left"), np.searchsorted(experiment, members, side="right")
        for e, start, stop in zip(members, *bounds, strict=True):
            rows[e] = (table, int(start), int(stop))
    return rows


def shared_metrics(results: list[Result]) -> pd.DataFrame:
    """The metrics of ``results`` (from one :func:`evaluate` call) in one table, with the
    column ``experiment``: the position of the row's result in ``results``, ascending."""
    import pandas as pd

    tables = {id(r.rows[0]): r.rows[0].frame for r in results if r.rows is not None}
    if not tables:
        return pd.DataFrame(columns=["experiment", *METRIC_COLUMNS])
    table = pd.concat(list(tables.values()), ignore_index=True)
    return table.sort_values("experiment", kind="stable", ignore_index=True)


def evaluate(
    experiments: Sequence[Experiment | Prepared],
    record_logs: bool = True,
    measure: bool = True,
    arena: RecordArena | None = None,
) -> list[Result]:
    """The pipeline: experiments (or prepared ones) to trajectories and metrics, batched.

    Every closed loop of every experiment on the same time grid goes through the kernel
    together (:func:`simulate_items`), and the runs are measured together (:func:`measure_runs`).
    ``nlcx run``, sweeps, tuners (through :class:`LoopSimulator`), the calibration and the
    thesis reproduction all come through here. ``record_logs=False`` skips controller logs and
    friction forces; ``measure=False`` leaves the metrics empty (a tuner scoring runs itself).
    With an ``arena`` the runs' records are its arrays, lent until the caller releases them
    (:class:`RecordArena`). Timings are per experiment; a shared kernel call is split evenly
    between its experiments.
    """
    reuse_freed_memory()
    prepared, timings = [], []
    for exp in experiments:
        start = time.perf_counter()
        prepared.append(exp if isinstance(exp, Prepared) else prepare(exp))
        timings.append({"prepare": time.perf_counter() - start})
    runs: list[list[Run]] = [[] for _ in prepared]
    grids: dict[tuple[Any, ...], list[int]] = {}
    for e, p in enumerate(prepared):
        sim = p.experiment.section.simulation
        grids.setdefault((sim.dt, p.grid.n_steps, sim.integrator), []).append(e)
    for (_, _, integrator), members in grids.items():
        start = time.perf_counter()
        items = [(e, item) for e in members for item in items_of(prepared[e])]
        done = simulate_items([item for _, item in items], prepared[members[0]].grid, integrator, record_logs, arena)
        for (e, _), run in zip(items, done, strict=True):
            runs[e].append(run)
        for e in members:
            timings[e]["simulate"] = (time.perf_counter() - start) / len(members)
    start = time.perf_counter()
    rows = _measure_all(prepared, runs) if measure else [None] * len(prepared)
    results = []
    for p, rs, block, timing in zip(prepared, runs, rows, timings, strict=True):
        timing["metrics"] = (time.perf_counter() - start) / len(prepared)
        p.tuning = [*p.tuning, *(row for run in rs for row in _controller_records(run))]
        results.append(Result(prepared=p, runs=rs, rows=block, timings=timing))
    return results


def remeasure(results: Sequence[Result], metrics: Mapping[str, Any]) -> list[Result]:
    """The runs of ``results`` (one :func:`evaluate` call) measured again under other metric
    definitions, without simulating them again: ``metrics`` updates the metrics section of
    every experiment (e.g. ``{"rise_limits": [0, 1], "settling_band": 0.05}``)."""
    prepared = []
    for r in results:
        section = r.prepared.experiment.section
        defined = MetricsSection.model_validate({**section.metrics.model_dump(), **metrics})
        experiment = dataclasses.replace(r.prepared.experiment, section=section.model_copy(update={"metrics": defined}))
        prepared.append(dataclasses.replace(r.prepared, experiment=experiment))
    rows = _measure_all(prepared, [r.runs for r in results])
    return [dataclasses.replace(r, prepared=p, rows=block) for r, p, block in zip(results, prepared, rows, strict=True)]


def load_kernel() -> None:
    """Load the kernel (:func:`nlcx.kernel.integrator.simulate`) from numba's disk cache, or
    compile it (seconds; loading from a warm cache is quick). Importing this module does not: a process
    that only prepares and measures (:func:`prewarm`) never needs it."""
    import nlcx.kernel.integrator  # noqa: F401


def prewarm(exp: Experiment) -> None:
    """Compile into numba's disk cache (or load from it) what :func:`evaluate` of ``exp`` needs
    besides the kernel: the functions of its plant, controllers and loop elements for the
    kernel's signatures, and the metric functions, run on zero trajectories of the right shapes.

    ``nlcx run`` starts this in a second process when loading the kernel takes long (an empty
    or stale cache), so that the two compile side by side and the run then loads these from the
    cache (:class:`nlcx.compiled_cache.CompileHelper`). Nothing is simulated, so an experiment
    with tuners, which simulate while preparing, is left alone."""
    if any(c.tuners for c in exp.controllers):
        return
    prepared = prepare(exp)
    n_k = prepared.grid.t.size
    runs = []
    for item in items_of(prepared):
        c, plant = item.controller, item.plant
        for function, signature in (
            (plant.rhs, RHS_SIG),
            (c.step, CONTROLLER_SIG),
            *((f, CALLBACK_SIG) for f in c.callbacks),
            *((e.function, ELEMENT_SIG) for e in item.elements),
        ):
            if not function.signatures:  # one declared with its signature is compiled on import
                function.compile(signature)
        runs.append(Run(controller=c, status="ok", reason="", t=prepared.grid.t, x=np.zeros((n_k, len(plant.states))),
                        u=np.zeros((n_k, len(plant.inputs))), r=item.ref, log=np.zeros((n_k, len(c.log_names))),
                        friction=np.zeros((n_k, len(plant.inputs)))))  # fmt: skip
    _measure_all([prepared], [runs])


def run_experiment(exp: Experiment) -> Result:
    """Prepare, simulate and measure one experiment (:func:`evaluate` of one); timings in seconds."""
    return evaluate([exp])[0]


@dataclass(frozen=True)
class LoopSimulator:
    """An experiment's plant, references and uncertainties under other controllers: what a
    tuner simulates (:attr:`nlcx.tuning.base.TuneContext.simulate`). Picklable, so a tuner can
    hand it to a process pool.

    ``controllers`` maps labels to controller configurations (their ``tune`` lists are
    dropped); ``simulation`` updates keys of the simulation section; ``uncertainty``, when
    given, replaces the uncertainty section (``{}``: the nominal plant).
    """

    raw: dict[str, Any]

    def __call__(
        self,
        controllers: Mapping[str, Mapping[str, Any]],
        simulation: Mapping[str, Any] | None = None,
        uncertainty: Mapping[str, Any] | None = None,
        measure: bool = True,
    ) -> Result:
        raw = copy.deepcopy(self.raw)
        raw["controllers"] = {label: {k: v for k, v in c.items() if k != "tune"} for label, c in controllers.items()}
        raw.setdefault("simulation", {}).update(simulation or {})
        if uncertainty is not None:
            raw["uncertainty"] = dict(uncertainty)
        return evaluate([build(raw)], measure=measure)[0]

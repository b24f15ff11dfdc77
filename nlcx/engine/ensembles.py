"""Ensembles: many variants of one prepared experiment that differ only in numbers of its packed arrays.

A columnar sweep (:mod:`nlcx.sweeps.columnar`) prepares one experiment, the :class:`Template`,
and finds where each varied value lands in the arrays the kernel reads (its :class:`Slot`\\ s).
:func:`simulate_ensemble` then packs a batch of variants straight from the value columns: the
template's kernel arguments (:mod:`nlcx.engine.simulate`) repeated once per variant, each slot
written from its column, every call of the template's loop structure run over the whole batch.
:func:`measure_ensemble` computes the metric rows of :func:`nlcx.engine.measure_runs` for the
batch as columns, with the same metric functions on the same rows, so the same bits.

The item arrays a slot can address (:data:`ITEM_FIELDS`) are every per-loop array of the
kernel's arguments: the plant's x0, p and bounds, the controller's cp and cs0, the reference
rows, the loop elements' parameters, states and data, the disturbance and the friction axes.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias

import numpy as np

from nlcx.engine.batching import group_key, groups_of, kernel_calls
from nlcx.engine.measure import signal_values
from nlcx.engine.metric_rows import Categories, MetricColumns, RowBlock, failed_block, ok_block, ordered
from nlcx.engine.plan import MeasuredSignal, MetricPlan, signal_plans
from nlcx.engine.prepared import TABLEAUS, Item, Prepared, items_of
from nlcx.engine.simulate import (
    controller_call,
    element_params,
    element_states,
    empty_records,
    failure_reason,
    loop_elements,
    plant_call,
    plant_forces,
)
from nlcx.kernel.signatures import ControllerStep
from nlcx.kernel.structures import (
    ControllerCall,
    Integration,
    LoopElements,
    Outcome,
    PlantCall,
    PlantForces,
    method_of,
)
from nlcx.plants.base import Plant

#: The structures of a kernel call: (plant, controller, elements, forces).
CallArguments: TypeAlias = tuple[PlantCall, ControllerCall, LoopElements, PlantForces]

#: The per-loop arrays of an item, by name, and the kernel argument (structure, field) each becomes.
ITEM_FIELDS: dict[str, tuple[Callable[[Item], np.ndarray | None], str, str]] = {
    "x0": (lambda it: it.plant.x0, "plant", "x0"),
    "p": (lambda it: it.plant.p, "plant", "p"),
    "bounds": (lambda it: it.plant.bounds, "plant", "bounds"),
    "cp": (lambda it: it.controller.cp, "controller", "cp"),
    "cs0": (lambda it: it.controller.cs0, "controller", "cs0"),
    "ref": (lambda it: it.ref, "controller", "ref"),
    "ep": (element_params, "elements", "ep"),
    "es0": (element_states, "elements", "es0"),
    "data": (lambda it: it.element_data, "elements", "data"),
    "dist": (lambda it: it.dist, "forces", "dist"),
    "friction": (lambda it: it.friction, "forces", "friction"),
}


@dataclass(frozen=True)
class Slot:
    """Where a varied value lands: the flat ``positions`` of field ``field`` (:data:`ITEM_FIELDS`)
    of the template's loop ``item`` hold the value itself."""

    item: int
    field: str
    positions: tuple[int, ...]


@dataclass
class Template:
    """One variant's prepared experiment and its closed loops: what every variant of an ensemble shares."""

    prepared: Prepared
    items: list[Item]
    #: The metric rows of each loop (built once, with the template).
    plan: MetricPlan

    @classmethod
    def of(cls, prepared: Prepared) -> Template:
        items = items_of(prepared)
        return cls(prepared, items, MetricPlan.of(prepared, [item.controller for item in items]))

    def arrays(self) -> list[dict[str, np.ndarray | None]]:
        """Each loop's arrays (:data:`ITEM_FIELDS`)."""
        return [{name: get(item) for name, (get, _, _) in ITEM_FIELDS.items()} for item in self.items]

    def structure(self) -> tuple[Hashable, ...]:
        """What the variants of an ensemble must share, numbers of the item arrays aside: the
        loops' compiled functions and sizes (:func:`~nlcx.engine.batching.group_key`), their
        controller steps, references, logs and array shapes, the plant's signals, the metric
        plans and definitions, the grid and the integrator; and no tuned controller."""
        p = self.prepared
        shapes = tuple(tuple(None if a is None else a.shape for a in arrays.values()) for arrays in self.arrays())
        loops = tuple(
            (group_key(it), id(it.controller.step), it.controller.label, it.controller.reference_signals,
             it.controller.reference_offsets, it.controller.log_names)
            for it in self.items
        )  # fmt: skip
        plans = tuple(sorted((s, repr(plan)) for s, plan in signal_plans(p).items()))
        sec = p.experiment.section
        plant = p.plant
        signals = tuple((s, plant.unit_of(s)) for s in [*plant.state_names, *plant.input_names])
        return (loops, shapes, plans, sec.metrics.model_dump_json(), sec.simulation.integrator,
                p.grid.dt, p.grid.n_steps, plant.name, signals, bool(p.tuning))  # fmt: skip


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is b
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def changed_positions(base: Template, probe: Template, base_value: float, value: float) -> list[Slot] | str:
    """The slots of a value set to ``value`` in ``probe`` and ``base_value`` in ``base`` (two
    templates of the same structure): every entry of the item arrays that differs between
    them, each of which must hold the value itself in both; else why not (a text)."""
    if probe.structure() != base.structure():
        return "it changes the loops' structure (a compiled function, a shape or a metric plan)"
    slots = []
    for i, (a, b) in enumerate(zip(base.arrays(), probe.arrays(), strict=True)):
        for name, x in a.items():
            y = b[name]
            if x is None or y is None:
                continue
            differ = np.flatnonzero(~((x == y) | (np.isnan(x) & np.isnan(y))))
            if differ.size == 0:
                continue
            flat_x, flat_y = x.reshape(-1)[differ], y.reshape(-1)[differ]
            if not (np.all(flat_x == base_value) and np.all(flat_y == value)):
                return f"it is not packed as itself (it changes {name} of loop {i} to other numbers)"
            slots.append(Slot(i, name, tuple(int(d) for d in differ)))
    return slots


def substituted(
    template: Template, slots: Mapping[str, Sequence[Slot]], values: Mapping[str, float]
) -> list[dict[str, np.ndarray | None]]:
    """The template's item arrays with ``values`` written into their slots (a prediction, which
    a probe's prepared arrays must equal)."""
    arrays = [{k: None if v is None else v.copy() for k, v in a.items()} for a in template.arrays()]
    for key, key_slots in slots.items():
        for slot in key_slots:
            target = arrays[slot.item][slot.field]
            assert target is not None
            target.reshape(-1)[list(slot.positions)] = values[key]
    return arrays


def same_arrays(a: list[dict[str, np.ndarray | None]], b: list[dict[str, np.ndarray | None]]) -> bool:
    """Whether two lists of item arrays are equal, bit for bit (NaN equal to NaN)."""
    return all(_same(x[k], y[k]) for x, y in zip(a, b, strict=True) for k in x)


def probed_slots(
    base: Template, probe: Callable[[str, float], Template], base_values: Mapping[str, float],
    probes: Mapping[str, Sequence[float]],
) -> dict[str, tuple[Slot, ...]] | str:  # fmt: skip
    """Where each key's values land in ``base``'s arrays: the key set to each of its ``probes``
    values (``probe(key, value)``: the template with that value alone changed) must change the
    same entries, each to the value itself (:func:`changed_positions`); else why not (a text)."""
    slots: dict[str, tuple[Slot, ...]] = {}
    for key, values in probes.items():
        found: set[tuple[Slot, ...]] = set()
        for value in values:
            changed = changed_positions(base, probe(key, value), base_values[key], value)
            if isinstance(changed, str):
                return f"{key}: {changed}"
            found.add(tuple(changed))
        if len(found) > 1:
            return f"{key}: its values land in different places"
        slots[key] = found.pop() if found else ()
    return slots


def corner_agrees(
    base: Template, corner: Template, slots: Mapping[str, Sequence[Slot]], values: Mapping[str, float]
) -> bool:
    """Whether ``corner`` (the template prepared with ``values``) is ``base`` with ``values``
    written into their slots: the same structure and the same arrays, bit for bit."""
    return corner.structure() == base.structure() and same_arrays(corner.arrays(), substituted(base, slots, values))


@dataclass
class EnsembleCall:
    """One kernel call of an ensemble: its rows (variant e, loop i), its records and outcome."""

    variants: np.ndarray
    loops: np.ndarray
    X: np.ndarray
    U: np.ndarray
    status: np.ndarray
    n_valid: np.ndarray
    fail_index: np.ndarray
    bounds: np.ndarray


def _expanded(base: np.ndarray, n_variants: int, n_rows: int) -> np.ndarray:
    """A call's array for one variant (rows the pattern's loops, or one shared row) repeated for
    ``n_variants`` variants: (n_variants * n_rows, ...), variant-major."""
    rows = base if base.shape[0] == n_rows else np.repeat(base, n_rows, axis=0)
    return np.ascontiguousarray(np.tile(rows, (n_variants,) + (1,) * (rows.ndim - 1)))


def ensemble_calls(items: list[Item], n_variants: int) -> list[tuple[np.ndarray, ControllerStep]]:
    """The kernel calls of ``n_variants`` variants of the loops ``items`` (each variant's loops
    in the same order): (the loops of one variant in the call, the controller step it runs).
    The calls :func:`~nlcx.engine.batching.kernel_calls` makes for the variants' items, found on
    one variant's: a group of loops splits into a call per step when each step has
    :data:`~nlcx.engine.batching.MIN_ROWS_PER_STEP` rows over all the variants."""
    calls = kernel_calls(groups_of([group_key(item) for item in items]), items, copies=n_variants)
    return [(np.array(call.indices), call.step) for call in calls]


def call_arguments(
    template: Template, pattern: np.ndarray, step: ControllerStep, n_variants: int,
    slots: Mapping[str, Sequence[Slot]], columns: Mapping[str, np.ndarray],
) -> CallArguments:  # fmt: skip
    """(plant, controller, elements, forces) of a call: the pattern's loops of the template,
    repeated per variant, each slot's positions written from its column."""
    group = [template.items[i] for i in pattern]
    # fields are replaced by name (``_replace(**{name: array})``), which no static type can follow
    parts: dict[str, Any] = {
        "plant": plant_call(group),
        "controller": controller_call(group, step),
        "elements": loop_elements(group),
        "forces": plant_forces(group),
    }
    n_rows = len(group)
    filled: dict[tuple[str, str], np.ndarray] = {}
    for key, key_slots in slots.items():
        for slot in key_slots:
            _, part, name = ITEM_FIELDS[slot.field]
            if (part, name) not in filled:
                filled[part, name] = _expanded(getattr(parts[part], name), n_variants, n_rows)
            view = filled[part, name].reshape(n_variants, n_rows, -1)
            for j in np.flatnonzero(pattern == slot.item):
                view[:, j, list(slot.positions)] = columns[key][:, None]
    for (part, name), array in filled.items():
        parts[part] = parts[part]._replace(**{name: array})
    for part, names in (("plant", ("x0",)), ("controller", ("cp", "cs0")), ("elements", ("ep", "es0"))):
        for name in names:  # the per-loop states and rows the kernel writes or reads per row
            if (part, name) not in filled:
                parts[part] = parts[part]._replace(**{name: _expanded(getattr(parts[part], name), n_variants, n_rows)})
    for _, part, name in ITEM_FIELDS.values():  # held per loop, filled by no column: per row of the call
        array = getattr(parts[part], name)
        if (part, name) not in filled and n_variants > 1 and n_rows > 1 and array.shape[0] == n_rows:
            parts[part] = parts[part]._replace(**{name: _per_call_row(array, n_variants, n_rows)})
    return parts["plant"], parts["controller"], parts["elements"], parts["forces"]


def _per_call_row(array: np.ndarray, n_variants: int, n_rows: int) -> np.ndarray:
    """An array of one row per loop of the pattern (the disturbance, the friction axes) as the
    kernel indexes it: per row of the call, or one shared row when every loop's row is the same
    (the kernel reads row v of an array of more than one row, v the call's row)."""
    if all(np.array_equal(array[0], array[j], equal_nan=True) for j in range(1, n_rows)):
        return np.ascontiguousarray(array[:1])
    return _expanded(array, n_variants, n_rows)


def simulate_ensemble(
    template: Template, slots: Mapping[str, Sequence[Slot]], columns: Mapping[str, np.ndarray], n_variants: int
) -> list[EnsembleCall]:
    """Simulate ``n_variants`` variants of ``template``, variant e having ``columns[key][e]`` in
    the slots of each key: the calls :func:`nlcx.engine.simulate_items` makes for the variants'
    items (the same loops in the same kernel calls, so the same bits), their arrays packed from
    the columns instead of built per variant. No controller logs or friction forces are kept."""
    from nlcx.kernel.integrator import integrate_batch

    sim = template.prepared.experiment.section.simulation
    grid = template.prepared.grid
    tableau = TABLEAUS[sim.integrator]
    integration = Integration(method=method_of(sim.integrator), rk_a=tableau.a, rk_b=tableau.b, dt=grid.dt)
    items = template.items
    calls = []
    for pattern, step in ensemble_calls(items, n_variants):
        plant, controller, elements, forces = call_arguments(template, pattern, step, n_variants, slots, columns)
        n_b = n_variants * pattern.size
        records = empty_records([items[i] for i in pattern], grid.t.size, 1, n_rows=n_b)
        outcome = Outcome(*(np.zeros(n_b, dtype=np.int64) for _ in range(3)))
        integrate_batch(integration, plant, controller, elements, forces, records, outcome)
        calls.append(EnsembleCall(
            variants=np.repeat(np.arange(n_variants), pattern.size), loops=np.tile(pattern, n_variants),
            X=records.X, U=records.U, status=outcome.status, n_valid=outcome.n_valid,
            fail_index=outcome.fail_index, bounds=np.broadcast_to(plant.bounds, (n_b, plant.bounds.shape[-1])),
        ))  # fmt: skip
    return calls


@dataclass
class LoopRows:
    """One loop's rows for every variant of an ensemble: the records of its runs, in variant order."""

    X: np.ndarray  # (n_variants, n_k, n_x)
    U: np.ndarray
    status: np.ndarray
    n_valid: np.ndarray
    fail_index: np.ndarray
    bounds: np.ndarray
    #: The runs that stopped (variant positions), when (t_fail) and why (as a :class:`~nlcx.engine.Run` says it).
    stopped: np.ndarray
    t_fail: np.ndarray
    reasons: list[str]


def loop_rows(calls: list[EnsembleCall], template: Template) -> list[LoopRows]:
    """The runs of each loop of the template, gathered from the calls, in variant order, with
    the time and reason of each run that stopped."""
    out = []
    for i in range(len(template.items)):
        parts = [(c, np.flatnonzero(c.loops == i)) for c in calls]
        parts = [(c, rows) for c, rows in parts if rows.size]
        (call, rows), *rest = parts
        if rest:  # pragma: no cover - a loop runs in one call
            raise AssertionError("an ensemble's loop is split between kernel calls")
        take: slice | np.ndarray = slice(None) if rows.size == call.loops.size else rows  # the whole call: views
        status, n_valid, fail_index = call.status[take], call.n_valid[take], call.fail_index[take]
        outcome = failure_rows(template, status, n_valid, fail_index, call.bounds[take])
        outcome.X, outcome.U = call.X[take], call.U[take]
        out.append(outcome)
    return out


def failure_rows(
    template: Template, status: np.ndarray, n_valid: np.ndarray, fail_index: np.ndarray, bounds: np.ndarray
) -> LoopRows:
    """One loop's outcome rows (no records), with the time and reason of each run that stopped."""
    grid = template.prepared.grid
    stopped = np.flatnonzero(status != 0)
    t_fail = grid.t[n_valid[stopped] - 1] + grid.dt
    empty = np.empty((status.size, 0, 0))
    reasons = _reasons(template.prepared.plant, stopped, status, fail_index, n_valid, t_fail, bounds)
    return LoopRows(empty, empty, status, n_valid, fail_index, bounds, stopped, t_fail, reasons)


def _reasons(
    plant: Plant, stopped: np.ndarray, status: np.ndarray, fail_index: np.ndarray, n_valid: np.ndarray,
    t_fail: np.ndarray, bounds: np.ndarray,
) -> list[str]:  # fmt: skip
    """Each stopped run's reason (:func:`~nlcx.engine.simulate.failure_reason`), written once
    per distinct (status, failing index, time, bounds): runs that stop alike share their text."""
    if not stopped.size:
        return []
    rows = bounds[stopped]
    if (rows == rows[:1]).all():  # the common case: the runs share their bounds
        key = np.zeros(stopped.size, dtype=np.int64)
    else:
        key = np.unique(rows, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)
    for part in (n_valid[stopped], fail_index[stopped], status[stopped]):  # one integer per distinct tuple
        key = key * (int(part.max()) + 1) + part
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    texts = [failure_reason(plant, int(status[stopped[k]]), int(fail_index[stopped[k]]), float(t_fail[k]),
                             bounds[stopped[k]]) for k in first]  # fmt: skip
    return [texts[j] for j in inverse]


def loop_values(template: Template, i: int, rows: LoopRows, ok: np.ndarray) -> np.ndarray:
    """The metric values of loop i over its runs that finished (runs, width of its
    :class:`~nlcx.engine.plan.LoopPlan`), a column per metric row in the plan's order."""
    plan = template.plan.loops[i]
    picked = np.flatnonzero(ok)
    ref = template.items[i].ref
    values = np.empty((picked.size, plan.width))
    o = 0
    for signal in plan.signals:
        width = len(signal.metrics)
        y, taken = _signal_rows(template, signal, rows, picked)
        r = ref[:, signal.reference] if signal.reference >= 0 else y[:1]
        values[:, o : o + width] = signal_values(signal, template.plan.t, y, r, taken)
        o += width
    return values


def _signal_rows(
    template: Template, signal: MeasuredSignal, rows: LoopRows, picked: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(samples, rows of them to measure) of ``signal`` in the runs ``picked``: a state's or an
    input's column of the records (a view), or the outputs y = x C_j of those runs formed."""
    where, index = signal.source
    if where == "state":
        return rows.X[:, :, index], picked
    if where == "input":
        return rows.U[:, :, index], picked
    c_row = template.prepared.plant.C[index]
    return np.stack([x @ c_row for x in rows.X[picked]]).reshape(picked.size, -1), np.arange(picked.size)


#: Where the metric values of a loop's runs that finished come from (:func:`loop_values`, or
#: the GPU's: :func:`nlcx.engine.gpu.simulate_measure`).
OkValues = Callable[[Template, int, LoopRows, np.ndarray], np.ndarray]


def measure_ensemble(
    template: Template, rows: list[LoopRows], n_variants: int, ok_values: OkValues | None = None
) -> MetricColumns:
    """The metric rows of every variant's runs (:func:`nlcx.engine.measure_runs`'s rows, with
    the variant's position in the column ``variant``), as columns: by variant, then loop (the
    template's order), then row (the template's :class:`~nlcx.engine.plan.MetricPlan`).
    ``ok_values``: where the values of the runs that finished come from (default: measured
    here from the rows' records, :func:`loop_values`)."""
    cats = Categories()
    blocks: list[RowBlock] = []
    for i, loop in enumerate(rows):
        plan = template.plan.loops[i]
        ok = loop.status == 0
        if ok.any():
            value = (ok_values or loop_values)(template, i, loop, ok)
            blocks.append(ok_block(np.flatnonzero(ok), i, value, plan.rows(), cats, plan.label))
        if (~ok).any():
            blocks.append(
                failed_block(loop.stopped, i, loop.t_fail, loop.reasons, plan.failed_rows(), cats, plan.label)
            )
    return ordered(blocks, cats, n_variants, len(rows))

"""Simulating closed loops: the kernel's arguments assembled from the items, the kernel called,
its records turned into runs.

:func:`simulate_items` takes the items of any number of experiments on one time grid through
the kernel (:func:`nlcx.kernel.integrator.simulate`), batched by
:mod:`nlcx.engine.batching`; the kernel's arguments are the named structures of
:mod:`nlcx.kernel.structures`, built here item by item.
"""

from __future__ import annotations

import math
import time

import numpy as np

from nlcx.engine.batching import group_key, groups_of, kernel_calls
from nlcx.engine.prepared import TABLEAUS, Item, Prepared, TimeGrid, items_of
from nlcx.engine.results import Run
from nlcx.kernel.abi import ELEMENT_ENTRY, HOOKS, STATUS_BOUND, STATUS_NONFINITE, callback_slots, element_slots
from nlcx.kernel.friction import FRICTION_AXIS
from nlcx.kernel.signatures import ControllerStep
from nlcx.kernel.structures import (
    ControllerCall,
    Integration,
    LoopElements,
    Outcome,
    PlantCall,
    PlantForces,
    Records,
    method_of,
)
from nlcx.plants.base import Plant, check_rows


def simulate_experiments(
    prepared: list[Prepared], record_logs: bool, timings: list[dict[str, float]]
) -> list[list[Run]]:
    """The runs of every prepared experiment: the closed loops of the experiments on the same
    time grid (dt, number of steps, integrator) go through one :func:`simulate_items` call, whose
    time is split evenly between them (``timings[e]["simulate"]``)."""
    runs: list[list[Run]] = [[] for _ in prepared]
    grids: dict[tuple[float, int, str, str], list[int]] = {}
    for e, p in enumerate(prepared):
        sim = p.experiment.section.simulation
        grids.setdefault((sim.dt, p.grid.n_steps, sim.integrator, sim.device), []).append(e)
    for members in grids.values():
        start = time.perf_counter()
        items = [(e, item) for e in members for item in items_of(prepared[e])]
        grid, sim = prepared[members[0]].grid, prepared[members[0]].experiment.section.simulation
        done = simulate_items([item for _, item in items], grid, sim.integrator, record_logs, sim.device)
        for (e, _), run in zip(items, done, strict=True):
            runs[e].append(run)
        for e in members:
            timings[e]["simulate"] = (time.perf_counter() - start) / len(members)
    return runs


def simulate_items(
    items: list[Item], grid: TimeGrid, integrator: str, record_logs: bool = True, device: str = "cpu"
) -> list[Run]:
    """Integrate every item; items sharing plant equations and controller kind go through one
    batched kernel call (per-item parameters, states, references and perturbations). The
    trajectories are read-only views of the call's records.

    ``record_logs=False`` skips the controller logs and friction forces (``Run.log`` and
    ``Run.friction`` are None): a sweep that keeps only metrics does not need them.
    ``device="cuda"``: on the GPU (:mod:`nlcx.kernel.cuda_loop`), the same calls."""
    from nlcx.kernel.integrator import integrate_batch  # loaded (or compiled) on first use: see load_kernel

    tableau = TABLEAUS[integrator]
    integration = Integration(method=method_of(integrator), rk_a=tableau.a, rk_b=tableau.b, dt=grid.dt)
    runs: list[Run | None] = [None] * len(items)
    for call in kernel_calls(groups_of([group_key(item) for item in items]), items):
        group = [items[i] for i in call.indices]
        check_rows(group[0].plant)
        records = empty_records(group, grid.t.size, grid.t.size if record_logs else 1)
        outcome = Outcome(
            status=np.zeros(len(group), dtype=np.int64), n_valid=np.zeros(len(group), dtype=np.int64),
            fail_index=np.zeros(len(group), dtype=np.int64),
        )  # fmt: skip
        plant, controller = plant_call(group), controller_call(group, call.step)
        arguments = (plant, controller, loop_elements(group), plant_forces(group))
        if device == "cuda":
            on_gpu(integration, *arguments, records, outcome)
        else:
            integrate_batch(integration, *arguments, records, outcome)
        for array in records:
            array.flags.writeable = False
        for j, i in enumerate(call.indices):
            runs[i] = _run(group[j], j, records, outcome, grid, record_logs)
    return [run for run in runs if run is not None]


def on_gpu(
    integration: Integration, plant: PlantCall, controller: ControllerCall, elements: LoopElements,
    forces: PlantForces, records: Records, outcome: Outcome,
) -> None:  # fmt: skip
    """A kernel call on the GPU (:func:`nlcx.kernel.cuda_loop.simulate`), or a one-line
    ConfigError naming what cannot run there."""
    from nlcx.kernel import cuda_loop, cuda_shape
    from nlcx.kernel.device import refused

    why = cuda_shape.unsupported(plant, controller, elements)
    if why is not None:
        raise refused(f"{why}; use device: cpu")
    cuda_loop.simulate(integration, plant, controller, elements, forces, records, outcome)


def plant_call(group: list[Item]) -> PlantCall:
    """The plant of a kernel call: the first item's equations, every item's arrays."""
    plant, plants = group[0].plant, [g.plant for g in group]
    return PlantCall(
        rhs=plant.rhs,
        x0=np.ascontiguousarray(np.stack([q.x0 for q in plants])),
        p=_stack([q.p for q in plants], plant.p.shape),
        C=np.ascontiguousarray(plant.C),
        bounds=_stack([q.bounds for q in plants], plant.bounds.shape),
    )


def controller_call(group: list[Item], step: ControllerStep) -> ControllerCall:
    """The controller of a kernel call: ``step``, the first item's callbacks, every item's arrays."""
    return ControllerCall(
        step=step,
        callbacks=callback_slots(group[0].controller.callbacks),
        cp=_pad_rows([g.controller.cp for g in group]),
        cs0=_pad_rows([g.controller.cs0 for g in group]),
        ref=_stack([g.ref for g in group], group[0].ref.shape),
    )


def loop_elements(group: list[Item]) -> LoopElements:
    """The loop elements of a group of items that share their element structure (hooks,
    functions and block sizes); rows are the items."""
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
    return LoopElements(
        functions=element_slots(functions),
        table=table,
        ep=_pad_rows([element_params(g) for g in group]),
        es0=_pad_rows([element_states(g) for g in group]),
        data=_stack([g.element_data for g in group], (1, d_off)),
    )


def element_params(item: Item) -> np.ndarray:
    """An item's loop elements' parameters, side by side (the row of ``LoopElements.ep``)."""
    return np.concatenate([np.zeros(0), *(e.params for e in item.elements)])


def element_states(item: Item) -> np.ndarray:
    """An item's loop elements' initial states, side by side (the row of ``LoopElements.es0``)."""
    return np.concatenate([np.zeros(0), *(e.state for e in item.elements)])


def plant_forces(group: list[Item]) -> PlantForces:
    """The disturbances and friction axes of a kernel call's items."""
    return PlantForces(
        dist=_stack([g.dist for g in group], group[0].dist.shape),
        dist_map=np.ascontiguousarray(group[0].dist_map),
        friction=_stack([g.friction for g in group], (len(group[0].plant.inputs), FRICTION_AXIS.size)),
    )


def empty_records(group: list[Item], n_k: int, n_rec: int, n_rows: int | None = None) -> Records:
    """The records of a group of items (``n_rows`` of them, by default one a member): states and
    inputs at the n_k samples, controller logs and friction forces at n_rec (1: not recorded).
    The kernel writes every sample up to where a run stops; the rest is never read."""
    plant, n_b = group[0].plant, len(group) if n_rows is None else n_rows
    n_u = len(plant.inputs)
    return Records(
        X=np.empty((n_b, n_k, len(plant.states))), U=np.empty((n_b, n_k, n_u)),
        LOG=np.empty((n_b, n_rec, len(group[0].controller.log_names))), FRICTION=np.empty((n_b, n_rec, n_u)),
    )  # fmt: skip


def _run(item: Item, j: int, records: Records, outcome: Outcome, grid: TimeGrid, record_logs: bool) -> Run:
    """The run of ``item``, row j of a kernel call's records, truncated where it stopped."""
    k = int(outcome.n_valid[j])
    status = int(outcome.status[j])
    t_fail = float(grid.t[k - 1] + grid.dt) if status else math.nan
    return Run(
        controller=item.controller,
        status="unstable" if status else "ok",
        reason=failure_reason(item.plant, status, int(outcome.fail_index[j]), t_fail),
        t=grid.t[:k],
        x=records.X[j, :k],
        u=records.U[j, :k],
        r=item.ref[:k],
        log=records.LOG[j, :k] if record_logs else None,
        friction=records.FRICTION[j, :k] if record_logs else None,
        t_fail=t_fail,
    )


def failure_reason(plant: Plant, status: int, index: int, t_fail: float, bounds: np.ndarray | None = None) -> str:
    """Why a run stopped (``status``: the kernel's, ``index``: its failing state or input), or ''
    (``bounds``: the run's divergence bounds, when not the plant's own)."""
    n = len(plant.states)
    if status == STATUS_BOUND:
        name = plant.state_names[index]
        bound = (plant.bounds if bounds is None else bounds)[index]
        return f"diverged at t = {t_fail:.4g} s: |{name}| > {bound:.6g} (simulation.bounds)"
    if status == STATUS_NONFINITE:
        what = plant.state_names[index] if index < n else plant.input_names[index - n]
        return f"diverged at t = {t_fail:.4g} s: {what} became non-finite"
    return ""


def _pad_rows(rows: list[np.ndarray]) -> np.ndarray:
    """Rows of different lengths as one array, zero-padded to the longest."""
    width = max(r.size for r in rows)
    out = np.zeros((len(rows), width))
    for i, r in enumerate(rows):
        out[i, : r.size] = r
    return out


def _stack(arrays: list[np.ndarray | None], empty_shape: tuple[int, ...]) -> np.ndarray:
    """Stack per-item arrays on a leading batch axis; one shared (or absent) array is broadcast."""
    first = arrays[0]
    if all(a is first for a in arrays):
        base = np.zeros(empty_shape) if first is None else first
        return np.ascontiguousarray(base[None]) if base.flags.writeable else base[None].copy()
    filled = [np.zeros(empty_shape) if a is None else a for a in arrays]
    # an axis of length 1 (e.g. no noise: one zero row for every sample) meets the others' length
    shape = tuple(max(sizes) for sizes in zip(*(a.shape for a in filled), strict=True))
    return np.ascontiguousarray(np.stack([np.broadcast_to(a, shape) for a in filled]))

"""Ensembles on the GPU: the variants of a columnar sweep simulated and measured there.

The host packs the variants' arrays exactly as :func:`nlcx.engine.ensembles.simulate_ensemble`
packs them for the CPU (the same kernel calls, rows and values), launches the closed loop
(:func:`nlcx.kernel.cuda_loop.launch`) with the signals the metrics need kept on the GPU, and
measures every run there (:mod:`nlcx.kernel.cuda_metrics`). Only each run's outcome and its
metric values come back; :func:`nlcx.engine.ensembles.measure_ensemble` lays them out as the
CPU's rows.

A batch larger than the GPU's memory holds is cut into chunks of rows (:func:`chunk_rows`).
One call at a time runs on the GPU: a second waits for the first, so that a sweep may lay out
and write one batch while the next one runs (:func:`nlcx.sweeps.runner.make_executor`).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from nlcx.engine.ensembles import (
    LoopRows,
    OkValues,
    Slot,
    Template,
    _call_arguments,
    _RunView,
    ensemble_calls,
    failure_rows,
    loop_rows,
    measure_ensemble,
    simulate_ensemble,
)
from nlcx.engine.measure import _input_step, _measured_outputs, _metric_plans, _selected_state, _time_origin
from nlcx.engine.prepared import TABLEAUS
from nlcx.kernel.device import refused
from nlcx.kernel.structures import Integration, method_of

#: Share of the GPU's free memory one chunk's records may take.
MEMORY_SHARE = 0.6

#: Held by the one :func:`simulate_measure` on the GPU at a time.
_ON_DEVICE = threading.Lock()


def _blocks(template: Template, i: int, recorded: list[tuple[int, int]]) -> list[tuple[str, Any]]:
    """(signal, metric block) of loop i (:class:`nlcx.kernel.cuda_metrics.Block`), in the order
    of :func:`nlcx.engine.measure_runs`: the outputs the loop follows, the others after a step on
    an input, the inputs; the signals they read are added to ``recorded``."""
    from nlcx.kernel.cuda_loop import INPUT, OUTPUT, STATE
    from nlcx.kernel.cuda_metrics import Block

    p = template.prepared
    plant, cfg, run = p.plant, p.experiment.section.metrics, _RunView(template.items[i].controller)
    plans = _metric_plans(p)
    lo, hi = cfg.rise_limits

    def signal(kind: int, index: int) -> int:
        if (kind, index) not in recorded:
            recorded.append((kind, index))
        return recorded.index((kind, index))

    def output(s: str) -> int:
        """The record of output s: its state where its row of C selects one, else y = C x."""
        j = plant.output_names.index(s)
        state = _selected_state(plant.C[j])
        return signal(STATE, state) if state is not None else signal(OUTPUT, j)

    followed = _measured_outputs(run, plant)
    blocks = []
    for s in followed:
        plan = plans[s]
        block = Block(plan.kind, output(s), -1, plan.t_step, plan.final, cfg.settling_band, window=cfg.ss_window)
        if plan.kind == "step":
            block = block._replace(rise_low=lo, rise_high=hi, origin=_time_origin(plan.t_step, cfg))
        elif plan.kind == "regulation":
            block = block._replace(abs_tol=cfg.regulation_abs_tol)
        blocks.append((s, block))
    step = _input_step(run, plant, plans)
    if step is not None:
        origin = _time_origin(step.t_step, cfg)
        blocks += [
            (s, Block("info", output(s), -1, step.t_step, band=cfg.settling_band, rise_low=lo, rise_high=hi,
                      origin=origin))
            for s in plant.output_names if s not in followed
        ]  # fmt: skip
    blocks += [(s, Block("input", signal(INPUT, j), -1)) for j, s in enumerate(plant.input_names)]
    return blocks


def _references(template: Template, i: int, blocks: list[tuple[str, Any]]) -> tuple[tuple[Any, ...], np.ndarray]:
    """The blocks with their reference rows, and the reference table (rows of K+1 samples)."""
    item = template.items[i]
    n_k = template.prepared.grid.t.size
    rows: list[np.ndarray] = []
    out: list[Any] = []
    for s, b in blocks:
        if b.kind in ("input", "info"):
            out.append(b)
            continue
        column = item.ref[:, item.controller.reference_signals.index(s)]
        rows.append(np.broadcast_to(column, (n_k,)))
        out.append(b._replace(ref_row=len(rows) - 1))
    table = np.ascontiguousarray(np.stack(rows)) if rows else np.zeros((1, n_k))
    return tuple(out), table


def chunk_rows(n_rows: int, bytes_per_row: int) -> int:
    """Rows a chunk takes: all, or what :data:`MEMORY_SHARE` of the GPU's free memory holds."""
    from nlcx.kernel.device import cuda, simulator_enabled

    if simulator_enabled():
        return n_rows
    free, _ = cuda().current_context().get_memory_info()
    return max(1, min(n_rows, int(free * MEMORY_SHARE) // max(bytes_per_row, 1)))


def _chunk(arguments: tuple[Any, ...], rows: slice) -> tuple[Any, ...]:
    """The kernel call's structures for the rows ``rows`` (arrays of one shared row stay whole)."""
    out = []
    for part in arguments:
        fields = {}
        for name, value in part._asdict().items():
            per_row = isinstance(value, np.ndarray) and value.ndim >= 1 and name not in ("C", "dist_map", "table")
            if per_row and value.shape[0] > 1:
                fields[name] = np.ascontiguousarray(value[rows])
        out.append(part._replace(**fields))
    return tuple(out)


def simulate_measure(
    template: Template, slots: Mapping[str, Sequence[Slot]], columns: Mapping[str, np.ndarray], n_variants: int
) -> tuple[list[LoopRows], OkValues]:
    """Simulate and measure ``n_variants`` variants of ``template`` on the GPU (the packing of
    :func:`~nlcx.engine.ensembles.simulate_ensemble`): each loop's outcome rows, and the
    function that gives :func:`~nlcx.engine.ensembles.measure_ensemble` the metric values of
    its runs that finished. Waits while another call runs on the GPU."""
    with _ON_DEVICE:
        return _simulate_measure(template, slots, columns, n_variants)


def _simulate_measure(
    template: Template, slots: Mapping[str, Sequence[Slot]], columns: Mapping[str, np.ndarray], n_variants: int
) -> tuple[list[LoopRows], OkValues]:
    """:func:`simulate_measure`, the GPU held."""
    from nlcx.kernel import cuda_loop, cuda_metrics
    from nlcx.kernel.device import cuda

    gpu = cuda()
    p = template.prepared
    sim, grid, items = p.experiment.section.simulation, p.grid, template.items
    tableau = TABLEAUS[sim.integrator]
    integration = Integration(method=method_of(sim.integrator), rk_a=tableau.a, rk_b=tableau.b, dt=grid.dt)
    t_dev = gpu.to_device(grid.t)
    names: dict[int, list[tuple[str, str]]] = {}
    values: dict[int, np.ndarray] = {}
    outcomes: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
    for pattern, step in ensemble_calls(items, n_variants):
        arguments = _call_arguments(template, pattern, step, n_variants, slots, columns)
        plant, controller, elements, _ = arguments
        why = cuda_loop.unsupported(plant, controller, elements)
        if why is not None:
            raise refused(f"{why}; use device: cpu")
        recorded: list[tuple[int, int]] = []
        labelled = {int(i): _blocks(template, int(i), recorded) for i in pattern}
        measuring = {}  # each loop's metric kernel, references on the GPU and number of values
        for i, blocks in labelled.items():
            refs, table = _references(template, i, blocks)
            width = sum(len(cuda_metrics.BLOCK_NAMES[b.kind]) for b in refs)
            measuring[i] = (cuda_metrics.metrics_kernel(refs, grid.t), gpu.to_device(table), width)
            names[i] = [(s, name) for s, b in blocks for name in cuda_metrics.BLOCK_NAMES[b.kind]]
        n_rows = n_variants * pattern.size
        n_u, n_log = len(p.plant.inputs), len(items[int(pattern[0])].controller.log_names)
        rec = np.array(recorded, dtype=np.int64).reshape(-1, 2)
        size = chunk_rows(n_rows, grid.t.size * max(rec.shape[0], 1) * 8)
        out: dict[int, list[np.ndarray]] = {int(i): [] for i in pattern}
        status, n_valid, fail_index = (np.empty(n_rows, dtype=np.int64) for _ in range(3))
        for start in range(0, n_rows, size):
            rows = slice(start, min(start + size, n_rows))
            plant_c, controller_c, elements_c, forces_c = _chunk(arguments, rows)
            done = cuda_loop.launch(
                integration, plant_c, controller_c, elements_c, forces_c, n_u, n_log, grid.t.size, rec, False
            )
            status[rows], n_valid[rows] = done.status.copy_to_host(), done.n_valid.copy_to_host()
            fail_index[rows] = done.fail_index.copy_to_host()
            for i, (kernel, refs, width) in measuring.items():
                OUT = gpu.device_array((rows.stop - rows.start, width))
                kernel[(OUT.shape[0] + 127) // 128, 128](t_dev, done.REC, refs, OUT)
                out[i].append(OUT.copy_to_host())
            del done
        loops = np.tile(pattern, n_variants)
        bounds = np.broadcast_to(plant.bounds, (n_rows, plant.bounds.shape[-1]))
        for i in labelled:
            mine = loops == i
            values[i] = np.concatenate(out[i])[mine]
            outcomes[i] = (status[mine], n_valid[mine], fail_index[mine], bounds[mine])
    rows_out = [failure_rows(template, *outcomes[i]) for i in range(len(items))]

    def ok_values(template: Template, i: int, loop: LoopRows, ok: np.ndarray) -> tuple[list[tuple[str, str]], Any]:
        return names[i], values[i][ok]

    return rows_out, ok_values


def ensemble_metrics(
    template: Template, slots: Mapping[str, Sequence[Slot]], columns: Mapping[str, np.ndarray], n_variants: int
) -> tuple[list[LoopRows], Any]:
    """Simulate and measure ``n_variants`` variants packed from ``columns`` (as
    :func:`~nlcx.engine.ensembles.simulate_ensemble`) where the template's experiment says
    (``simulation.device``: on the GPU, :func:`simulate_measure`; on the CPU, the ensemble's
    kernel calls): each loop's rows and the metric rows (:class:`~nlcx.engine.metric_rows.MetricColumns`)."""
    if template.prepared.experiment.section.simulation.device == "cuda":
        rows, ok_values = simulate_measure(template, slots, columns, n_variants)
        return rows, measure_ensemble(template, rows, n_variants, ok_values)
    rows = loop_rows(simulate_ensemble(template, slots, columns, n_variants), template)
    return rows, measure_ensemble(template, rows, n_variants)

"""Ensembles on the GPU: a columnar sweep's or a GA generation's variants simulated and measured there.

The host packs the variants' arrays exactly as :func:`nlcx.engine.ensembles.simulate_ensemble`
packs them for the CPU (the same kernel calls, rows and values), launches the closed loop
(:func:`nlcx.kernel.cuda_loop.launch`) with the signals the metrics need kept on the GPU, and
measures every run there (:mod:`nlcx.kernel.cuda_metrics`). Only each run's outcome and its
metric values come back; :func:`nlcx.engine.ensembles.measure_ensemble` lays them out as the
CPU's rows.

Several ensembles may go in one call (:func:`simulate_measure_all`, the identification's
generations of many hypotheses): their kernel calls that compile to the same closed-loop kernel
and share their one-row arrays run as the rows of one launch. A launch larger than the GPU's
memory holds is cut into chunks of rows (:func:`chunk_rows`). One call at a time runs on the
GPU: a second waits for the first, so that a sweep may lay out and write one batch while the
next one runs (:func:`nlcx.sweeps.runner.make_executor`).
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, TypeVar

import numpy as np

from nlcx.engine.ensembles import (
    CallArguments,
    LoopRows,
    OkValues,
    Slot,
    Template,
    call_arguments,
    ensemble_calls,
    failure_rows,
    loop_rows,
    measure_ensemble,
    simulate_ensemble,
)
from nlcx.engine.metric_rows import MetricColumns
from nlcx.engine.prepared import TABLEAUS
from nlcx.kernel.device import refused
from nlcx.kernel.signatures import DeviceArray
from nlcx.kernel.structures import Integration, method_of

if TYPE_CHECKING:
    from nlcx.kernel.cuda_metrics import MeasuredRecord

#: One of a kernel call's structures (:data:`~nlcx.engine.ensembles.CallArguments`).
Structure = TypeVar("Structure", bound=NamedTuple)

#: Share of the GPU's free memory one chunk's records may take.
MEMORY_SHARE = 0.6

#: Held by the one :func:`simulate_measure` on the GPU at a time.
_ON_DEVICE = threading.Lock()


def _measured(
    template: Template, i: int, recorded: list[tuple[int, int]]
) -> tuple[tuple[MeasuredRecord, ...], np.ndarray]:
    """The measured signals of loop i as the GPU's metric kernel reads them
    (:class:`nlcx.kernel.cuda_metrics.MeasuredRecord`, in the order of the loop's
    :class:`~nlcx.engine.plan.LoopPlan`), and their reference table (rows of K+1 samples); the
    signals they read are added to ``recorded``."""
    from nlcx.kernel.cuda_loop import INPUT, OUTPUT, STATE
    from nlcx.kernel.cuda_metrics import MeasuredRecord

    item, n_k = template.items[i], template.plan.t.size
    kinds = {"state": STATE, "output": OUTPUT, "input": INPUT}
    rows: list[np.ndarray] = []
    out = []
    for signal in template.plan.loops[i].signals:
        where, index = signal.source
        if (kinds[where], index) not in recorded:
            recorded.append((kinds[where], index))
        ref_row = -1
        if signal.reference >= 0:
            rows.append(np.broadcast_to(item.ref[:, signal.reference], (n_k,)))
            ref_row = len(rows) - 1
        out.append(MeasuredRecord(signal.kind, recorded.index((kinds[where], index)), ref_row, signal.final,
                                  signal.timing, len(signal.metrics)))  # fmt: skip
    table = np.ascontiguousarray(np.stack(rows)) if rows else np.zeros((1, n_k))
    return tuple(out), table


def chunk_rows(n_rows: int, bytes_per_row: int) -> int:
    """Rows a chunk takes: all, or what :data:`MEMORY_SHARE` of the GPU's free memory holds."""
    from nlcx.kernel.device import cuda, simulator_enabled

    if simulator_enabled():
        return n_rows
    free, _ = cuda().current_context().get_memory_info()
    return max(1, min(n_rows, int(free * MEMORY_SHARE) // max(bytes_per_row, 1)))


def _chunk(arguments: CallArguments, rows: slice) -> CallArguments:
    """The kernel call's structures for the rows ``rows`` (arrays of one shared row stay whole)."""
    plant, controller, elements, forces = arguments
    return _rows(plant, rows), _rows(controller, rows), _rows(elements, rows), _rows(forces, rows)


def _rows(part: Structure, rows: slice) -> Structure:
    """One of :func:`_chunk`'s structures."""
    fields = {}
    for name, value in part._asdict().items():
        per_row = isinstance(value, np.ndarray) and value.ndim >= 1 and name not in _WHOLE
        if per_row and value.shape[0] > 1:
            fields[name] = np.ascontiguousarray(value[rows])
    return part._replace(**fields)


class Ensemble(NamedTuple):
    """``n_variants`` variants of a template, packed from ``columns`` into the places ``slots``
    name (as :func:`~nlcx.engine.ensembles.simulate_ensemble` packs them)."""

    template: Template
    slots: Mapping[str, Sequence[Slot]]
    columns: Mapping[str, np.ndarray]
    n_variants: int


@dataclass
class _Call:
    """One kernel call of an ensemble on the GPU: its structures, the signals its metrics read,
    each loop's metric blocks and reference table, and (once run) its rows' outcomes and each
    loop's metric rows over the call's rows (pieces in row order)."""

    pattern: np.ndarray
    arguments: CallArguments
    integration: Integration
    t: np.ndarray
    recorded: np.ndarray
    measuring: dict[int, tuple[tuple[MeasuredRecord, ...], np.ndarray]]
    n_rows: int
    n_u: int
    n_log: int
    #: What each loop of the call is measured with (its blocks and reference table's digest).
    signature: tuple[tuple[tuple[MeasuredRecord, ...], str], ...] = ()
    outcome: tuple[np.ndarray, ...] = ()
    pieces: dict[int, list[np.ndarray]] = field(default_factory=dict)


def simulate_measure(
    template: Template, slots: Mapping[str, Sequence[Slot]], columns: Mapping[str, np.ndarray], n_variants: int
) -> tuple[list[LoopRows], OkValues]:
    """Simulate and measure ``n_variants`` variants of ``template`` on the GPU (the packing of
    :func:`~nlcx.engine.ensembles.simulate_ensemble`): each loop's outcome rows, and the
    function that gives :func:`~nlcx.engine.ensembles.measure_ensemble` the metric values of
    its runs that finished. Waits while another call runs on the GPU."""
    return simulate_measure_all([Ensemble(template, slots, columns, n_variants)])[0]


def simulate_measure_all(ensembles: Sequence[Ensemble]) -> list[tuple[list[LoopRows], OkValues]]:
    """:func:`simulate_measure` of each ensemble, their kernel calls launched together: the calls
    of every ensemble that compile to the same closed-loop kernel (:class:`LoopShape`) on the same
    time grid and integration, with the same shared arrays, run as the rows of one launch, and
    the runs that read the same metric blocks and references are measured by one launch. Each
    row is its own thread, so a run's numbers do not depend on the launch it is in."""
    with _ON_DEVICE:
        return _simulate_measure_all(ensembles)


def _simulate_measure_all(ensembles: Sequence[Ensemble]) -> list[tuple[list[LoopRows], OkValues]]:
    """:func:`simulate_measure_all`, the GPU held."""
    calls = [_calls(e) for e in ensembles]
    groups: dict[tuple[Hashable, ...], list[_Call]] = {}
    for call in (c for mine in calls for c in mine):
        groups.setdefault(_launch_key(call), []).append(call)
    for group in groups.values():
        _run_group(sorted(group, key=lambda call: repr(call.signature)))  # alike measured together
    return [_assembled(e, mine) for e, mine in zip(ensembles, calls, strict=True)]


def _calls(ensemble: Ensemble) -> list[_Call]:
    """The GPU calls of an ensemble (one per call of :func:`ensemble_calls`), not yet run; a
    plugin that cannot run on the GPU is refused in one line."""
    from nlcx.kernel import cuda_shape

    template, slots, columns, n_variants = ensemble
    p = template.prepared
    sim, grid, items = p.experiment.section.simulation, p.grid, template.items
    tableau = TABLEAUS[sim.integrator]
    integration = Integration(method=method_of(sim.integrator), rk_a=tableau.a, rk_b=tableau.b, dt=grid.dt)
    out = []
    for pattern, step in ensemble_calls(items, n_variants):
        arguments = call_arguments(template, pattern, step, n_variants, slots, columns)
        why = cuda_shape.unsupported(*arguments[:3])
        if why is not None:
            raise refused(f"{why}; use device: cpu")
        recorded: list[tuple[int, int]] = []
        measuring = {int(i): _measured(template, int(i), recorded) for i in pattern}
        rec = np.array(recorded, dtype=np.int64).reshape(-1, 2)
        n_log = len(items[int(pattern[0])].controller.log_names)
        signature = tuple((measuring[int(i)][0], _digest(measuring[int(i)][1])) for i in pattern)
        out.append(_Call(pattern, arguments, integration, grid.t, rec, measuring,
                         n_variants * pattern.size, len(p.plant.inputs), n_log, signature))  # fmt: skip
    return out


#: Fields of the kernel's structures that are not per row (an array of one row is shared).
_WHOLE = ("C", "dist_map", "table")


def _launch_key(call: _Call) -> tuple[Hashable, ...]:
    """What the calls of one launch share: the loop kernel, the time grid and integration, the
    signals recorded, and each shared array (by content); per-row arrays by their row shape."""
    from nlcx.kernel import cuda_shape

    shape = cuda_shape.shape_of(*call.arguments, call.n_u, call.n_log, call.integration)
    fields: list[tuple[Hashable, ...]] = []
    for part in call.arguments:
        for name, value in part._asdict().items():
            if _per_row(name, value, call.n_rows):
                fields.append((name, "rows", value.shape[1:], value.dtype.str))
            elif isinstance(value, np.ndarray):
                fields.append((name, "shared", value.shape, value.dtype.str, _digest(value)))
    i = call.integration
    return (shape, i.dt, _digest(i.rk_a), _digest(i.rk_b), _digest(call.t), call.recorded.tobytes(), tuple(fields))


def _per_row(name: str, value: object, n_rows: int) -> bool:
    """Whether a field of a call's structures holds a row per row of the call (else it is shared)."""
    if not isinstance(value, np.ndarray) or value.ndim == 0 or name in _WHOLE:
        return False
    return value.shape[0] > 1 or n_rows == 1


def _digest(array: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()


def _joined(group: list[_Call]) -> CallArguments:
    """The structures of one launch: the calls' per-row arrays one after the other, the shared
    ones as they are (the same in every call of a launch, :func:`_launch_key`)."""
    if len(group) == 1:
        return group[0].arguments
    n_rows = group[0].n_rows
    return (
        _joined_part([c.arguments[0] for c in group], n_rows),
        _joined_part([c.arguments[1] for c in group], n_rows),
        _joined_part([c.arguments[2] for c in group], n_rows),
        _joined_part([c.arguments[3] for c in group], n_rows),
    )


def _joined_part(parts: list[Structure], n_rows: int) -> Structure:
    """One of :func:`_joined`'s structures, from the calls' (``n_rows``: the first call's rows)."""
    fields = {}
    for name, value in parts[0]._asdict().items():
        if _per_row(name, value, n_rows):
            fields[name] = np.concatenate([part._asdict()[name] for part in parts])
    return parts[0]._replace(**fields)


class _MetricRun(NamedTuple):
    """One metric launch of a loop launch: the measured records and reference table it measures with, over
    the launch's rows [start, stop), which are the rows of ``members`` (call, loop, first row)."""

    records: tuple[MeasuredRecord, ...]
    table: np.ndarray
    digest: str  # the table's
    start: int
    stop: int
    members: list[tuple[_Call, int, int]]


def _metric_runs(group: list[_Call], offsets: np.ndarray) -> list[_MetricRun]:
    """The metric launches of a loop launch: for each loop of a call, one over the call's rows
    (the other loops' rows measured and dropped, as each loop reads only its own), merged with
    the next calls' while they measure with the same blocks and references (their
    ``signature``)."""
    runs: list[_MetricRun] = []
    signature_before = None
    for call, first in zip(group, offsets, strict=False):
        stop, n = int(first) + call.n_rows, len(call.pattern)
        if call.signature == signature_before:
            runs[-n:] = [run._replace(stop=stop, members=[*run.members, (call, int(i), int(first))])
                         for run, i in zip(runs[-n:], call.pattern, strict=True)]  # fmt: skip
        else:
            runs += [_MetricRun(*call.measuring[int(i)], digest, int(first), stop, [(call, int(i), int(first))])
                     for i, (_, digest) in zip(call.pattern, call.signature, strict=True)]  # fmt: skip
        signature_before = call.signature
    return runs


def _run_group(group: list[_Call]) -> None:
    """Launch the calls of ``group`` (one :func:`_launch_key`) as one loop launch, in chunks of
    rows that fit the GPU's memory (:func:`chunk_rows`), measure them there, and hand each call
    its outcomes and metric rows."""
    from nlcx.kernel import cuda_loop, cuda_metrics
    from nlcx.kernel.device import cuda

    gpu = cuda()
    one = group[0]
    arguments = _joined(group)
    offsets = np.cumsum([0] + [c.n_rows for c in group])
    n_rows = int(offsets[-1])
    t_dev = gpu.to_device(one.t)
    tables: dict[str, DeviceArray] = {}
    measuring = []
    for run in _metric_runs(group, offsets):
        if run.digest not in tables:
            tables[run.digest] = gpu.to_device(run.table)
        width = sum(record.width for record in run.records)
        measuring.append((run, cuda_metrics.metrics_kernel(run.records, one.t), tables[run.digest], width))
    for call in group:
        call.pieces = {int(i): [] for i in call.pattern}
    outcome = tuple(np.empty(n_rows, dtype=np.int64) for _ in range(3))
    size = chunk_rows(n_rows, one.t.size * max(one.recorded.shape[0], 1) * 8)
    for start in range(0, n_rows, size):
        stop = min(start + size, n_rows)
        plant, controller, elements, forces = _chunk(arguments, slice(start, stop))
        done = cuda_loop.launch(one.integration, plant, controller, elements, forces, one.n_u, one.n_log,
                                one.t.size, one.recorded, False)  # fmt: skip
        for array, on_gpu in zip(outcome, (done.status, done.n_valid, done.fail_index), strict=True):
            array[start:stop] = on_gpu.copy_to_host()
        for run, kernel, table, width in measuring:
            lo, hi = max(run.start, start), min(run.stop, stop)
            if lo >= hi:
                continue
            OUT = gpu.device_array((hi - lo, width))
            kernel[(hi - lo + cuda_loop.THREADS - 1) // cuda_loop.THREADS, cuda_loop.THREADS](
                t_dev, done.REC, table, OUT, lo - start
            )
            values = OUT.copy_to_host()
            for call, loop, first in run.members:
                a, b = max(first, lo), min(first + call.n_rows, hi)
                if a < b:
                    call.pieces[loop].append(values[a - lo : b - lo])
        del done
    for call, first in zip(group, offsets, strict=False):
        call.outcome = tuple(array[first : first + call.n_rows] for array in outcome)


def _assembled(ensemble: Ensemble, calls: list[_Call]) -> tuple[list[LoopRows], OkValues]:
    """An ensemble's loop rows and metric values from its calls, once run."""
    template, n_variants = ensemble.template, ensemble.n_variants
    values: dict[int, np.ndarray] = {}
    rows: dict[int, LoopRows] = {}
    for call in calls:
        loops = np.tile(call.pattern, n_variants)
        bounds = call.arguments[0].bounds
        bounds = np.broadcast_to(bounds, (call.n_rows, bounds.shape[-1]))
        for i in map(int, call.pattern):
            mine = loops == i
            values[i] = np.concatenate(call.pieces[i])[mine]
            status, n_valid, fail_index = (array[mine] for array in call.outcome)
            rows[i] = failure_rows(template, status, n_valid, fail_index, bounds[mine])

    def ok_values(template: Template, i: int, loop: LoopRows, ok: np.ndarray) -> np.ndarray:
        return values[i][ok]

    return [rows[i] for i in range(len(template.items))], ok_values


def ensemble_metrics(
    template: Template, slots: Mapping[str, Sequence[Slot]], columns: Mapping[str, np.ndarray], n_variants: int
) -> tuple[list[LoopRows], MetricColumns]:
    """Simulate and measure ``n_variants`` variants packed from ``columns`` (as
    :func:`~nlcx.engine.ensembles.simulate_ensemble`) where the template's experiment says
    (``simulation.device``: on the GPU, :func:`simulate_measure`; on the CPU, the ensemble's
    kernel calls): each loop's rows and the metric rows (:class:`~nlcx.engine.metric_rows.MetricColumns`)."""
    if template.prepared.experiment.section.simulation.device == "cuda":
        rows, ok_values = simulate_measure(template, slots, columns, n_variants)
        return rows, measure_ensemble(template, rows, n_variants, ok_values)
    rows = loop_rows(simulate_ensemble(template, slots, columns, n_variants), template)
    return rows, measure_ensemble(template, rows, n_variants)


def ensembles_metrics(ensembles: Sequence[Ensemble]) -> list[MetricColumns]:
    """The metric rows of each ensemble (:func:`ensemble_metrics`), those on the GPU simulated
    and measured together (:func:`simulate_measure_all`), the others one by one on the CPU."""
    on_gpu = [k for k, e in enumerate(ensembles) if e.template.prepared.experiment.section.simulation.device == "cuda"]
    out: dict[int, MetricColumns] = {}
    for k, (rows, ok_values) in zip(on_gpu, simulate_measure_all([ensembles[k] for k in on_gpu]), strict=True):
        out[k] = measure_ensemble(ensembles[k].template, rows, ensembles[k].n_variants, ok_values)
    for k, e in enumerate(ensembles):
        if k not in out:
            out[k] = ensemble_metrics(*e)[1]
    return [out[k] for k in range(len(ensembles))]

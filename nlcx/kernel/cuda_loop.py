"""The closed loop on the GPU: one thread a variant, the plugins' own source compiled for it.

:func:`simulate` takes the structures the CPU kernel takes (:mod:`nlcx.kernel.structures`)
and integrates every row of the batch on the GPU, one CUDA thread per row, in the order of
:func:`nlcx.kernel.integrator.simulate`: at t_k = k dt

    y_k = C x_k -> SENSOR elements -> controller -> u_k -> ACTUATOR elements,

u_k held while the method of ``integration`` (the classic RK4 written out, or any explicit
tableau) integrates to t_{k+1}, disturbances at the stage times; a row whose input or state is
not finite, or whose state is past its bound, stops with the same status, failing index and
number of valid samples as on the CPU. The plant's right-hand side, the controller's step, its
gain schedules and the loop elements are the plugins' numba functions compiled as device
functions (:class:`nlcx.kernel.device.Retarget`), called with the thread's row or column of
the ABI's arrays (:mod:`nlcx.kernel.abi`: a plant sees a batch of one column, a controller
and an element a batch of one row).

What the kernel keeps of a run is chosen by ``recorded``: per sample and row, a list of
signals (a state, an output y_i = C_i x, an input), stored time-major (K+1, signals, B) so
that the threads of a warp write neighbouring addresses. :func:`simulate` records every state
and input and copies them back as the CPU kernel's :class:`~nlcx.kernel.structures.Records`;
:mod:`nlcx.engine.gpu` keeps outputs and inputs on the GPU and measures them there.

A variant with friction is stepped by the CPU's friction path (Appendix A), compiled for its
thread (:mod:`nlcx.kernel.cuda_friction`); a kernel whose variants have none is compiled without it.

Not on the GPU: plugins that are not numba functions, which
:func:`nlcx.kernel.cuda_shape.unsupported` names before any work; and any plugin whose source
numba-cuda cannot compile, which :func:`launch` names with numba's reason when the kernel
compiles, before any thread runs.
"""

from __future__ import annotations

import functools
import math
import re
from typing import Any, NamedTuple

import numpy as np

from nlcx.kernel.abi import (
    STATUS_BOUND,
    STATUS_NONFINITE,
    STATUS_OK,
)
from nlcx.kernel.cuda_friction import AT_SAMPLE, OVER_STEP, FrictionDevices
from nlcx.kernel.cuda_shape import LoopDevices, LoopShape, loop_devices, shape_of
from nlcx.kernel.device import Retarget, cuda, kept, refused
from nlcx.kernel.signatures import (
    DeviceArray,
    DeviceFunction,
    FloatArray,
    IntArray,
)
from nlcx.kernel.stepping import (
    CLASSIC,
    SEQUENTIAL,
    first_failing_state,
    hold_input,
    output_picks,
    rk_step,
    sample_signals,
    stage_nodes,
)
from nlcx.kernel.structures import (
    CLASSIC_RK4,
    ControllerCall,
    Integration,
    LoopElements,
    Outcome,
    PlantCall,
    PlantForces,
    Records,
)

#: What a recorded signal is (column 0 of ``recorded``): a state, an output (row of C), an input,
#: the friction force on an input's axis.
STATE, OUTPUT, INPUT, FRICTION = 0, 1, 2, 3
#: Threads per block of the closed-loop and metric kernels.
THREADS = 128


# ----------------------------------------------------------------------------- the kernel

_KERNELS: dict[LoopShape, DeviceFunction] = {}


def loop_kernel(shape: LoopShape) -> DeviceFunction:
    """The closed-loop kernel of ``shape``, compiled on its first launch (one per shape and process)."""
    if shape not in _KERNELS:
        _KERNELS[shape] = kept(_build(shape, *loop_devices(shape)), loop_kernel, shape)
    return _KERNELS[shape]


#: numba's CUDA module as a global of this module: the kernel reads ``cuda_module.grid`` and
#: ``cuda_module.local`` through it, where numba's simulator finds and replaces it.
cuda_module: Any = None


@functools.cache
def _steps() -> tuple[DeviceFunction, DeviceFunction, DeviceFunction, DeviceFunction]:
    """(sample_signals, hold_input, rk_step, first_failing_state) of :mod:`nlcx.kernel.stepping`
    compiled for the GPU, called by a thread with a batch of one."""
    retarget = Retarget()
    sample, hold, advance, failing = (
        retarget.device(f) for f in (sample_signals, hold_input, rk_step, first_failing_state)
    )
    return sample, hold, advance, failing


def _build(
    shape: LoopShape,
    rhs: DeviceFunction,
    step: DeviceFunction,
    sensor: DeviceFunction,
    actuator: DeviceFunction,
    friction: FrictionDevices,
) -> DeviceFunction:
    """The kernel of ``shape``: the thread's closed loop from t_0 to t_K (the module docstring),
    with the plugins' device functions, the friction path and the stage combination of its method.
    Its arguments are the arrays of a kernel call's structures (:func:`launch` passes them by name)."""
    global cuda_module
    cuda_module = cuda()
    combination = CLASSIC if shape.method == CLASSIC_RK4 else SEQUENTIAL
    return _thread_loop(shape, (rhs, step, sensor, actuator, friction), combination)


def _thread_loop(shape: LoopShape, devices: LoopDevices, combination: int) -> DeviceFunction:
    """The kernel of :func:`_build`; the thread's own state, signals and rows live in its local memory."""
    from numba import float64, int64

    N, NU, NY, NR, NLOG, NST, NCP, NCS = _local_sizes(shape)
    record, (sample, hold, advance, failing), load = _recorder(), _steps(), _thread_rows(N, NU)
    rhs, step, sensor, actuator, (has_friction, start_friction, friction_at) = devices

    @cuda_module.jit
    def kernel(x0: FloatArray, params: FloatArray, C: FloatArray, picked: IntArray, bounds: FloatArray, cp: FloatArray,
               cs: FloatArray, ref: FloatArray, ep: FloatArray, es: FloatArray, data: FloatArray, dist: FloatArray,
               dist_map: IntArray, friction: FloatArray, rk_a: FloatArray, rk_b: FloatArray, rk_c: FloatArray,
               dt: float, n_steps: int, n_u: int, recorded: IntArray, record_friction: bool, REC: FloatArray,
               LOGS: FloatArray, status: IntArray, n_valid: IntArray,
               fail_index: IntArray) -> None:  # pragma: no cover  # fmt: skip
        v = cuda_module.grid(1)
        if v >= x0.shape[0]:
            return
        local = cuda_module.local.array
        x, xs, xn = local((N, 1), float64), local((N, 1), float64), local((N, 1), float64)
        ks, xrow, y = local((NST, N, 1), float64), local((1, N), float64), local((1, NY), float64)
        r, u = local((1, NR), float64), local((1, NU), float64)
        uc, logged, vid = local((NU, 1), float64), local((1, NLOG), float64), local(1, int64)
        cp_row, cs_row, bound = local((1, NCP), float64), local((1, NCS), float64), local((N, 1), float64)
        mode, direction, held, f_k = local(NU, int64), local(NU, float64), local(NU, float64), local((1, NU), float64)
        load(v, x0, cp, cs, bounds, x, cp_row, cs_row, bound, f_k, vid)  # the thread's rows, in its own memory
        pv = v if params.shape[1] > 1 else 0
        pc = params[:, pv : pv + 1]
        bd = v if dist.shape[0] > 1 else 0
        cpv, csv, logv = cp_row[:, : cp.shape[1]], cs_row[:, : cs.shape[1]], logged[:, : LOGS.shape[1]]
        yv, rv, uv, ucv = y[:, : C.shape[0]], r[:, : ref.shape[2]], u[:, :n_u], uc[:n_u, :]
        axes = friction[v if friction.shape[0] > 1 else 0]
        frictional, integration = has_friction(axes), Integration(0, rk_a, rk_b, dt)
        if frictional:
            start_friction(axes, x[:, 0], mode, direction, held)
        status[v], fail_index[v], n_valid[v] = STATUS_OK, -1, n_steps + 1
        for k in range(n_steps + 1):
            t, kd = k * dt, (k if dist.shape[1] > 1 else 0)
            sample(1, vid, x, xrow, C, picked, yv, ref, k if ref.shape[1] > 1 else 0, rv, uv)
            sensor(t, dt, k, yv, vid, ep, es, data)
            step(t, dt, xrow, yv, rv, cpv, csv, uv, logv, 0)
            actuator(t, dt, k, uv, vid, ep, es, data)
            bad_u = hold(0, uv, ucv)
            if frictional and bad_u < 0:  # the breakaway at t_k (Appendix A), and its forces when recorded
                friction_at(AT_SAMPLE, t, k, kd, x, uv, pc, dist, bd, dist_map, integration, rk_c, axes, mode,
                            direction, held, xn, f_k, record_friction)  # fmt: skip
            record(recorded, REC, k, v, x, y, u, C, f_k)
            if LOGS.shape[0] > 1:
                for i in range(LOGS.shape[1]):
                    LOGS[k, i, v] = logv[0, i]
            if bad_u >= 0:
                status[v], fail_index[v], n_valid[v] = STATUS_NONFINITE, N + bad_u, k + 1
                return
            if k == n_steps:
                return
            if frictional:
                friction_at(OVER_STEP, t, k, kd, x, uv, pc, dist, bd, dist_map, integration, rk_c, axes, mode,
                            direction, held, xn, f_k, False)  # fmt: skip
            else:
                advance(rhs, t, dt, 1, x, xn, ucv, pc, ks, xs, rk_a, rk_b, rk_c, combination, dist, vid, kd, dist_map,
                        None)  # fmt: skip
            for i in range(N):
                x[i, 0] = xn[i, 0]
            bad = failing(x, 0, bound)
            if bad >= 0:
                status[v] = STATUS_NONFINITE if not math.isfinite(x[bad, 0]) else STATUS_BOUND
                fail_index[v], n_valid[v] = bad, k + 1
                return

    return kernel


def _local_sizes(shape: LoopShape) -> tuple[int, int, int, int, int, int, int, int]:
    """The sizes of a thread's local arrays: states, inputs, outputs, references, logged values,
    stages, controller parameters and controller states (each but the states at least 1)."""
    return (
        shape.n_x, max(shape.n_u, 1), max(shape.n_y, 1), max(shape.n_r, 1),
        max(shape.n_log, 1), max(shape.n_stages, 1), max(shape.n_cp, 1), max(shape.n_cs, 1),
    )  # fmt: skip


@functools.cache
def _thread_rows(n_x: int, n_u: int) -> DeviceFunction:
    """The device function that copies thread v's rows into its local memory: the controller's
    parameters and state, the initial state and the state's bounds; no friction force yet."""

    @cuda().jit(device=True)
    def load(
        v: int,
        x0: FloatArray,
        cp: FloatArray,
        cs: FloatArray,
        bounds: FloatArray,
        x: FloatArray,
        cp_row: FloatArray,
        cs_row: FloatArray,
        bound: FloatArray,
        f_k: FloatArray,
        vid: IntArray,
    ) -> None:  # pragma: no cover - device
        for i in range(cp.shape[1]):
            cp_row[0, i] = cp[v, i]
        for i in range(cs.shape[1]):
            cs_row[0, i] = cs[v, i]
        for i in range(n_x):
            x[i, 0] = x0[v, i]
        for j in range(n_u):
            f_k[0, j] = 0.0
        vid[0] = v
        bb = v if bounds.shape[0] > 1 else 0
        for i in range(n_x):
            bound[i, 0] = bounds[bb, i]

    return load


@functools.cache
def _recorder() -> DeviceFunction:
    """The device function that stores a thread's recorded signals of sample k."""

    @cuda().jit(device=True)
    def record(
        recorded: IntArray,
        REC: FloatArray,
        k: int,
        v: int,
        x: FloatArray,
        y: FloatArray,
        u: FloatArray,
        C: FloatArray,
        f_k: FloatArray,
    ) -> None:  # pragma: no cover - device
        for q in range(recorded.shape[0]):
            kind, i = recorded[q, 0], recorded[q, 1]
            if kind == STATE:
                REC[k, q, v] = x[i, 0]
            elif kind == INPUT:
                REC[k, q, v] = u[0, i]
            elif kind == FRICTION:
                REC[k, q, v] = f_k[0, i]
            else:
                acc = 0.0
                for j in range(C.shape[1]):
                    acc += C[i, j] * x[j, 0]
                REC[k, q, v] = acc

    return record


# ----------------------------------------------------------------------------- launching


class Launch(NamedTuple):
    """What a launch leaves on the GPU: the recorded signals (K+1, signals, B), the controller
    logs (K+1|1, n_log, B) and each row's outcome (status, n_valid, fail_index)."""

    REC: DeviceArray
    LOG: DeviceArray
    status: DeviceArray
    n_valid: DeviceArray
    fail_index: DeviceArray


def launch(
    integration: Integration, plant: PlantCall, controller: ControllerCall, elements: LoopElements,
    forces: PlantForces, n_u: int, n_log: int, n_samples: int, recorded: np.ndarray, record_logs: bool,
) -> Launch:  # fmt: skip
    """Run the kernel call's rows on the GPU, recording the signals ``recorded`` ((kind, index)
    rows: :data:`STATE`, :data:`OUTPUT`, :data:`INPUT`) at each of the ``n_samples`` samples; the
    results stay on the GPU."""
    gpu = cuda()
    shape = shape_of(plant, controller, elements, forces, n_u, n_log, integration)
    kernel = loop_kernel(shape)
    n_rows = plant.x0.shape[0]
    dev = gpu.to_device
    REC = gpu.device_array((n_samples, recorded.shape[0], n_rows))
    LOG = gpu.device_array((n_samples if record_logs else 1, max(n_log, 0), n_rows if record_logs else 1))
    out = Launch(REC, LOG, *(gpu.device_array(n_rows, dtype=np.int64) for _ in range(3)))
    rk_a = np.ascontiguousarray(integration.rk_a)
    args = (
        dev(plant.x0), dev(np.ascontiguousarray(plant.p.T)), dev(plant.C), dev(output_picks(plant.C)),
        dev(plant.bounds), dev(controller.cp), dev(np.array(controller.cs0, copy=True)), dev(controller.ref),
        dev(elements.ep), dev(np.array(elements.es0, copy=True)), dev(elements.data), dev(forces.dist),
        dev(forces.dist_map), dev(forces.friction), dev(rk_a), dev(np.ascontiguousarray(integration.rk_b)),
        dev(stage_nodes(rk_a)),
        float(integration.dt), n_samples - 1, n_u, dev(recorded), bool((recorded[:, 0] == FRICTION).any()),
        REC, LOG, out.status, out.n_valid, out.fail_index,
    )  # fmt: skip
    blocks = (n_rows + THREADS - 1) // THREADS
    try:  # compiled at its first launch, before any thread runs
        kernel[blocks, THREADS](*args)
    except Exception as exc:
        from numba.core.errors import NumbaError

        if not isinstance(exc, NumbaError):
            raise
        raise refused(f"{_names(shape)} do not compile for the GPU ({_first_line(exc)}); use device: cpu") from None
    return out


def _names(shape: LoopShape) -> str:
    """The plugins of a closed loop, by name: what a compilation error on the GPU concerns."""
    names = [getattr(shape.rhs, "__name__", "the plant"), getattr(shape.step, "__name__", "the controller")]
    names += [getattr(fn, "__name__", "an element") for _, fn, *_ in shape.elements]
    return "the plant, controller and elements " + ", ".join(repr(n) for n in names)


def _first_line(exc: BaseException) -> str:
    """The first line of numba's message, without its terminal colours."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[0][:200] if lines else type(exc).__name__


def simulate(
    integration: Integration,
    plant: PlantCall,
    controller: ControllerCall,
    elements: LoopElements,
    forces: PlantForces,
    records: Records,
    outcome: Outcome,
) -> None:
    """:func:`nlcx.kernel.integrator.simulate` on the GPU: the same structures in, ``records``
    (every state and input; the logs and friction forces where recorded) and ``outcome`` written."""
    _, n_k, n = records.X.shape
    n_u, n_log = records.U.shape[2], records.LOG.shape[2]
    logs = records.LOG.shape[1] > 1
    rows = [[STATE, i] for i in range(n)] + [[INPUT, j] for j in range(n_u)]
    rows += [[FRICTION, j] for j in range(n_u)] if records.FRICTION.shape[1] > 1 else []
    done = launch(integration, plant, controller, elements, forces, n_u, n_log, n_k, np.array(rows, np.int64), logs)
    rec = done.REC.copy_to_host()
    records.X[...] = rec[:, :n, :].transpose(2, 0, 1)
    records.U[...] = rec[:, n : n + n_u, :].transpose(2, 0, 1)
    if records.FRICTION.shape[1] > 1:
        records.FRICTION[...] = rec[:, n + n_u :, :].transpose(2, 0, 1)
    if logs:
        records.LOG[...] = done.LOG.copy_to_host().transpose(2, 0, 1)
    outcome.status[...] = done.status.copy_to_host()
    outcome.n_valid[...] = done.n_valid.copy_to_host()
    outcome.fail_index[...] = done.fail_index.copy_to_host()

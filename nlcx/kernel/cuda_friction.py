"""Stick-slip friction (Appendix A) on the GPU: the CPU's friction path, for one thread's variant.

A variant with friction is stepped on the CPU by :func:`nlcx.kernel.friction_path.step_with_friction`,
its breakaway checked at each sample by :func:`nlcx.kernel.friction.update_friction_modes`. On
the GPU the thread of such a variant calls the same functions, compiled from their source as
device functions (:class:`nlcx.kernel.device.Retarget`) with the plant's right-hand side handed
over as on the CPU: the step split where a sliding axis stops, the holding force of a stuck
axis solved from the plant's own accelerations, the breakaway in the direction of the net
force. The work space the CPU allocates once per kernel call
(:class:`~nlcx.kernel.structures.FrictionWork`) lives in the thread's own memory, and the
axes' modes, slip directions and held positions in the kernel's (:func:`friction_devices`).

A kernel whose variants have no friction is compiled without this path: its three device
functions are then ones that do nothing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

from nlcx.kernel.device import Retarget, cuda
from nlcx.kernel.friction import friction_forces, has_friction, initial_modes, update_friction_modes
from nlcx.kernel.friction_path import sample_stage, step_with_friction
from nlcx.kernel.signatures import DeviceFunction, FloatArray, IntArray
from nlcx.kernel.structures import FrictionScratch, FrictionWork, OneColumn

if TYPE_CHECKING:
    from nlcx.kernel.structures import Integration

#: What :attr:`FrictionDevices.act` does: the breakaway at t_k (and the friction force there,
#: when recorded), or the sampling step from t_k.
AT_SAMPLE, OVER_STEP = 0, 1

#: numba's CUDA module as a global of this module, where numba's simulator finds and replaces
#: it (as :data:`nlcx.kernel.cuda_loop.cuda_module`).
cuda_module: Any = None


class FrictionDevices(NamedTuple):
    """The friction path of one kernel, as device functions of the thread's variant.

    ``has(axes)``: whether its axes have friction. ``start(axes, x, mode, direction, hold)``: the
    modes at t_0. ``act(phase, t, k, kd, x, u, pc, dist, bd, dist_map, integration, c, axes,
    mode, direction, hold, xn, f_k, record)``: at :data:`AT_SAMPLE`, the breakaway at t_k and,
    with ``record``, the friction forces into ``f_k`` (1, n_u); :data:`OVER_STEP`, the step into
    ``xn`` (n, 1)."""

    has: DeviceFunction
    start: DeviceFunction
    act: DeviceFunction


def friction_devices(
    retarget: Retarget, rhs: DeviceFunction, n_x: int, n_u: int, n_stages: int, n_d: int
) -> FrictionDevices:
    """The friction path compiled for a kernel with friction (``rhs``: the plant's right-hand
    side as a device function; the sizes of the thread's work space)."""
    global cuda_module
    gpu = cuda_module = cuda()
    from numba import float64

    N, NU, NST, ND = n_x, max(n_u, 1), max(n_stages, 1), max(n_d, 1)
    at_sample, update = retarget.device(sample_stage), retarget.device(update_friction_modes)
    forces_at, step_one = retarget.device(friction_forces), retarget.device(step_with_friction)

    @gpu.jit(device=True)
    def act(phase: int, t: float, k: int, kd: int, x: FloatArray, u: FloatArray, pc: FloatArray, dist: FloatArray,
            bd: int, dist_map: IntArray, integration: Integration, c: FloatArray, axes: FloatArray, mode: IntArray,
            direction: FloatArray, hold: FloatArray, xn: FloatArray, f_k: FloatArray,
            record: bool) -> None:  # pragma: no cover - device  # fmt: skip
        local = cuda_module.local.array
        one = OneColumn(local((N, 1), float64), local((NU, 1), float64), pc, local((N, 1), float64))
        scratch = FrictionScratch(
            local((NST, N, 1), float64), local((N, 1), float64), local(NU, float64), local(NU, float64),
            local((NU, NU), float64), local(NU, float64), local(N, float64), local(ND, float64)[: dist.shape[3]], one,
        )  # fmt: skip
        column = (N, 1)
        work = FrictionWork(local(column, float64), local(column, float64), local(column, float64),
                            local((NU, 1), float64), scratch)  # fmt: skip
        for i in range(N):
            work.x[i, 0] = x[i, 0]
        for j in range(NU):
            work.u[j, 0] = u[0, j]
        if phase == AT_SAMPLE:
            step, stage = at_sample(dist[bd], k)  # a device function returns no view: indices
            d_k = dist[bd, step, stage]
            update(rhs, t, work.x[:, 0], work.u[:, 0], d_k, dist_map, axes, mode, direction, scratch)
            if record:
                forces_at(rhs, t, work.x[:, 0], work.u[:, 0], d_k, dist_map, axes, mode, direction, scratch)
                for j in range(NU):
                    f_k[0, j] = scratch.f[j]
            return
        step_one(rhs, t, work, dist, bd, kd, c, dist_map, axes, mode, direction, hold, integration)
        for i in range(N):
            xn[i, 0] = work.x_new[i, 0]

    return FrictionDevices(retarget.device(has_friction), retarget.device(initial_modes), act)


def frictionless() -> FrictionDevices:
    """The friction path of a kernel without friction: never acts."""
    gpu = cuda()

    @gpu.jit(device=True)
    def has(axes: FloatArray) -> bool:  # pragma: no cover - device
        return False

    @gpu.jit(device=True)
    def start(
        axes: FloatArray, x: FloatArray, mode: IntArray, direction: FloatArray, hold: FloatArray
    ) -> None:  # pragma: no cover - device
        return

    @gpu.jit(device=True)
    def act(phase: int, t: float, k: int, kd: int, x: FloatArray, u: FloatArray, pc: FloatArray, dist: FloatArray,
            bd: int, dist_map: IntArray, integration: Integration, c: FloatArray, axes: FloatArray, mode: IntArray,
            direction: FloatArray, hold: FloatArray, xn: FloatArray, f_k: FloatArray,
            record: bool) -> None:  # pragma: no cover - device  # fmt: skip
        return

    return FrictionDevices(has, start, act)

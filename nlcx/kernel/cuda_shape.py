"""What a closed-loop GPU kernel is specialised to (:class:`LoopShape`), whether a loop can run
on the GPU at all (:func:`unsupported`), and the plugins' device functions of a shape
(:func:`loop_devices`): the plant's right-hand side, the controller's step with its gain
schedules reached by slot, the chains of sensor and actuator elements in table order, and the
friction path. :mod:`nlcx.kernel.cuda_loop` compiles the thread's loop around them.
"""

from __future__ import annotations

from typing import NamedTuple, TypeAlias

from nlcx._numba_compat import is_numba_function
from nlcx.kernel.abi import ACTUATOR, ELEMENT_ENTRY, SENSOR, Padding, no_element
from nlcx.kernel.cuda_friction import FrictionDevices, friction_devices, frictionless
from nlcx.kernel.device import Retarget, cuda
from nlcx.kernel.friction import any_friction
from nlcx.kernel.signatures import (
    Callbacks,
    ControllerStep,
    DeviceFunction,
    FloatArray,
    GainSchedule,
    IntArray,
    LoopElement,
    RightHandSide,
)
from nlcx.kernel.structures import ControllerCall, Integration, LoopElements, PlantCall, PlantForces

__all__ = ["ElementEntry", "LoopDevices", "LoopShape", "loop_devices", "shape_of", "unsupported"]

EE = ELEMENT_ENTRY.at


#: An entry of the element table: (hook, function, p_off, s_off, d_off).
ElementEntry: TypeAlias = tuple[int, LoopElement | Padding, int, int, int]


class LoopShape(NamedTuple):
    """What a compiled closed-loop kernel is specialised to: the plugins' functions (CPU forms),
    the element table's order and offsets, whether any variant has friction, and the sizes of
    the thread's local arrays."""

    rhs: RightHandSide
    step: ControllerStep
    schedules: tuple[tuple[int, GainSchedule], ...]  # (slot, schedule function) of the callback table
    elements: tuple[ElementEntry, ...]
    n_x: int
    n_u: int
    n_y: int
    n_r: int
    n_log: int
    n_cp: int
    n_cs: int
    method: int
    n_stages: int
    friction: bool
    n_d: int


def shape_of(
    plant: PlantCall,
    controller: ControllerCall,
    elements: LoopElements,
    forces: PlantForces,
    n_u: int,
    n_log: int,
    integration: Integration,
) -> LoopShape:
    """The :class:`LoopShape` of a kernel call's structures (``n_u`` inputs, ``n_log`` logged values)."""
    schedules = tuple((slot, fn) for slot, fn in enumerate(controller.callbacks) if is_numba_function(fn))
    table = tuple(
        (int(row[EE.hook]), elements.functions[int(row[EE.slot])], int(row[EE.param_offset]),
         int(row[EE.state_offset]), int(row[EE.data_offset]))
        for row in elements.table
    )  # fmt: skip
    return LoopShape(
        rhs=plant.rhs, step=controller.step, schedules=schedules, elements=table,
        n_x=plant.x0.shape[1], n_u=n_u, n_y=plant.C.shape[0], n_r=controller.ref.shape[2], n_log=n_log,
        n_cp=controller.cp.shape[1], n_cs=controller.cs0.shape[1], method=integration.method,
        n_stages=integration.rk_b.shape[0], friction=any_friction(forces.friction),
        n_d=forces.dist.shape[3],
    )  # fmt: skip


def unsupported(plant: PlantCall, controller: ControllerCall, elements: LoopElements) -> str | None:
    """Why a kernel call cannot run on the GPU (one line naming what), or None."""
    for what, fn in (("plant right-hand side", plant.rhs), ("controller step", controller.step)):
        if not is_numba_function(fn):
            return f"the {what} {getattr(fn, '__name__', fn)!r} is not a numba function"
    for fn in elements.functions:
        if fn is not no_element and not is_numba_function(fn):  # no_element: the table's padding
            return f"the loop element {getattr(fn, '__name__', fn)!r} is not a numba function"
    return None


# ----------------------------------------------------------------------------- device functions

#: The device functions of a closed-loop kernel: (rhs, controller step, sensor chain, actuator
#: chain, friction path).
LoopDevices: TypeAlias = tuple[DeviceFunction, DeviceFunction, DeviceFunction, DeviceFunction, FrictionDevices]


def _via_slot(retarget: Retarget, schedules: tuple[tuple[int, GainSchedule], ...]) -> DeviceFunction:
    """The GPU's :func:`nlcx.controllers.pid_step.via_slot`: a branch over the slots in use."""
    gpu = cuda()

    @gpu.jit(device=True)
    def none(
        callbacks: Callbacks, slot: int, t: float, e: float, edot: float, p: FloatArray, row: int, offset: int
    ) -> tuple[float, float, float]:  # pragma: no cover - device
        return 0.0, 0.0, 0.0

    chain = none
    for slot, fn in reversed(schedules):
        chain = _slot_branch(slot, retarget.device(fn), chain)
    return chain


def _slot_branch(slot: int, gains: DeviceFunction, rest: DeviceFunction) -> DeviceFunction:
    @cuda().jit(device=True)
    def branch(
        callbacks: Callbacks, s: int, t: float, e: float, edot: float, p: FloatArray, row: int, offset: int
    ) -> tuple[float, float, float]:  # pragma: no cover - device
        if s == slot:
            return gains(t, e, edot, p, row, offset)
        return rest(callbacks, s, t, e, edot, p, row, offset)

    return branch


def _element_chain(retarget: Retarget, entries: tuple[ElementEntry, ...], hook: int) -> DeviceFunction:
    """One device function calling the elements at ``hook`` in table order."""
    gpu = cuda()

    @gpu.jit(device=True)
    def nothing(
        t: float, dt: float, k: int, signal: FloatArray, vid: IntArray, ep: FloatArray, es: FloatArray, data: FloatArray
    ) -> None:  # pragma: no cover - device
        return

    chain = nothing
    for h, fn, p_off, s_off, d_off in reversed(entries):
        if h == hook:
            chain = _element_link(retarget.device(fn), p_off, s_off, d_off, chain)
    return chain


def _element_link(fn: DeviceFunction, p_off: int, s_off: int, d_off: int, rest: DeviceFunction) -> DeviceFunction:
    @cuda().jit(device=True)
    def link(
        t: float, dt: float, k: int, signal: FloatArray, vid: IntArray, ep: FloatArray, es: FloatArray, data: FloatArray
    ) -> None:  # pragma: no cover - device
        fn(t, dt, k, signal, vid, ep, es, data, p_off, s_off, d_off)
        rest(t, dt, k, signal, vid, ep, es, data)

    return link


def loop_devices(shape: LoopShape) -> LoopDevices:
    """(rhs, controller step, sensor chain, actuator chain, friction path) compiled for the GPU."""
    from nlcx.controllers.pid_step import via_slot

    retarget = Retarget()  # one for the schedules and the step that calls them: each compiled once
    retarget.stand_in(via_slot, _via_slot(retarget, shape.schedules))
    entries = tuple(e for e in shape.elements if e[1] is not no_element)
    rhs = retarget.device(shape.rhs)
    friction = (
        friction_devices(retarget, rhs, shape.n_x, shape.n_u, shape.n_stages, shape.n_d)
        if shape.friction else frictionless()
    )  # fmt: skip
    return (
        rhs, retarget.device(shape.step),
        _element_chain(retarget, entries, SENSOR), _element_chain(retarget, entries, ACTUATOR), friction,
    )  # fmt: skip

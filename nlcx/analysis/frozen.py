"""Frozen gains: each PID loop of a built controller with its schedule evaluated at one point.

A gain-scheduled PID is linear time-varying; frozen at a point (t, e) of its schedule it is a
linear time-invariant PID with the gains the schedule gives there. The frozen point
(:class:`FrozenPoint`) is a time t (the argument of time-AGS, eqs. 2.17-2.19) and an error e
(the argument of error-AGS, eqs. 2.20-2.22, and of the fuzzy and ANFIS schedules, whose
de/dt is frozen at 0, the operating point at rest); a constant schedule has no argument.

Everything a loop is read from is the parameter row the compiled step reads
(:mod:`nlcx.controllers.pid_step`): the loop's output, input, sign and scale, its derivative
options and PID form, and its schedule's block, on which the registered schedule's own
compiled function is evaluated. So the frozen gains are the gains the simulation computes at
that (t, e), not a second implementation of the schedules.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from nlcx import registry
from nlcx.controllers.base import ControllerInstance
from nlcx.controllers.pid import FORMS, HEAD, INPUT, LOOP
from nlcx.errors import ConfigError

#: The arguments a frozen point gives a schedule: time (s) and error (the outputs' units).
AXES = ("t", "e")
#: The argument each built-in schedule varies with; a schedule not named here is taken to vary
#: with both (its gains are still evaluated at the frozen point, t and e together).
SCHEDULE_AXES: Mapping[str, tuple[str, ...]] = {
    "constant": (),
    "time_ags": ("t",),
    "error_ags": ("e",),
    "fuzzy": ("e",),
    "anfis": ("e",),
}
#: What ``--at`` takes.
AT_FORMS = "allowed: t=T (a time >= 0, in s) or e=E (an error r - y, in the outputs' units)"


@dataclass(frozen=True)
class FrozenPoint:
    """Where the schedules are frozen: time ``t`` (s) and error ``e`` = r - y, in the units of
    the plant's outputs (a loop's schedule sees it times the loop's ``scale``, as in the
    simulation)."""

    t: float = 0.0
    e: float = 0.0

    def describe(self, axes: tuple[str, ...] = AXES) -> str:
        """``t = 2 s, e = 0.5`` for the axes named."""
        return ", ".join(f"t = {self.t:g} s" if axis == "t" else f"e = {self.e:g}" for axis in axes)

    def moved(self, axis: str, value: float) -> FrozenPoint:
        """This point with ``axis`` set to ``value``."""
        return replace(self, **{axis: float(value)})


def parse_at(
    at: str | Mapping[str, float] | FrozenPoint | None, key: str = "at"
) -> tuple[FrozenPoint, tuple[str, ...]]:
    """The frozen point ``at`` names and the axes it sets: ``"t=T"``, ``"e=E"``, a mapping
    ``{"t": T, "e": E}`` (either or both), a :class:`FrozenPoint` (both) or None (t = 0 and
    e = 0, the schedules' starting point, no axis set). Bad input: one :class:`ConfigError`
    naming ``key``."""
    if at is None:
        return FrozenPoint(), ()
    if isinstance(at, FrozenPoint):
        return at, AXES
    if isinstance(at, str):
        name, sep, text = at.partition("=")
        values: Mapping[str, Any] = {name.strip(): text.strip()} if sep else {}
    elif isinstance(at, Mapping):
        values = at
    else:
        raise ConfigError(key, at, AT_FORMS)
    if not values or any(name not in AXES for name in values):
        raise ConfigError(key, at, AT_FORMS)
    point = FrozenPoint()
    for name, text in values.items():
        try:
            value = float(text)
        except (TypeError, ValueError):
            raise ConfigError(key, at, AT_FORMS) from None
        if not math.isfinite(value) or (name == "t" and value < 0):
            raise ConfigError(key, at, AT_FORMS)
        point = point.moved(name, value)
    return point, tuple(name for name in AXES if name in values)


@dataclass(frozen=True)
class FrozenLoop:
    """One PID loop frozen at a point: what it regulates and drives, and its linear law

        v = sign * scale * [k_p (b r - y) + k_i (r - y)/s + k_d N s/(s + N) (r - y, or -y)]

    with (k_p, k_i, k_d) the parallel-form gains the loop acts with at that point (as the PID
    logs them), b the set-point weight and N the derivative filter (:func:`derivative_filter`)."""

    name: str
    output: str
    input: str
    sign: float
    scale: float
    schedule: str
    kp: float
    ki: float
    kd: float
    N: float
    derivative: str
    on_measurement: bool
    setpoint_weight: float


def schedule_axes(kind: str) -> tuple[str, ...]:
    """The frozen point's axes a schedule of ``kind`` varies with (:data:`SCHEDULE_AXES`)."""
    return SCHEDULE_AXES.get(kind, AXES)


def loop_schedules(controller: ControllerInstance) -> dict[str, str]:
    """Each loop's schedule kind, by loop name, in the order of the parameter row (none for a
    controller without loops: a control law)."""
    loops = controller.config.get("loops", {})
    return {name: str(loop["schedule"]["kind"]) for name, loop in loops.items()}


def varying_axes(controller: ControllerInstance) -> tuple[str, ...]:
    """The axes some loop of ``controller`` varies with, in :data:`AXES` order."""
    found = {axis for kind in loop_schedules(controller).values() for axis in schedule_axes(kind)}
    return tuple(axis for axis in AXES if axis in found)


def parallel_gains(kp: float, ki: float, kd: float, form: int) -> tuple[float, float, float]:
    """The schedule's (k_p, k_i, k_d) as the parallel gains the loop acts with, as the PID's
    step turns them (:data:`nlcx.controllers.pid.FORMS`): parallel k_p + k_i/s + k_d s as they
    are; ideal k_p (1 + k_i/s + k_d s) gives (k_p, k_p k_i, k_p k_d); series
    k_p (1 + k_i/s)(1 + k_d s) gives (k_p (1 + k_i k_d), k_p k_i, k_p k_d)."""
    if form == FORMS["parallel"]:
        return kp, ki, kd
    return (kp * (1.0 + ki * kd) if form == FORMS["series"] else kp), kp * ki, kp * kd


def derivative_filter(filtered: bool, N: float, period: float) -> float:
    """The N of the loop's derivative k_d N s/(s + N).

    A filtered derivative (``derivative.method: filtered``) is N s/(s + N) itself. A backward
    difference (e_k - e_{k-1})/T is, at frequencies well below 1/T, the ideal derivative s
    delayed by half a sample, s exp(-s T/2); an ideal k_d s is improper, which python-control's
    state-space models cannot hold, so it is realised as s/(1 + s T/2) (the first-order Pade
    approximation of that delay): N = 2/T, with T the PID's sampling period (``sample_time``)
    or the simulation step dt."""
    return N if filtered else 2.0 / period


def frozen_gains(
    controller: ControllerInstance, block: Mapping[str, float], kind: str, at: FrozenPoint
) -> tuple[float, float, float]:
    """(k_p, k_i, k_d) of the loop whose :data:`~nlcx.controllers.pid.LOOP` block is ``block``, its
    schedule (``kind``) evaluated at ``at`` by the schedule's compiled function on the
    controller's parameter row, with the argument the PID's step gives it: e times the loop's
    scale, de/dt = 0. For the built-in schedules this is

    - constant: (k_p, k_i, k_d) as configured;
    - time-AGS, at t: k_p = kp_min + (kp_max - kp_min) exp(-k t) (eq. 2.17),
      k_i = ki_max - (ki_max - ki_min) exp(-k t) (eq. 2.18),
      k_d = kd_min + (kd_max - kd_min) exp(-k t) (eq. 2.19);
    - error-AGS, at s = |c e| (or c e, ``error: signed``; c its ``error_scale``):
      k_p = kp_max - (kp_max - kp_min) exp(-k s) (eq. 2.20),
      k_i = ki_min - (ki_min - ki_max) exp(-k s) (eq. 2.21),
      k_d = kd_max - (kd_max - kd_min) exp(-k s) (eq. 2.22),

    each gain with its own rate k. Returned as the schedule gives them (the PID form's
    parameters; :func:`parallel_gains` turns them into the parallel gains)."""
    gains = registry.schedules.get(kind).gains
    row = np.ascontiguousarray(controller.cp[np.newaxis, :])
    e = at.e * block["scale"]
    kp, ki, kd = gains(float(at.t), float(e), 0.0, row, 0, int(block["schedule_offset"]))
    return float(kp), float(ki), float(kd)


def update_period(controller: ControllerInstance, dt: float) -> float:
    """The period T the PID updates over: its ``sample_time``, or the simulation step ``dt``."""
    sample_time = HEAD.unpack(controller.cp)["sample_time"]
    return sample_time if sample_time > 0 else dt


def frozen_loops(
    controller: ControllerInstance, at: FrozenPoint, outputs: list[str], inputs: list[str], dt: float
) -> tuple[FrozenLoop, ...]:
    """Every loop of a built PID ``controller`` frozen at ``at``, read from its parameter row
    (``outputs`` and ``inputs``: the plant's names, which the row's indices select; ``dt``: the
    simulation step, the period of a PID without a ``sample_time``)."""
    cp = controller.cp
    base = HEAD.size + INPUT.size * int(HEAD.unpack(cp)["n_inputs"])
    period = update_period(controller, dt)
    loops = []
    for i, (name, kind) in enumerate(loop_schedules(controller).items()):
        block = LOOP.unpack(cp, base + LOOP.size * i)
        kp, ki, kd = parallel_gains(*frozen_gains(controller, block, kind, at), int(block["form"]))
        filtered = block["filtered"] != 0.0
        loops.append(
            FrozenLoop(
                name=name, output=outputs[int(block["y_index"])], input=inputs[int(block["u_index"])],
                sign=block["sign"], scale=block["scale"], schedule=kind, kp=kp, ki=ki, kd=kd,
                N=derivative_filter(filtered, block["N"], period),
                derivative="filtered" if filtered else "backward",
                on_measurement=block["on_measurement"] != 0.0, setpoint_weight=block["setpoint_weight"],
            )
        )  # fmt: skip
    return tuple(loops)

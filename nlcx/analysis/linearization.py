"""Frozen-gain linear analysis of a configured PID loop or control law: ``nlcx.linearize`` and ``nlcx linearize``.

The plant is linearised about its operating point (:func:`nlcx.plants.base.linearize`), the
PID's gain schedules are frozen at one point (t, e) (:mod:`nlcx.analysis.frozen`), and the
loop is closed (:mod:`nlcx.analysis.linear`): its closed-loop poles and its margins with the
loop broken at the plant input are those of the linear time-invariant loop the scheduled PID
would be if its gains stopped moving there. :func:`linearize_along` repeats this along the
schedule's argument. A control law (:mod:`nlcx.controllers.law`: a user's law, LQR, pole
placement, state feedback, sliding mode) is linearised numerically about the operating point
instead (:mod:`nlcx.analysis.law`); it has no schedule to freeze.

What the linear model leaves out, each result says in its ``notes``: the uncertainty
sections (disturbances, noise, friction, actuator lag and saturation), the PID's actuator
saturation and integral limits (linear inside them), and its sampling (the model is
continuous).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import control as ct
import numpy as np

from nlcx.analysis.frozen import (
    AXES,
    FrozenPoint,
    frozen_loops,
    loop_schedules,
    parse_at,
    schedule_axes,
    update_period,
    varying_axes,
)
from nlcx.analysis.frozen_results import FrozenSweep, Linearization, MarginalPole
from nlcx.analysis.linear import (
    closed_loop_system,
    controller_system,
    margins_table,
    plant_system,
    poles_table,
)
from nlcx.errors import ConfigError, did_you_mean
from nlcx.limits import MAX_POINTS, check_count

if TYPE_CHECKING:
    from collections.abc import Mapping

    from nlcx.api import ConfigLike, OverridesLike
    from nlcx.config import Experiment, PluginSection
    from nlcx.controllers.base import ControllerInstance
    from nlcx.controllers.pid_config import PIDConfig
    from nlcx.engine import Prepared
    from nlcx.protocols import ControllerPlugin

__all__ = ["FrozenSweep", "Linearization", "MarginalPole", "analyse", "linearize", "linearize_along"]

#: Frozen points of :func:`linearize_along` unless told otherwise.
POINTS = 51


@dataclass(frozen=True)
class _Setting:
    """What every frozen point of one analysis shares: the experiment, the prepared plant and
    controller, the plant's linear model and the notes on what it leaves out."""

    experiment: Experiment
    prepared: Prepared
    controller: ControllerInstance
    plant: ct.StateSpace
    notes: tuple[str, ...]


def _is_pid(section: PluginSection[ControllerPlugin]) -> bool:
    return section.kind == "pid"


def _is_law(section: PluginSection[ControllerPlugin]) -> bool:
    from nlcx.controllers.law import LawController

    return isinstance(section.model, LawController)


def _scheduled(section: PluginSection[ControllerPlugin]) -> bool:
    """Whether some loop of a PID section has a schedule that varies."""
    config = cast("PIDConfig", section.config)  # a PID section's (the caller's check, _is_pid)
    for loop in config.loops.values():
        kind = loop.schedule["kind"] if isinstance(loop.schedule, dict) else loop.schedule.kind
        if schedule_axes(str(kind)):
            return True
    return False


def _chosen(exp: Experiment, controller: str | None) -> PluginSection[ControllerPlugin]:
    """The controller section to analyse: the one named, or the config's first PID with a
    scheduled loop, or else its first PID."""
    labels = [c.label for c in exp.controllers]
    if controller is not None:
        section = next((c for c in exp.controllers if c.label == controller), None)
        if section is None:
            problem = f"not a controller of {exp.name}{did_you_mean(controller, labels)}"
            raise ConfigError("controller", controller, f"{problem}; allowed: {', '.join(labels)}")
        if not (_is_pid(section) or _is_law(section)):
            raise ConfigError(
                f"controllers.{controller}.kind", section.kind, "linearize analyses PID controllers (pid) and control "
                "laws (nlcx.controller, lqr, pole_placement, state_feedback, sliding_mode); it cannot freeze this one",
            )  # fmt: skip
        return section
    pids = [c for c in exp.controllers if _is_pid(c)]
    if not pids:
        laws = [c for c in exp.controllers if _is_law(c)]
        if laws:
            return laws[0]
        raise ConfigError("controllers", labels, "linearize analyses PID controllers (kind: pid) and control laws; "
                          "this config has none")  # fmt: skip
    return next((c for c in pids if _scheduled(c)), pids[0])


def _notes(exp: Experiment, controller: ControllerInstance) -> tuple[str, ...]:
    """What the linear model leaves out of ``exp`` and ``controller``."""
    notes = []
    if exp.uncertainties:
        names = ", ".join(u.label for u in exp.uncertainties)
        notes.append(f"the uncertainty sections ({names}) are not part of the linear model (nominal plant)")
    if controller.law is not None:
        return (*notes, "the law is linearised numerically about the operating point (central differences); "
                "its update every period T is modelled as continuous, ds/dt = (s_next - s) / T")  # fmt: skip
    config = controller.config
    if config.get("saturation"):
        notes.append("the PID's actuator saturation is not part of the linear model (linear below its limits)")
    limited = [name for name, loop in config["loops"].items() if loop.get("integral_limit") is not None]
    if limited:
        notes.append(f"the integral limits of {', '.join(limited)} are not part of the linear model")
    if config.get("sample_time", 0.0) > 0:
        notes.append(
            f"the PID samples every {config['sample_time']:g} s; the linear model is continuous (it leaves out the "
            "hold's delay of about half a sample)"
        )
    return tuple(notes)


def _setting(config: ConfigLike, controller: str | None, overrides: OverridesLike) -> _Setting:
    """The experiment of ``config``, built with only the controller analysed."""
    from nlcx import api, engine

    exp = api.experiment(config, overrides)
    section = _chosen(exp, controller)
    prepared = engine.prepare(dataclasses.replace(exp, controllers=(section,)))
    (built,) = prepared.controllers
    return _Setting(exp, prepared, built, plant_system(prepared.plant), _notes(exp, built))


def _frozen(setting: _Setting, at: FrozenPoint) -> Linearization:
    """The analysis of ``setting`` frozen at ``at``."""
    plant = setting.prepared.plant
    outputs, inputs = plant.output_names, plant.input_names
    dt = setting.experiment.section.simulation.dt
    if setting.controller.law is not None:
        return _law_linearization(setting, at, dt)
    loops = frozen_loops(setting.controller, at, outputs, inputs, dt)
    controller = controller_system(loops, outputs, inputs)
    closed = closed_loop_system(setting.plant, controller)
    margins, transfers = margins_table(setting.plant, loops)
    return Linearization(
        experiment=setting.experiment, label=setting.controller.label, at=at, loops=loops,
        period=update_period(setting.controller, dt), plant=setting.plant,
        controller=controller, closed_loop=closed, poles=poles_table(closed), margins=margins,
        loop_transfers=transfers, notes=setting.notes,
    )  # fmt: skip


def _law_linearization(setting: _Setting, at: FrozenPoint, dt: float) -> Linearization:
    """The analysis of a control law (:mod:`nlcx.analysis.law`): nothing to freeze."""
    import nlcx.analysis.law as law

    plant, built = setting.prepared.plant, setting.controller
    controller = law.law_system(built, plant, dt)
    measured = law.measured_plant(setting.plant, built, plant)
    closed = law.law_closed_loop(measured, controller, plant.output_names)
    shape = built.law.shape
    driven = [plant.input_names[int(i)] for i in built.cp[shape.n_y : shape.n_y + shape.n_u]]
    margins, transfers = law.law_margins(measured, controller, driven)
    period = float(built.cp[shape.hold + 1]) or dt
    return Linearization(
        experiment=setting.experiment, label=built.label, at=at, loops=(), period=period, plant=setting.plant,
        controller=controller, closed_loop=closed, poles=poles_table(closed), margins=margins,
        loop_transfers=transfers, notes=setting.notes, law_gains=law.law_gains(built, plant),
    )  # fmt: skip


def _check_axes(setting: _Setting, given: tuple[str, ...], key: str, value: object) -> None:
    """Refuse a frozen point or sweep on an axis no loop of the controller varies with."""
    varying = varying_axes(setting.controller)
    unused = [axis for axis in given if axis not in varying]
    if not unused:
        return
    kinds = ", ".join(f"{name} {kind}" for name, kind in loop_schedules(setting.controller).items())
    allowed = f"allowed: {', '.join(varying)}" if varying else "its gains are constant: give none"
    message = f"the gains of controller {setting.controller.label!r} do not vary with {unused[0]} ({kinds}); {allowed}"
    raise ConfigError(key, value, message)


def linearize(
    config: ConfigLike,
    controller: str | None = None,
    at: str | Mapping[str, float] | FrozenPoint | None = None,
    *,
    overrides: OverridesLike = None,
) -> Linearization:
    """Linearise ``config``'s plant about its operating point and close its PID loops with the
    gains frozen at ``at``.

    The schedules are evaluated as the simulation evaluates them (time-AGS at t, eqs.
    2.17-2.19; error-AGS at e, eqs. 2.20-2.22; constant gains as they are), and each loop's
    law is k_p + k_i/s + k_d N s/(s + N) in its PID form's parallel gains. A backward-difference
    derivative, an ideal k_d s delayed by half a sample, is realised with N = 2/T (T the PID's
    period), so the controller is proper (:func:`nlcx.analysis.frozen.derivative_filter`).

    Parameters
    ----------
    config : str, path, mapping or Experiment
        What :func:`nlcx.experiment` takes.
    controller : str, optional
        The controller's label; default: the config's first PID with a scheduled loop, or else
        its first PID.
    at : str, mapping or FrozenPoint, optional
        ``"t=T"`` (time-AGS frozen at time T, in s) or ``"e=E"`` (error-AGS frozen at error
        E = r - y, in the outputs' units), or ``{"t": T, "e": E}``; default: t = 0 and e = 0,
        the point the schedules start from. An axis no loop varies with is refused.
    overrides : list of str or mapping, optional
        What :func:`nlcx.experiment` takes.

    Returns
    -------
    Linearization
        The named state-space systems ``plant``, ``controller`` and ``closed_loop``, the
        tables ``poles``, ``margins`` and ``gains``, and the loop transfers.

    Raises
    ------
    nlcx.errors.ConfigError
        An unknown or non-PID controller, a malformed ``at``, or an axis its gains do not vary with.

    Examples
    --------
    >>> import nlcx
    >>> lin = nlcx.linearize("configs/x_error_ags.yaml", "proposed", at="e=0.5")
    >>> lin.plant.input_labels, lin.plant.output_labels, lin.closed_loop.nstates
    (['F_x'], ['x', 'theta'], 8)
    >>> lin.gains[["loop", "kp", "ki", "kd"]].round(3).values.tolist()
    [['theta', 24.585, 3.498, 3.049], ['x', -2.971, -1.01, -4.471]]
    >>> list(lin.poles.columns)
    ['real', 'imag', 'zeta', 'omega_n']
    >>> lin.margins[["opening", "name", "input"]].values.tolist()
    [['loop', 'theta', 'F_x'], ['loop', 'x', 'F_x'], ['input', 'F_x', 'F_x']]
    """
    result, _ = analyse(config, controller, at, overrides=overrides)
    return result


def _extent(setting: _Setting, axis: str) -> float:
    """Where a sweep along ``axis`` ends: the simulation's end (t), or the largest error a loop
    starts from or is commanded to, max |r(t) - y(0)| over its output's reference (e)."""
    prepared = setting.prepared
    if axis == "t":
        return float(setting.experiment.section.simulation.t_end)
    plant = prepared.plant
    y0 = plant.C @ plant.x0
    largest = 0.0
    for name in dict.fromkeys(loop["signal"] or key for key, loop in setting.controller.config["loops"].items()):
        reference = prepared.references[name]
        r = reference.model.values(reference.config, prepared.grid.t)
        largest = max(largest, float(np.max(np.abs(r - y0[plant.output_names.index(name)]))))
    if not largest > 0:
        raise ConfigError("along", axis, "no loop's error leaves 0 (each reference equals its output's start)")
    return largest


def linearize_along(
    config: ConfigLike,
    along: str,
    controller: str | None = None,
    at: str | Mapping[str, float] | FrozenPoint | None = None,
    *,
    points: int = POINTS,
    overrides: OverridesLike = None,
) -> FrozenSweep:
    """:func:`linearize` at evenly spaced values of one argument of the schedules.

    Parameters
    ----------
    config : str, path, mapping or Experiment
        What :func:`nlcx.experiment` takes.
    along : {"t", "e"}
        The argument swept: t from 0 to the end of the simulation, or e from 0 to the largest
        error a loop starts from or is commanded to, max |r(t) - y(0)| over the loops'
        outputs. Some loop's schedule must vary with it.
    controller : str, optional
        As for :func:`linearize`.
    at : str, mapping or FrozenPoint, optional
        Where the other argument stays (default 0); its value on the swept one is replaced.
    points : int
        Values of the swept argument, the ends included (at least 2).
    overrides : list of str or mapping, optional
        What :func:`nlcx.experiment` takes.

    Returns
    -------
    FrozenSweep
        The analysis at each value, and its tables.

    Examples
    --------
    >>> import nlcx.analysis
    >>> sweep = nlcx.analysis.linearize_along("configs/x_error_ags.yaml", "e", "proposed", points=3)
    >>> sweep.values.tolist()
    [0.0, 0.5, 1.0]
    >>> sweep.gains.query("loop == 'theta'").kp.round(4).tolist()
    [24.0, 24.5852, 25.142]
    """
    _, sweep = analyse(config, controller, at, along, points=points, overrides=overrides)
    return cast("FrozenSweep", sweep)  # analyse sweeps when told along what


def analyse(
    config: ConfigLike,
    controller: str | None = None,
    at: str | Mapping[str, float] | FrozenPoint | None = None,
    along: str | None = None,
    *,
    points: int = POINTS,
    overrides: OverridesLike = None,
) -> tuple[Linearization, FrozenSweep | None]:
    """:func:`linearize` at ``at`` and, ``along`` an axis, :func:`linearize_along` it, from one
    built experiment (``nlcx linearize`` runs this). The arguments are checked before the
    experiment is built."""
    point, given = parse_at(at)
    if along is not None:
        if along not in AXES:
            raise ConfigError("along", along, "allowed: t (time) or e (error)")
        check_count("points", points, 2, MAX_POINTS, "frozen points along the axis")
    setting = _setting(config, controller, overrides)
    _check_axes(setting, given, "at", at)
    result = _frozen(setting, point)
    if along is None:
        return result, None
    _check_axes(setting, (along,), "along", along)
    values = np.linspace(0.0, _extent(setting, along), points)
    return result, FrozenSweep(along, values, tuple(_frozen(setting, point.moved(along, v)) for v in values))

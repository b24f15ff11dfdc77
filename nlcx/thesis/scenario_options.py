"""The experiment options of the pendulums (chapters 2-4) a hypothesis about the loop the
thesis simulated may pick: each edits an experiment's raw config outside its PID controllers'
sections, and :data:`nlcx.thesis.loop_options.FAMILIES` lists them with the PID's own options.

Every option is a setting a user can put in any config (nothing here is a special case of
the kernel): an actuator lag and a reference prefilter (loop elements and references); the
experiment as Simulink may have run it: the steps' amplitude and time, the initial angle, the
z loop of the x-z and x-y-z pendulums, the disturbance's phase, start and entry; and how it is
measured: the origin of the measured times, the settling band of a regulated angle, the rise
time's limits. A value changes only what the experiment has: a disturbance option leaves an
experiment without a disturbance as it is.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from nlcx import registry

#: An experiment's raw (interpolated) config, or one of its sections.
Raw = dict[str, Any]

#: The angle states (and the loops on them).
ANGLES = ("theta", "phi")
#: Reference kinds that step (a step, and a step through a prefilter).
STEPS = ("step", "filtered_step")


def _forces_before_input_disturbances(raw: Raw) -> None:
    """Loop elements act in config order: an actuator lag filters the controller's forces
    only, so it goes before any disturbance that enters at the inputs."""
    elements = raw.get("uncertainty") or {}
    lag = elements.get("actuator_lag")
    names = list(elements)
    at_input = [k for k, e in elements.items() if isinstance(e, dict) and e.get("kind") == "disturbance"
                and e.get("entry") == "input"]  # fmt: skip
    if lag is None or not at_input or names.index("actuator_lag") < names.index(at_input[0]):
        return
    rest = [(k, e) for k, e in elements.items() if k != "actuator_lag"]
    first = [k for k, _ in rest].index(at_input[0])
    raw["uncertainty"] = dict([*rest[:first], ("actuator_lag", lag), *rest[first:]])


def actuator_lag(raw: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """A first-order lag tau on every force (the actuator_lag loop element), after every other
    element except a disturbance entering at the inputs (:func:`_forces_before_input_disturbances`)."""
    raw.setdefault("uncertainty", {})["actuator_lag"] = {"kind": "actuator_lag", "tau": params["tau"]}
    _forces_before_input_disturbances(raw)


def prefilter(raw: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """Every step reference through a first-order prefilter of time constant T_f."""
    for reference in raw.get("reference", {}).values():
        if reference.get("kind") == "step":
            reference.update(kind="filtered_step", time_constant=params["T_f"])


def _step_references(raw: Raw) -> list[Raw]:
    """The experiment's step references (a prefiltered step is one)."""
    return [r for r in (raw.get("reference") or {}).values() if r.get("kind") in STEPS]


def _set_metrics(raw: Raw, **settings: Any) -> None:
    raw["metrics"] = {**(raw.get("metrics") or {}), **settings}


def plant_states(raw: Raw) -> list[str]:
    """The state names of the experiment's plant (from the plant registry)."""
    plant = registry.plants.get(raw["plant"]["name"], path="plant.name")
    return [s.name for s in plant.states]


def absolute_settling(raw: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """A regulated signal (theta, phi) settles inside a band of at least tol (the free
    parameter): the larger of tol and the settling band's fraction of its peak deviation."""
    _set_metrics(raw, regulation_abs_tol=params["tol"])


def step_amplitude(raw: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """Every step reference ends at A (the free parameter) instead of its configured final value."""
    for reference in _step_references(raw):
        reference["final"] = params["A"]


def _step_at_one_second(raw: Raw, _: Mapping[str, float], __: list[str]) -> None:
    """The reference steps at t = 1 s (Simulink's Step block default), not at t = 0."""
    for reference in _step_references(raw):
        reference["time"] = 1.0


def step_at_one_second_timed_from(origin: str) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    """The reference steps at t = 1 s; a step response's times are measured from ``origin``
    (``metrics.time_origin``: ``start``, t = 0, or ``step``, its step)."""

    def change(raw: Raw, params: Mapping[str, float], inputs: list[str]) -> None:
        _step_at_one_second(raw, params, inputs)
        _set_metrics(raw, time_origin=origin)

    return change


def initial_angle(raw: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """The pendulum starts tilted: theta(0) = theta0 (the free parameter), and phi(0) alike
    on the pendulums that have it."""
    angles = [state for state in plant_states(raw) if state in ANGLES]
    plant = raw["plant"]
    plant["x0"] = {**(plant.get("x0") or {}), **dict.fromkeys(angles, params["theta0"])}


def z_loop(feedforward: bool, printed: bool) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    """On a plant with a z axis only: without the equilibrium feed-forward on every PID (the z
    loop holds the weight by its integrator) and/or with the printed state equations."""

    def change(raw: Raw, _: Mapping[str, float], __: list[str]) -> None:
        if "z" not in plant_states(raw):
            return
        if not feedforward:
            for controller in (raw.get("controllers") or {}).values():
                if controller.get("kind") == "pid":
                    controller["feedforward"] = "none"
        if printed:
            raw["plant"]["params"] = {**(raw["plant"].get("params") or {}), "equations": "printed"}

    return change


def disturbance(**settings: Any) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    """``settings`` on every ``kind: disturbance`` element of the experiment (none: no change)."""

    def change(raw: Raw, _: Mapping[str, float], __: list[str]) -> None:
        for element in (raw.get("uncertainty") or {}).values():
            if isinstance(element, dict) and element.get("kind") == "disturbance":
                element.update(settings)
        _forces_before_input_disturbances(raw)

    return change


def rise_limits(low: float, high: float) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    """A measurement option: t_r from ``low`` to ``high`` of the step (metrics.rise_limits)."""

    def change(raw: Raw, _: Mapping[str, float], __: list[str]) -> None:
        _set_metrics(raw, rise_limits=[low, high])

    return change

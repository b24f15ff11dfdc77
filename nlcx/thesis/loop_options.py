"""The loop options of the pendulums (chapters 2-4) a hypothesis about the loop the thesis
simulated may pick (:mod:`nlcx.thesis.hypotheses`), by family (:data:`FAMILIES`).

Every option is a setting a user can put in any config (nothing here is a special case of
the kernel). Here, the PID's: its derivative, integral form, PID form, sampling and actuator
saturation with anti-windup, the units its loops see, the error-AGS argument, the reading of
the printed gain ranges, the integrators' limits, the z loop's schedule and the x-z and x-y-z
pendulums' own conventional gains; the experiment's (an actuator lag, a reference prefilter,
the steps, the initial angle, the z loop, the disturbance, the measurement) are
:mod:`nlcx.thesis.scenario_options`'.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from nlcx.thesis.scenario_options import (
    ANGLES,
    Raw,
    absolute_settling,
    actuator_lag,
    disturbance,
    initial_angle,
    plant_states,
    prefilter,
    rise_limits,
    step_amplitude,
    step_at_one_second_timed_from,
    z_loop,
)

#: A PID loop's gains, each with its own schedule.
GAINS = ("kp", "ki", "kd")


@dataclass(frozen=True)
class OptionValue:
    """One value of an option family: how it changes a PID controller's config (given the
    free parameters' values and the plant's inputs), and the continuous parameters
    (name -> (lower, upper)) it frees."""

    doc: str
    change: Callable[[Raw, Mapping[str, float], list[str]], None]
    free: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    #: "controller": ``change`` edits each PID controller's section; "experiment": the
    #: whole experiment (a loop element or a reference).
    scope: str = "controller"


def _by_magnitude(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
    """Gain ranges of the negative-gain loops read as min/max of |k|, not of k: where both
    printed bounds are negative, the "min" value is the one of smaller magnitude."""
    for loop in pid["loops"].values():
        schedule = loop["schedule"]
        for gain in GAINS:
            bounds = schedule.get(gain)
            if isinstance(bounds, dict) and bounds["min"] < 0 and bounds["max"] < 0:
                lo, hi = sorted((bounds["min"], bounds["max"]), key=abs)
                schedule[gain] = {"min": lo, "max": hi}


def _derivative(method: str, on: str) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    def change(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
        pid["derivative"] = {"method": method, "N": 100.0, "on": on}

    return change


def _integral_inside(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
    pid["integral"] = "inside"


def _signed_error(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
    for loop in pid["loops"].values():
        if loop["schedule"].get("kind") == "error_ags":
            loop["schedule"]["error"] = "signed"


def _saturation(anti_windup: str) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    def change(pid: Raw, params: Mapping[str, float], inputs: list[str]) -> None:
        pid["saturation"] = {"limits": {name: params["F_max"] for name in inputs}, "anti_windup": anti_windup}

    return change


def unchanged(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
    """The default setting: the config as it is."""


def _form(form: str) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    def change(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
        pid["form"] = form

    return change


def _angles_in_degrees(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
    """The angle loops (theta, phi) see their output and reference in degrees."""
    for key, loop in pid["loops"].items():
        if (loop.get("signal") or key) in ANGLES:
            loop["scale"] = 180.0 / math.pi


def _ags_angle_degrees(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
    """The error schedules of the angle loops take e in degrees (the loop itself stays in radians)."""
    for key, loop in pid["loops"].items():
        if (loop.get("signal") or key) in ANGLES and loop["schedule"].get("kind") == "error_ags":
            loop["schedule"]["error_scale"] = 180.0 / math.pi


def _sampled(pid: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """A discrete PID sampled every T_s (the free parameter)."""
    pid["sample_time"] = params["T_s"]


def _integral_limit(signals: tuple[str, ...] | None) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    """The integrator of each loop on ``signals`` (None: every loop) held inside [-L, L] (the
    free parameter), as the output limits of Simulink's Integrator block hold it."""

    def change(pid: Raw, params: Mapping[str, float], _: list[str]) -> None:
        for key, loop in pid["loops"].items():
            if signals is None or (loop.get("signal") or key) in signals:
                loop["integral_limit"] = params["L"]

    return change


def _own_conventional_gains(raw: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """On a plant with a z axis (x-z, x-y-z) only: the constant-gain angle and position loops'
    k_p, k_i, k_d times their own factors (``c_angle_kp`` ... ``c_position_kd``, free), so these
    pendulums' conventional gains are their own, not the x pendulum's."""
    if "z" not in plant_states(raw):
        return
    for controller in (raw.get("controllers") or {}).values():
        if controller.get("kind") != "pid":
            continue
        for key, loop in controller["loops"].items():
            group = GAIN_GROUPS.get(loop.get("signal") or key)
            schedule = loop.get("schedule")
            if group is None or not isinstance(schedule, dict) or schedule.get("kind") != "constant":
                continue
            for gain in GAINS:
                schedule[gain] = schedule[gain] * params[f"c_{group}_{gain}"]


def _z_schedule(swapped: bool, rate_free: bool) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    """The z loop's gain schedule (Tables 3.6 and 4.1 print its ranges from 25 to 15, and no
    rate): its printed min and max exchanged, and/or its three rates one free k_z."""

    def change(pid: Raw, params: Mapping[str, float], _: list[str]) -> None:
        for key, loop in pid["loops"].items():
            schedule = loop.get("schedule")
            if (loop.get("signal") or key) != "z" or schedule.get("kind") not in ("time_ags", "error_ags"):
                continue
            if swapped:
                for gain in GAINS:
                    schedule[gain] = {"min": schedule[gain]["max"], "max": schedule[gain]["min"]}
            if rate_free:
                schedule["rate"] = dict.fromkeys(GAINS, params["k_z"])

    return change


#: The position loops (an integrator limit on them leaves the angle and z loops unlimited).
POSITIONS = ("x", "y")
#: The loops whose gains :func:`_own_conventional_gains` scales, by group.
GAIN_GROUPS = {"theta": "angle", "phi": "angle", "x": "position", "y": "position"}
#: The factors of the x-z and x-y-z pendulums' own conventional gains.
OWN_GAINS = {f"c_{group}_{gain}": (0.2, 5.0) for group in ("angle", "position") for gain in GAINS}
F_MAX = {"F_max": (2.0, 100.0)}
#: The free parameters' values nearest the default loop: the widest limit, the shortest lag,
#: prefilter and sampling period, the narrowest absolute band, the unit step, the upright
#: start, the widest integrator limit, the z schedule's rate as configured (the position
#: loops'), the shared conventional gains (factors 1).
NEUTRAL = {
    "F_max": 100.0, "tau": 0.001, "T_f": 0.01, "T_s": 0.001, "u_max": 20.0,
    "tol": 0.002, "A": 1.0, "theta0": 0.0, "L": 2.0, "k_z": 0.1, **dict.fromkeys(OWN_GAINS, 1.0),
}  # fmt: skip
#: The integrators' limit L.
L_MAX = {"L": (0.01, 2.0)}

#: family -> value -> option; the first value of each family is the default.
FAMILIES: dict[str, dict[str, OptionValue]] = {
    "ordering": {
        "value": OptionValue("AGS ranges min/max by value, as printed (default)", unchanged),
        "magnitude": OptionValue("negative-gain AGS ranges min/max by magnitude", _by_magnitude),
    },
    "derivative": {
        "backward": OptionValue("backward difference of e (default)", unchanged),
        "filtered": OptionValue("filtered N s/(s + N), N = 100 (Simulink's default)", _derivative("filtered", "error")),
        "measurement": OptionValue("filtered, N = 100, on the measurement", _derivative("filtered", "measurement")),
    },
    "integral": {
        "outside": OptionValue("u = k_i(t) integral(e), eqs. 2.17-2.22 as printed (default)", unchanged),
        "inside": OptionValue("u = integral(k_i(t) e) (Simulink's AGS by a gain block)", _integral_inside),
    },
    "ags_error": {
        "abs": OptionValue("error AGS on |e| (default)", unchanged),
        "signed": OptionValue("error AGS on e as eqs. 2.20-2.22 print it", _signed_error),
    },
    "ags_argument": {
        "as_seen": OptionValue("the error schedule's argument is e as the loop sees it (default)", unchanged),
        "angle_degrees": OptionValue("the angle loops' error schedules take e in degrees", _ags_angle_degrees),
    },
    "form": {
        "parallel": OptionValue("k_p + k_i/s + k_d s (default)", unchanged),
        "ideal": OptionValue("k_p (1 + k_i/s + k_d s), Simulink's ideal form", _form("ideal")),
        "series": OptionValue("k_p (1 + k_i/s)(1 + k_d s)", _form("series")),
    },
    "units": {
        "radians": OptionValue("angle loops see radians (default)", unchanged),
        "degrees": OptionValue("angle loops see degrees (y, r, e and the schedule's argument)", _angles_in_degrees),
    },
    "lag": {
        "none": OptionValue("forces applied as commanded (default)", unchanged),
        "first_order": OptionValue(
            "first-order actuator lag tau on every force", actuator_lag, {"tau": (0.001, 0.3)}, "experiment"
        ),
    },
    "prefilter": {
        "none": OptionValue("raw step references (default)", unchanged),
        "first_order": OptionValue(
            "first-order prefiltered steps, time constant T_f", prefilter, {"T_f": (0.01, 3.0)}, "experiment"
        ),
    },
    "sampling": {
        "continuous": OptionValue("PID updated at every integration step, dt = 1 ms (default)", unchanged),
        "discrete": OptionValue(
            "discrete PID at T_s (free in [1, 50] ms; 10 and 20 ms inside), output held between samples",
            _sampled,
            {"T_s": (0.001, 0.05)},
        ),
    },
    "saturation": {
        "none": OptionValue("unlimited forces (default)", unchanged),
        "plain": OptionValue("|F| <= F_max, no anti-windup", _saturation("none"), F_MAX),
        "clamping": OptionValue("|F| <= F_max, clamping anti-windup", _saturation("clamping"), F_MAX),
        "back_calculation": OptionValue(
            "|F| <= F_max, back-calculation anti-windup", _saturation("back_calculation"), F_MAX
        ),
    },
    "theta_settling": {
        "relative": OptionValue("a regulated angle settles inside 2 % of its peak deviation (default)", unchanged),
        "absolute": OptionValue(
            "a regulated angle settles inside max(2 % of its peak deviation, tol) (metrics.regulation_abs_tol)",
            absolute_settling,
            {"tol": (0.002, 0.05)},
            "experiment",
        ),
    },
    "reference_amplitude": {
        "unit": OptionValue("unit steps, as printed (default)", unchanged),
        "free": OptionValue(
            "every step reference ends at A (the AGS error normalisation untouched)",
            step_amplitude,
            {"A": (0.2, 2.0)},
            "experiment",
        ),
    },
    "step_time": {
        "zero": OptionValue("reference step at t = 0 (default)", unchanged),
        "one_second": OptionValue(
            "reference step at t = 1 s (Simulink's default), times measured from t = 0 (metrics.time_origin: start)",
            step_at_one_second_timed_from("start"),
            scope="experiment",
        ),
        "one_second_from_step": OptionValue(
            "reference step at t = 1 s (Simulink's default), times measured from the step (metrics.time_origin: step)",
            step_at_one_second_timed_from("step"),
            scope="experiment",
        ),
    },
    "initial_angle": {
        "zero": OptionValue("the pendulum starts upright (default)", unchanged),
        "free": OptionValue(
            "theta(0) = theta0, and phi(0) alike where the pendulum has phi",
            initial_angle,
            {"theta0": (0.0, 0.2)},
            "experiment",
        ),
    },
    "z_loop": {
        "as_configured": OptionValue(
            "x-z, x-y-z: equilibrium feed-forward F_z = (M + m) g, derived equations (default)", unchanged
        ),
        "no_feedforward": OptionValue(
            "x-z, x-y-z: no feed-forward (the z loop's integrator holds the weight)",
            z_loop(feedforward=False, printed=False),
            scope="experiment",
        ),
        "no_feedforward_printed": OptionValue(
            "x-z, x-y-z: no feed-forward, the printed state equations",
            z_loop(feedforward=False, printed=True),
            scope="experiment",
        ),
        "printed": OptionValue(
            "x-z, x-y-z: the printed state equations (plant.params.equations)",
            z_loop(feedforward=True, printed=True),
            scope="experiment",
        ),
    },
    "disturbance_phase": {
        "zero": OptionValue("d = A sin(2 pi f t), as printed (default)", unchanged),
        "quarter": OptionValue("the disturbance's phase pi/2", disturbance(phase=math.pi / 2), scope="experiment"),
        "half": OptionValue("the disturbance's phase pi", disturbance(phase=math.pi), scope="experiment"),
        "three_quarter": OptionValue(
            "the disturbance's phase 3 pi/2", disturbance(phase=3 * math.pi / 2), scope="experiment"
        ),
    },
    "disturbance_start": {
        "zero": OptionValue("the disturbance acts from t = 0 (default)", unchanged),
        "one_second": OptionValue(
            "the disturbance starts at t = 1 s (d = 0 before)", disturbance(start=1.0), scope="experiment"
        ),
    },
    "disturbance_entry": {
        "accelerations": OptionValue("d added to every acceleration, as eqs. 2.13-2.16 print it (default)", unchanged),
        "input": OptionValue("d added as a force to every plant input", disturbance(entry="input"), scope="experiment"),
    },
    "integrator_limit": {
        "none": OptionValue("unlimited integrators (default)", unchanged),
        "position": OptionValue(
            "the position loops' (x, y) integrators held inside [-L, L]", _integral_limit(POSITIONS), L_MAX
        ),
        "all": OptionValue("every loop's integrator held inside [-L, L]", _integral_limit(None), L_MAX),
    },
    "conventional_gains": {
        "shared": OptionValue(
            "one set of conventional angle and position gains for every pendulum (default)", unchanged
        ),
        "own_with_z": OptionValue(
            "x-z, x-y-z: their own conventional angle and position gains, the shared ones times factors c in "
            "[0.2, 5] (the x-y pendulum keeps the x pendulum's: no train table has it)",
            _own_conventional_gains,
            OWN_GAINS,
            "experiment",
        ),
    },
    "z_schedule": {
        "as_printed": OptionValue(
            "x-z, x-y-z AGS: the z ranges as printed (k_p from 25 to 15 ...), the position loops' rates (default)",
            unchanged,
        ),
        "swapped": OptionValue(
            "the z ranges' printed min and max exchanged (k_p from 15 to 25 ...)", _z_schedule(True, False)
        ),
        "rate_free": OptionValue(
            "the z schedule's three rates one free k_z", _z_schedule(False, True), {"k_z": (0.01, 2.0)}
        ),
        "swapped_rate_free": OptionValue(
            "the z ranges exchanged and the rates one free k_z", _z_schedule(True, True), {"k_z": (0.01, 2.0)}
        ),
    },
    "rise_time": {
        "10_90": OptionValue("a measurement option: t_r from 10 % to 90 % of the step (default)", unchanged),
        "0_100": OptionValue(
            "a measurement option: t_r from the step to its first reaching 100 %",
            rise_limits(0.0, 1.0),
            scope="experiment",
        ),
        "5_95": OptionValue(
            "a measurement option: t_r from 5 % to 95 % of the step", rise_limits(0.05, 0.95), scope="experiment"
        ),
    },
}

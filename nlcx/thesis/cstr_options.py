"""The loop options of chapter 5 (Table 5.8; the CSTR) a hypothesis may pick
(:mod:`nlcx.thesis.hypotheses`), by family: the Ziegler-Nichols rule, the derivative, the
set-point weight, the step's time, an actuator limit, the model's time unit and the reactor."""

from __future__ import annotations

from collections.abc import Callable, Mapping

from nlcx.thesis.loop_options import FAMILIES, OptionValue, unchanged
from nlcx.thesis.scenario_options import Raw


def _zn_rule(rule: str) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    """Every Ziegler-Nichols tuner of the controller uses ``rule`` (PI: no derivative)."""

    def change(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
        for tuner in pid.get("tune", []):
            if tuner.get("kind") == "ziegler_nichols":
                tuner["rule"] = rule

    return change


def _setpoint_weight(b: float) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    def change(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
        pid["setpoint_weight"] = b

    return change


def _derivative_n(method: str, on: str, n: float) -> Callable[[Raw, Mapping[str, float], list[str]], None]:
    def change(pid: Raw, _: Mapping[str, float], __: list[str]) -> None:
        pid["derivative"] = {"method": method, "N": n, "on": on}

    return change


def _actuator_limit(raw: Raw, params: Mapping[str, float], _: list[str]) -> None:
    """|u| <= u_max on the plant input, whatever controller drives it (a loop element)."""
    raw.setdefault("uncertainty", {})["limit"] = {"kind": "actuator_saturation", "limit": params["u_max"]}


def _model_in_seconds(raw: Raw, _: Mapping[str, float], __: list[str]) -> None:
    """The model's time unit read as seconds converted from minutes: G(s) -> G(60 s), with
    the run's horizon and step scaled alike (t_end and dt x 60)."""
    params = raw["plant"]["params"]
    for key in ("num", "den"):
        coefficients = params[key]
        n = len(coefficients) - 1
        params[key] = [c * 60.0 ** (n - i) for i, c in enumerate(coefficients)]
    raw["simulation"] = {**raw["simulation"], "t_end": raw["simulation"]["t_end"] * 60.0}
    raw["simulation"]["dt"] = raw["simulation"]["dt"] * 60.0


def _nonlinear_reactor(raw: Raw, _: Mapping[str, float], __: list[str]) -> None:
    """The Van de Vusse reactor (eqs. 5.1-5.2) in place of its transfer function: every
    controller adds the operating dilution rate, the step is 0.05 gmol/L about C_Bs (a unit
    step is beyond the reactor's reach; M_p, t_r, t_s are relative to the step)."""
    raw["plant"] = {"name": "cstr"}
    for controller in raw.get("controllers", {}).values():
        controller["feedforward"] = "equilibrium"
    for reference in raw.get("reference", {}).values():
        step = reference["final"] - reference.get("initial", 0.0)
        reference.update(initial=CSTR_OPERATING_CB, final=CSTR_OPERATING_CB + 0.05 * step)


#: C_B at the CSTR's operating point (u_s = 4/7 1/min), gmol/L (configs/cstr_nonlinear.yaml).
CSTR_OPERATING_CB = 1.117021276595745

#: Chapter 5's families (Table 5.8; the CSTR), same form as :data:`FAMILIES`.
CSTR_FAMILIES: dict[str, dict[str, OptionValue]] = {
    "zn_rule": {
        "classic": OptionValue("Ziegler-Nichols PID, Table 5.1 (default)", unchanged),
        "pi": OptionValue("Ziegler-Nichols PI, Table 5.1 (PI instead of PID)", _zn_rule("pi")),
        "pessen": OptionValue("Pessen's integral rule", _zn_rule("pessen")),
        "some_overshoot": OptionValue("ZN 'some overshoot'", _zn_rule("some_overshoot")),
        "no_overshoot": OptionValue("ZN 'no overshoot'", _zn_rule("no_overshoot")),
        "tyreus_luyben": OptionValue("Tyreus-Luyben PID", _zn_rule("tyreus_luyben")),
    },
    "cstr_derivative": {
        "backward": OptionValue("backward difference of e (default)", unchanged),
        "filtered_n100": OptionValue("filtered, N = 100 (Simulink's default)", _derivative_n("filtered", "error", 100)),
        "filtered_n10": OptionValue("filtered, N = 10", _derivative_n("filtered", "error", 10)),
        "measurement": OptionValue(
            "backward difference of -y (no kick)", _derivative_n("backward", "measurement", 100)
        ),
    },
    "setpoint_weight": {
        "one": OptionValue("proportional term on e (default)", unchanged),
        "half": OptionValue("proportional term on 0.5 r - y", _setpoint_weight(0.5)),
        "zero": OptionValue("proportional term on -y (b = 0; I-PD with the derivative on y)", _setpoint_weight(0.0)),
    },
    # the pendulums' family, its times measured from the step as chapter 5's always were
    "step_time": {v: FAMILIES["step_time"][v] for v in ("zero", "one_second_from_step")},
    "actuator_limit": {
        "none": OptionValue("unlimited dilution rate (default)", unchanged),
        "saturated": OptionValue(
            "|u| <= u_max on the input, any controller", _actuator_limit, {"u_max": (0.1, 20.0)}, "experiment"
        ),
    },
    "time_unit": {
        "minutes": OptionValue("the model's time unit (min) printed as s (default)", unchanged),
        "seconds": OptionValue("the model converted to seconds, G(60 s)", _model_in_seconds, scope="experiment"),
    },
    "reactor": {
        "transfer_function": OptionValue("the transfer function 5.10 (default)", unchanged),
        "nonlinear": OptionValue(
            "the nonlinear reactor about its operating point", _nonlinear_reactor, scope="experiment"
        ),
    },
}

"""Ziegler-Nichols closed-loop (ultimate-gain) tuning, Table 5.1.

The ultimate gain K_u and period T_u come from the phase crossover of the plant's linear
model (python-control's ``stability_margins``: K_u is the gain margin, T_u = 2 pi / w_pc);
for a plant other than a transfer function the model is linearised about its operating
point. Table 5.1 then gives the gains (parallel form, k_i = k_p / T_i, k_d = k_p T_d):

    P:   k_p = 0.5 K_u
    PI:  k_p = 0.45 K_u,  T_i = T_u / 1.2
    PID: k_p = 0.6 K_u,   T_i = T_u / 2,  T_d = T_u / 8
"""

from __future__ import annotations

import itertools
import math
from typing import Any, Literal

import control as ct
import numpy as np
from pydantic import Field

from nlcx.errors import ConfigError
from nlcx.plants.base import Plant, linearize
from nlcx.tuning.base import TuneContext, TunerConfig, TunerModel, single_loop

#: Table 5.1: (k_p / K_u, T_i / T_u, T_d / T_u).
RULES: dict[str, tuple[float, float | None, float | None]] = {
    "p": (0.5, None, None),
    "pi": (0.45, 1 / 1.2, None),
    "pid": (0.6, 0.5, 0.125),
}
#: Other published ultimate-gain rules, same columns (not in the thesis): Pessen's integral
#: rule, Ziegler-Nichols "some overshoot" and "no overshoot", Tyreus-Luyben's PID.
VARIANT_RULES: dict[str, tuple[float, float | None, float | None]] = {
    "pessen": (0.7, 0.4, 0.15),
    "some_overshoot": (0.33, 0.5, 0.33),
    "no_overshoot": (0.2, 0.5, 0.33),
    "tyreus_luyben": (1 / 2.2, 2.2, 1 / 6.3),
}
ALL_RULES = {**RULES, **VARIANT_RULES}


class ZieglerNicholsConfig(TunerConfig):
    kind: Literal["ziegler_nichols"] = Field(
        "ziegler_nichols", description="registered name of this tuner; selects the model that validates this section"
    )
    rule: Literal["p", "pi", "pid", "pessen", "some_overshoot", "no_overshoot", "tyreus_luyben"] = Field(
        "pid",
        description=(
            "tuning rule from the ultimate gain K_u and period T_u: p, pi, pid (Table 5.1), pessen, some_overshoot, "
            "no_overshoot, tyreus_luyben"
        ),
    )
    range_factors: tuple[float, float] = Field(
        (0.5, 1.5),
        description="for a fuzzy schedule: the gain ranges [low x ZN gain, high x ZN gain] of eqs. 5.12-5.14",
    )
    verify: bool = Field(
        True, description="cross-check K_u and T_u by simulating the P loop at K_u (recorded in tuning.csv)"
    )
    verify_periods: float = Field(8.0, gt=1, description="length of that check, in periods T_u")


def linear_model(plant: Plant) -> ct.StateSpace:
    """The plant's linear model from its input to its output."""
    if plant.name == "transfer_function":
        num = plant.params["num"]
        den = plant.params["den"]
        return ct.ss(ct.tf(num, den))
    A, B, C = linearize(plant)
    return ct.ss(A, B, C, np.zeros((C.shape[0], B.shape[1])))


def ultimate(plant: Plant) -> tuple[float, float]:
    """(K_u, T_u) from the phase crossover of the plant's linear model."""
    sys = linear_model(plant)
    if sys.ninputs != 1 or sys.noutputs != 1:
        raise ConfigError("tune", "ziegler_nichols", f"{plant.name} is not SISO")
    gm, _, _, wpc, _, _ = ct.stability_margins(sys)
    if not (np.isfinite(gm) and np.isfinite(wpc) and wpc > 0):
        raise ConfigError("tune", "ziegler_nichols", f"{plant.name} has no finite ultimate gain (no phase crossover)")
    return float(gm), float(2 * math.pi / wpc)


def zn_gains(ku: float, tu: float, rule: str) -> tuple[float, float, float]:
    """(k_p, k_i, k_d) by Table 5.1."""
    a, ti, td = ALL_RULES[rule]
    kp = a * ku
    ki = kp / (ti * tu) if ti is not None else 0.0
    kd = kp * td * tu if td is not None else 0.0
    return kp, ki, kd


def p_loop(controller: dict[str, Any], key: str, gain: float) -> dict[str, Any]:
    """The P-only loop at ``gain`` of a SISO PID (its feed-forward and bias kept)."""
    loop = {**controller["loops"][key], "schedule": {"kind": "constant", "kp": gain}}
    keep: dict[str, object] = {k: controller[k] for k in ("feedforward", "bias") if k in controller}
    return {"kind": "pid", "loops": {key: loop}, **keep}


def oscillation_at(ctx: TuneContext, p_controller: dict[str, Any], periods: float, tu: float) -> tuple[float, float]:
    """(period, amplitude ratio last/first) of the nominal P loop ``p_controller``, simulated
    for ``periods`` periods T_u."""
    result = ctx.simulate(
        {"p": p_controller}, simulation={"t_end": round(periods * tu / ctx.dt) * ctx.dt}, uncertainty={}, measure=False
    )
    (run,) = result.runs
    y = (run.x @ result.prepared.plant.C.T)[:, 0]
    settle = y - np.mean(y[run.t > run.t[-1] - 2 * tu])
    upward = np.nonzero((settle[:-1] < 0) & (settle[1:] >= 0))[0]
    times = run.t[upward] - settle[upward] * (run.t[upward + 1] - run.t[upward]) / (settle[upward + 1] - settle[upward])
    if len(times) < 3:
        return math.nan, math.nan
    period = float(np.mean(np.diff(times[1:])))
    peaks = [np.max(np.abs(settle[a:b])) for a, b in itertools.pairwise(upward[1:])]
    return period, float(peaks[-1] / peaks[0]) if peaks else math.nan


class ZieglerNichols(TunerModel):
    """Ziegler-Nichols ultimate-gain tuning (Table 5.1) of a SISO PID."""

    Config = ZieglerNicholsConfig

    def tune(self, controller: dict[str, Any], cfg: ZieglerNicholsConfig, ctx: TuneContext) -> dict[str, Any]:
        key, loop = single_loop(controller, ctx, "ziegler_nichols")
        ku, tu = ultimate(ctx.plant)
        kp, ki, kd = zn_gains(ku, tu, cfg.rule)
        ctx.shared["zn"] = {"Ku": ku, "Tu": tu, "kp": kp, "ki": ki, "kd": kd}
        for name, value in (("Ku", ku), ("Tu", tu), ("kp", kp), ("ki", ki), ("kd", kd)):
            ctx.record("ziegler_nichols", name, value)
        if cfg.verify:
            period, ratio = oscillation_at(ctx, p_loop(controller, key, ku), cfg.verify_periods, tu)
            ctx.record("ziegler_nichols", "Tu_simulated", period)
            ctx.record("ziegler_nichols", "amplitude_ratio_at_Ku", ratio)
        schedule = dict(loop.get("schedule") or {"kind": "constant"})
        kind = schedule.get("kind", "constant")
        if kind == "constant":
            schedule.update({"kind": "constant", "kp": kp, "ki": ki, "kd": kd})
        elif kind == "fuzzy":
            lo, hi = cfg.range_factors
            for name, value in (("kp", kp), ("ki", ki), ("kd", kd)):
                schedule[name] = {"min": lo * value, "max": hi * value}
                ctx.record("ziegler_nichols", f"{name}_min", lo * value)
                ctx.record("ziegler_nichols", f"{name}_max", hi * value)
        elif kind != "anfis":
            raise ConfigError(f"{ctx.path}.loops.{key}.schedule.kind", kind, "ziegler_nichols sets constant or fuzzy")
        loops = {key: {**loop, "schedule": schedule}}
        return {**controller, "loops": loops}

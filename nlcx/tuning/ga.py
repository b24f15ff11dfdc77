"""Genetic-algorithm PID tuning (section 5.4.4): minimise ISE = integral of (r - y)^2 (eq. 5.20).

The same seeded GA as the calibration (:mod:`nlcx.tuning.optimise`); every generation's
candidates are simulated on the experiment's plant, references and uncertainties in one
batched kernel call, optionally split across a process pool (``jobs``), with the same
result serial or parallel.
"""

from __future__ import annotations

from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import Field, field_validator

from nlcx import runtime
from nlcx.tuning.base import Simulate, TuneContext, TunerConfig, TunerModel, single_loop
from nlcx.tuning.optimise import GASettings, evolve, require_pymoo

if TYPE_CHECKING:
    from nlcx.config.building import PluginSection
    from nlcx.protocols import ControllerPlugin

PENALTY = 1e6


class GATunerConfig(TunerConfig):
    kind: Literal["ga"] = Field(
        "ga", description="registered name of this tuner; selects the model that validates this section"
    )
    objective: Literal["ise"] = Field(
        "ise", description="the cost the GA minimises: ise, the integral of the squared error of the step response"
    )
    bounds: dict[str, tuple[float, float]] = Field(
        default_factory=lambda: {"kp": (0.0, 5.0), "ki": (0.0, 5.0), "kd": (0.0, 2.0)},
        description="search box of the gains: kp, ki and kd each [lower, upper]",
    )
    optimiser: GASettings = Field(
        GASettings(pop_size=40, generations=25, seed=1), description="settings of the seeded genetic algorithm"
    )
    jobs: int = Field(1, ge=1, description="worker processes evaluating each generation (1: in this process)")

    @field_validator("bounds")
    @classmethod
    def _gains(cls, bounds: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        if set(bounds) != {"kp", "ki", "kd"}:
            raise ValueError("bounds needs exactly kp, ki and kd")
        for key, (lo, hi) in bounds.items():
            if not lo < hi:
                raise ValueError(f"bounds of {key} must be [lower, upper] with lower < upper")
        return bounds


class ISEObjective:
    """ISE of a batch of (k_p, k_i, k_d) candidates, simulated together in one call of the
    tuner's ``simulate`` (picklable when it is, as the engine's is, for a process pool)."""

    def __init__(self, simulate: Simulate, key: str, controller: dict[str, Any]) -> None:
        self.simulate = simulate
        self.key = key
        self.controller = {k: v for k, v in controller.items() if k != "tune"}

    def _candidate(self, x: np.ndarray) -> dict[str, Any]:
        loop = self.controller["loops"][self.key]
        schedule = {"kind": "constant", "kp": float(x[0]), "ki": float(x[1]), "kd": float(x[2])}
        return {**self.controller, "loops": {self.key: {**loop, "schedule": schedule}}}

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(X)
        result = self.simulate({f"c{i}": self._candidate(x) for i, x in enumerate(X)}, measure=False)
        plant = result.prepared.plant
        name = _signal(self.controller, self.key)
        j = plant.output_names.index(name)
        out = np.empty(len(X))
        for i, run in enumerate(result.runs):
            if run.status != "ok":
                out[i] = PENALTY
                continue
            e = run.r[:, run.controller.reference_signals.index(name)] - run.x @ plant.C[j]
            with np.errstate(over="ignore", invalid="ignore"):
                ise = float(np.sum(0.5 * (e[1:] ** 2 + e[:-1] ** 2) * np.diff(run.t)))
            out[i] = ise if np.isfinite(ise) else PENALTY
        return out


def _signal(controller: dict[str, Any], key: str) -> str:
    return controller["loops"][key].get("signal") or key


class GATuner(TunerModel):
    """Genetic-algorithm PID tuning minimising ISE (eq. 5.20), seeded."""

    Config = GATunerConfig

    def tune(self, controller: dict[str, Any], cfg: GATunerConfig, ctx: TuneContext) -> dict[str, Any]:
        require_pymoo(f"{ctx.path}.tune.kind = ga")
        key, loop = single_loop(controller, ctx, "ga")
        objective = ISEObjective(ctx.simulate, key, controller)
        lower = np.array([cfg.bounds[g][0] for g in ("kp", "ki", "kd")])
        upper = np.array([cfg.bounds[g][1] for g in ("kp", "ki", "kd")])
        if cfg.jobs > 1:
            with ProcessPoolExecutor(max_workers=cfg.jobs, initializer=runtime.worker) as pool:
                result = evolve(objective, lower, upper, cfg.optimiser, pool, cfg.jobs)
        else:
            result = evolve(objective, lower, upper, cfg.optimiser)
        kp, ki, kd = (float(v) for v in result.x)
        for name, value in (("kp", kp), ("ki", ki), ("kd", kd), ("ISE", result.f)):
            ctx.record("ga", name, value)
        ctx.record("ga", "evaluations", result.evaluations)
        for name, value in cfg.optimiser.model_dump().items():
            ctx.record("ga", f"optimiser.{name}", value)
        for gain, (lo, hi) in cfg.bounds.items():
            ctx.record("ga", f"bounds.{gain}", f"[{lo}, {hi}]")
        schedule = {"kind": "constant", "kp": kp, "ki": ki, "kd": kd}
        return {**controller, "loops": {key: {**loop, "schedule": schedule}}}


def require_tuning_extra(controllers: Iterable[PluginSection[ControllerPlugin]], where: str = "") -> None:
    """Fail before any run, in one line, where one of ``controllers`` (an experiment's controller
    sections, with their tuners) is GA-tuned and pymoo is not installed; ``where`` (a config's
    path) prefixes the message."""
    for c in controllers:
        for tuner in c.tuners:
            if tuner.kind == "ga":
                require_pymoo(f"{where}controllers.{c.label}.tune.kind = ga")

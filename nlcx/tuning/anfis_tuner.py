"""ANFIS tuning of a PID (section 5.4.3): learn the gains as functions of (e, de/dt).

The thesis says only that the ANFIS's "input output data set has been taken from a PID
controller tuned using conventional ZN method". nlcx therefore (docs/assumptions.md A23):

1. runs the Ziegler-Nichols-tuned loop (the ``ziegler_nichols`` tuner must come first) and
   records its error e and error rate de/dt (the PID's own derivative estimate);
2. evaluates the fuzzy self-tuning surface of section 5.4.1 (Tables 5.2-5.7, 25 rules, gain
   ranges from ZN as for the fuzzy PID) at those samples: the teacher gains;
3. trains one first-order Takagi-Sugeno ANFIS per gain on (e, de/dt) -> gain with Jang's
   hybrid rule (:mod:`nlcx.tuning.anfis`), seeded, and installs them as the loop's schedule,
   with the gains clipped to the teacher's ranges (the ANFIS must not extrapolate outside them).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field

from nlcx.errors import ConfigError
from nlcx.tuning.base import TuneContext, TunerConfig, TunerModel, single_loop


class AnfisTunerConfig(TunerConfig):
    kind: Literal["anfis"] = Field(
        "anfis", description="registered name of this tuner; selects the model that validates this section"
    )
    n_mfs: int = Field(3, ge=2, le=7, description="membership functions per input of each trained model")
    mf: Literal["gbell", "gauss"] = Field("gbell", description="membership functions: generalised bell or Gaussian")
    epochs: int = Field(
        60,
        ge=1,
        description=(
            "training epochs (hybrid learning: least squares for the consequents, gradient descent for the premises)"
        ),
    )
    seed: int = Field(1, ge=0, description="seed of the training's random draws")
    samples: int = Field(1500, ge=50, description="training samples taken evenly from the Ziegler-Nichols run")
    range_factors: tuple[float, float] = Field(
        (0.5, 1.5),
        description="gain ranges of the fuzzy teacher: [low x ZN gain, high x ZN gain] (as for the fuzzy PID)",
    )
    teacher: dict[str, Any] = Field(
        default_factory=dict, description="overrides of the fuzzy teacher's configuration (sets, universes, rules, ...)"
    )


class AnfisTuner(TunerModel):
    """ANFIS gain schedule trained on the ZN loop's (e, de/dt) with the fuzzy surface as teacher."""

    Config = AnfisTunerConfig

    def tune(self, controller: dict[str, Any], cfg: AnfisTunerConfig, ctx: TuneContext) -> dict[str, Any]:
        from nlcx.controllers.fuzzy import fuzzy_surface
        from nlcx.tuning.anfis import anfis_schedule

        key, loop = single_loop(controller, ctx, "anfis")
        zn = ctx.shared.get("zn")
        if zn is None:
            raise ConfigError(f"{ctx.path}.tune", "anfis", "needs a ziegler_nichols tuner before it in the tune list")
        zn_loop = {**loop, "schedule": {"kind": "constant", "kp": zn["kp"], "ki": zn["ki"], "kd": zn["kd"]}}
        zn_run = ctx.simulate({ctx.label: {**controller, "loops": {key: zn_loop}}}, measure=False)
        run, plant = zn_run.runs[0], zn_run.prepared.plant
        signal = loop.get("signal") or key
        y = run.x @ plant.C[plant.output_names.index(signal)]
        e = run.r[:, run.controller.reference_signals.index(signal)] - y
        edot = np.diff(e, prepend=e[0]) / np.diff(run.t, prepend=run.t[0] - (run.t[1] - run.t[0]))
        pick = np.unique(np.linspace(0, len(e) - 1, min(cfg.samples, len(e))).round().astype(int))
        X = np.column_stack([e[pick], edot[pick]])
        lo, hi = cfg.range_factors
        teacher = {
            "kind": "fuzzy",
            **{g: {"min": lo * zn[g], "max": hi * zn[g]} for g in ("kp", "ki", "kd")},
            **cfg.teacher,
        }
        gains = np.column_stack(fuzzy_surface(teacher, X[:, 0], X[:, 1]))
        # the gains stay within the teacher's ranges, as the fuzzy PID's do (eqs. 5.12-5.14)
        clip = {g: {"min": lo * zn[g], "max": hi * zn[g]} for g in ("kp", "ki", "kd")}
        schedule, histories = anfis_schedule(
            X, gains, clip=clip, n_mfs=cfg.n_mfs, epochs=cfg.epochs, seed=cfg.seed, mf=cfg.mf
        )
        ctx.record("anfis", "training_samples", len(pick))
        for gain, history in histories.items():
            ctx.record("anfis", f"{gain}.rmse_initial", history[0])
            ctx.record("anfis", f"{gain}.rmse_final", history[-1])
        for name in ("n_mfs", "mf", "epochs", "seed"):
            ctx.record("anfis", name, getattr(cfg, name))
        return {**controller, "loops": {key: {**loop, "schedule": schedule}}}

"""Simple and exponential (Stribeck) friction of Appendix A on every moving base axis.

Appendix A (after Campbell et al.): at rest the friction holds the base up to the
breakaway force mu_s F_N; sliding, the simple model gives Coulomb plus viscous friction,
-mu_c F_N sgn(v) - eps v, and the exponential model
-[mu_c + (mu_s - mu_c) exp(-(|v|/v_s)^gamma)] F_N sgn(v) - eps v with form factor
gamma = 2 and Stribeck velocity v_s = 0.105 m/s. F_N = (M + m) g.

The stick-slip physics is a plant-force element (nlcx.kernel.friction): a sliding axis whose velocity
reaches zero within a step stops there and sticks; a stuck axis gets exactly the force that
keeps its acceleration zero (so it stays at rest, with no chattering from sgn(0)) while
that force is at most mu_s F_N, and breaks away in the direction of the net force otherwise.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from nlcx.errors import ConfigError, did_you_mean
from nlcx.kernel.friction import FRICTION_AXIS, FRICTION_EXPONENTIAL, FRICTION_SIMPLE
from nlcx.uncertainty.base import Hooks, UncertaintyConfig, UncertaintyModel
from nlcx.validation import join

#: The input whose axis is vertical: gravity gives it no normal force.
VERTICAL_INPUT = "F_z"


class FrictionConfig(UncertaintyConfig):
    kind: Literal["friction"] = Field(
        "friction", description="registered name of this uncertainty; selects the model that validates this section"
    )
    model: Literal["none", "simple", "exponential"] = Field(
        "simple",
        description=(
            "simple or exponential (Stribeck) friction of Appendix A; none switches friction off (handy as a sweep "
            "value)"
        ),
    )
    mu_s: float = Field(0.2, ge=0, description="static (breakaway) friction coefficient mu_s")
    mu_c: float = Field(0.15, ge=0, description="Coulomb (sliding) friction coefficient mu_c")
    viscous: float = Field(
        0.1, ge=0, description="viscous friction coefficient eps", json_schema_extra={"unit": "N s/m"}
    )
    stribeck_velocity: float = Field(
        0.105,
        gt=0,
        description="Stribeck velocity v_s of the exponential model (Appendix A)",
        json_schema_extra={"unit": "m/s"},
    )
    form_factor: float = Field(2.0, gt=0, description="form factor gamma of the exponential model (Appendix A)")
    normal_force: Literal["weight"] | float = Field(
        "weight",
        description="normal force F_N in N, or weight: (M + m) g as Appendix A defines it",
        json_schema_extra={"unit": "N"},
    )
    vertical: Literal["same", "viscous_only", "none"] = Field(
        "same",
        description=(
            "the vertical (z) axis: same applies F_N = (M + m) g as Appendix A literally does; viscous_only keeps only"
            " eps z_dot; none removes friction from z"
        ),
    )
    axes: list[str] | None = Field(
        None, description="inputs whose axes have friction; default: every input with an axis"
    )

    @model_validator(mode="after")
    def _static_at_least_sliding(self) -> FrictionConfig:
        if self.mu_s < self.mu_c:
            raise ValueError(f"mu_s ({self.mu_s}) must be >= mu_c ({self.mu_c})")
        return self


class Friction(UncertaintyModel):
    """Appendix A friction (simple or exponential) with true stiction on each base axis."""

    Config = FrictionConfig

    def apply(self, cfg: FrictionConfig, hooks: Hooks, path: str) -> None:
        plant = hooks.plant
        if hooks.friction is not None:
            raise ConfigError(path, cfg.kind, "only one friction model can act on a plant")
        if not plant.features.input_axes:
            raise ConfigError(join(path, "kind"), cfg.kind, f"{plant.name} has no mechanical axes for friction")
        axes = cfg.axes if cfg.axes is not None else list(plant.features.input_axes)
        if cfg.normal_force == "weight":
            if plant.features.weight is None:
                raise ConfigError(
                    join(path, "normal_force"), "weight", f"{plant.name} defines no weight; give a number"
                )
            f_n = plant.features.weight
        else:
            f_n = float(cfg.normal_force)
        if cfg.model == "none":
            return
        table = np.zeros((len(plant.inputs), FRICTION_AXIS.size))
        model = FRICTION_SIMPLE if cfg.model == "simple" else FRICTION_EXPONENTIAL
        for i, name in enumerate(axes):
            if name not in plant.features.input_axes:
                raise ConfigError(
                    join(path, "axes", i),
                    name,
                    f"not an input with an axis{did_you_mean(name, plant.features.input_axes)}; "
                    f"allowed: {', '.join(plant.features.input_axes)} (inputs with an axis)",
                )
            normal = f_n
            if name == VERTICAL_INPUT and cfg.vertical != "same":
                if cfg.vertical == "none":
                    continue
                normal = 0.0
            row = plant.input_names.index(name)
            velocity_name = plant.features.input_axes[name]
            velocity = plant.state_names.index(velocity_name)
            position = plant.state_names.index(velocity_name.removesuffix("_dot"))
            table[row] = FRICTION_AXIS.pack(
                model=model, mu_s=cfg.mu_s, mu_c=cfg.mu_c, viscous=cfg.viscous, normal_force=normal,
                stribeck_velocity=cfg.stribeck_velocity, form_factor=cfg.form_factor,
                velocity_index=velocity, position_index=position,
            )  # fmt: skip
        hooks.set_friction(table)

"""H2 and H-infinity preview servo (thesis section 5.5, eqs. 5.21-5.22, Figs. 5.18-5.19).

The controller knows the reference h samples ahead and applies (eq. 5.21)

    u(k) = u* + K_x xhat(k) + sum_{i=0..h} K_di d(k + i)

at the controller samples t = k Ts, holding u in between (zero-order hold). Here
xhat = [x - x*; v] is the plant state (full information) measured from the operating point
(x*, u*), extended by the integral of the tracking error v, and d(k + i) = r(t + i Ts) - y*
are the previewed reference samples, read from time-shifted reference channels.

The design (the discrete linear model, the preview design model and its H2 and H-infinity
syntheses) is :mod:`nlcx.controllers.preview_design`'s; the compiled step
:mod:`nlcx.controllers.preview_step`'s. Here: the controller's configuration and the plugin,
which designs the gains for a plant and packs them into the step's parameter row.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel, check_sample_time
from nlcx.controllers.preview_design import PreviewDesign, design_preview, linear_model
from nlcx.controllers.preview_step import LOG_SIZE, PREVIEW, STATE_HEAD, preview_step
from nlcx.errors import ConfigError, did_you_mean
from nlcx.plants.base import Plant
from nlcx.validation import join


class PreviewConfig(ControllerConfig):
    kind: Literal["preview"] = Field(
        "preview", description="registered name of this controller; selects the model that validates this section"
    )
    design: Literal["h2", "hinf"] = Field(
        "hinf", description="h2: LQ design; hinf: H-infinity design (game Riccati equation, bisection on gamma)"
    )
    preview: int = Field(
        10,
        ge=0,
        le=1000,
        description="preview length h: the controller reads r(t), r(t + T_s), ..., r(t + h T_s)",
        json_schema_extra={"unit": "samples"},
    )
    sample_time: float = Field(
        0.1,
        gt=0,
        description="controller sample time T_s, a whole number of simulation steps dt",
        json_schema_extra={"unit": "s"},
    )
    q: float = Field(
        1.0,
        gt=0,
        description=(
            "weight of the squared tracking error (c x - d)^2, d the reference's deviation from the operating point"
        ),
    )
    r: float = Field(
        0.1, gt=0, description="weight of the squared control effort u^2 (deviation from the equilibrium input)"
    )
    integral: float | None = Field(
        1.0,
        ge=0,
        description="weight of the squared error integral v^2; 0 or null: no integrator (no zero-offset guarantee)",
    )
    disturbance: bool = Field(
        False,
        description="add an input-disturbance channel (entering like u) to the H-infinity design's exogenous input",
    )
    gamma_tolerance: float = Field(1e-4, gt=0, lt=1, description="relative tolerance of the bisection on gamma")
    gamma_factor: float = Field(
        1.05, ge=1, description="the H-infinity design is made at gamma_factor * gamma_min (a numerical margin)"
    )
    signal: str | None = Field(
        None, description="plant output tracked (default: the plant's single output); its reference is previewed"
    )


class Preview(ControllerModel):
    """H2 / H-infinity preview servo with full state information (thesis section 5.5)."""

    Config = PreviewConfig
    step = staticmethod(preview_step)

    @staticmethod
    def tracked_output(cfg: PreviewConfig, plant: Plant, path: str) -> int:
        outputs = plant.output_names
        if cfg.signal is None:
            if len(outputs) != 1:
                raise ConfigError(
                    join(path, "signal"), None, f"{plant.name} has several outputs; name one of: {', '.join(outputs)}"
                )
            return 0
        if cfg.signal not in outputs:
            raise ConfigError(
                join(path, "signal"),
                cfg.signal,
                f"not an output of {plant.name}{did_you_mean(cfg.signal, outputs)}; allowed: {', '.join(outputs)}",
            )
        return outputs.index(cfg.signal)

    def design(self, cfg: PreviewConfig, plant: Plant, path: str = "controller") -> PreviewDesign:
        """The gains for ``plant`` under ``cfg``."""
        out = self.tracked_output(cfg, plant, path)
        model = linear_model(plant, cfg.sample_time, out, path)
        try:
            return design_preview(
                model,
                design=cfg.design,
                h=cfg.preview,
                q=cfg.q,
                r=cfg.r,
                integral=cfg.integral or None,
                disturbance=cfg.disturbance,
                gamma_tolerance=cfg.gamma_tolerance,
                gamma_factor=cfg.gamma_factor,
            )
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise ConfigError(
                join(path, "design"), cfg.design, f"no stabilising preview controller for {plant.name}: {exc}"
            ) from None

    def build(
        self, label: str, cfg: PreviewConfig, plant: Plant, path: str, dt: float | None = None
    ) -> ControllerInstance:
        if dt is not None:
            check_sample_time(cfg.sample_time, dt, path)
        d = self.design(cfg, plant, path)
        model, aug = d.model, d.aug
        n, m, h = aug.n, aug.m, aug.h
        Kv = d.Kx[:, n] if aug.integrator else np.zeros(m)
        cp = np.concatenate(
            [
                PREVIEW.pack(n=n, m=m, h=h, integrator=aug.integrator, sample_time=cfg.sample_time, y_eq=model.y_eq),
                model.x_eq,
                model.u_eq,
                model.c,
                d.Kx[:, :n].ravel(),
                Kv,
                d.Kd.ravel(),
            ]
        ).astype(float)
        signal = plant.output_names[self.tracked_output(cfg, plant, path)]
        log_names: list[str] = []
        log_units: list[str] = []
        for name in plant.input_names:
            suffix = "" if m == 1 else f".{name}"
            unit = plant.unit_of(name)
            log_names += [f"u{suffix}", f"preview{suffix}", f"feedback{suffix}"]
            log_units += [unit, unit, unit]
        unit_y = plant.unit_of(signal)
        log_names.append("integral")
        log_units.append(f"{unit_y}*s" if unit_y else "s")
        config = cfg.model_dump()
        records: dict[str, object] = {"design": cfg.design, "preview": h, "sample_time": cfg.sample_time}
        if cfg.design == "hinf":
            records.update(gamma=d.gamma, gamma_min=d.gamma_min)
        records.update({f"Kx[{i}]": float(v) for i, v in enumerate(np.ravel(d.Kx))})
        records.update({f"Kd[{i}]": float(v) for i, v in enumerate(np.ravel(d.Kd))})
        return ControllerInstance(
            label=label,
            kind="preview",
            step=self.step,
            cp=np.ascontiguousarray(cp),
            cs0=np.zeros(STATE_HEAD + LOG_SIZE * m),
            reference_signals=(signal,) * (h + 1),
            reference_offsets=tuple(i * cfg.sample_time for i in range(h + 1)),
            log_names=tuple(log_names),
            log_units=tuple(log_units),
            config=config,
            records=records,
        )

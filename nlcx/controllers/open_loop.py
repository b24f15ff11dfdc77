"""Open loop: the plant input is the reference (u = r), for exercising plants."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from nlcx._numba_compat import hot_njit
from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel
from nlcx.kernel.signatures import Callbacks, FloatArray
from nlcx.plants.base import Plant


class OpenLoopConfig(ControllerConfig):
    kind: Literal["open_loop"] = Field(
        "open_loop", description="registered name of this controller; selects the model that validates this section"
    )


@hot_njit(cache=True, error_model="numpy")
def open_loop_step(
    t: float,
    dt: float,
    x: FloatArray,
    y: FloatArray,
    r: FloatArray,
    cp: FloatArray,
    cs: FloatArray,
    u: FloatArray,
    log: FloatArray,
    callbacks: Callbacks,
) -> None:  # pragma: no cover - compiled
    """u_j(t) = r_j(t): the reference channels are the plant inputs (every row)."""
    for b in range(u.shape[0]):
        for j in range(u.shape[1]):
            u[b, j] = r[b, j]


class OpenLoop(ControllerModel):
    """Open loop u = r; the references are named after the plant's inputs."""

    Config = OpenLoopConfig
    step = staticmethod(open_loop_step)

    def build(
        self, label: str, cfg: OpenLoopConfig, plant: Plant, path: str, dt: float | None = None
    ) -> ControllerInstance:
        return ControllerInstance(
            label=label,
            kind="open_loop",
            step=self.step,
            cp=np.zeros(1),
            cs0=np.zeros(1),
            reference_signals=tuple(plant.input_names),
            config=cfg.model_dump(),
        )

"""What a reference is: r(t) on the sampling grid, and how its signal should be measured."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict


class ReferenceConfig(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    kind: str


@dataclass(frozen=True)
class SignalPlan:
    """How a signal following this reference is measured (see docs/metrics.md).

    ``step``: step-response metrics from ``initial`` to ``final`` at ``t_step``;
    ``regulation``: held at the constant ``final`` (peak deviation, settling);
    ``tracking``: error integrals only.
    """

    kind: Literal["step", "regulation", "tracking"]
    final: float = 0.0
    t_step: float = 0.0


class ReferenceModel:
    """A registered reference. Subclasses set ``Config`` and implement :meth:`values`."""

    Config: ClassVar[type[ReferenceConfig]] = ReferenceConfig

    def values(self, cfg: Any, t: np.ndarray) -> np.ndarray:
        """r(t) at the times ``t``."""
        raise NotImplementedError

    def signal_plan(self, cfg: Any) -> SignalPlan:
        return SignalPlan("tracking")

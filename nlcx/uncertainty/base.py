"""What an uncertainty is: a contribution to the perturbation terms the kernel applies."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from nlcx.plants.base import Plant


class UncertaintyConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: str


@dataclass
class Perturbations:
    """The perturbation terms of one run, collected from the configured uncertainties.

    ``stage_times`` has shape (K, s): the times t_k + c_i dt at which the integrator
    evaluates the right-hand side; disturbances are sampled there.
    """

    plant: Plant
    t: np.ndarray
    stage_times: np.ndarray
    rng: np.random.Generator
    dist_columns: list[np.ndarray] = field(default_factory=list)
    dist_values: list[np.ndarray] = field(default_factory=list)
    noise_y: np.ndarray | None = None
    noise_u: np.ndarray | None = None
    #: (n_u, FRICTION_FIELDS) friction of each input's axis, see nlcx.kernel.
    friction: np.ndarray | None = None

    def add_disturbance(self, column: np.ndarray, values: np.ndarray) -> None:
        """Add d(t) (sampled at ``stage_times``) times ``column`` to dx/dt."""
        self.dist_columns.append(np.asarray(column, dtype=float))
        self.dist_values.append(np.asarray(values, dtype=float))

    def add_noise(self, where: str, values: np.ndarray) -> None:
        """Add a noise sequence (K+1, n_y) to the measurements or (K+1, n_u) to the inputs."""
        if where == "measurement":
            self.noise_y = values if self.noise_y is None else self.noise_y + values
        else:
            self.noise_u = values if self.noise_u is None else self.noise_u + values

    def dist_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(dist (1, K, s, n_d), dist_map (n, n_d)) for the kernel."""
        n = len(self.plant.states)
        n_s = self.stage_times.shape[1]
        if not self.dist_columns:
            return np.zeros((1, 1, n_s, 0)), np.zeros((n, 0))
        dist = np.stack(self.dist_values, axis=-1)[None]
        return np.ascontiguousarray(dist), np.ascontiguousarray(np.stack(self.dist_columns, axis=-1))


class UncertaintyModel:
    """A registered uncertainty. Subclasses set ``Config`` and implement :meth:`apply`."""

    Config: ClassVar[type[UncertaintyConfig]] = UncertaintyConfig

    def apply(self, cfg: Any, perturbations: Perturbations, path: str) -> None:
        raise NotImplementedError

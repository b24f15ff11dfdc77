"""What an uncertainty or loop element is: something it adds to the closed loop at a hook point.

The signal path has four places where an uncertainty or loop element can act
(docs/architecture.md)::

    x --C--> y --[sensor]--> controller --> u --[actuator]--> plant: f(t, x, u + forces) + derivative terms

- **sensor** and **actuator** elements are compiled functions (:data:`nlcx.kernel.abi.ELEMENT_SIG`)
  with their own parameters, state and time series; any number, in the order they are added
  (measurement noise, a quantiser, control-output noise, a dead zone, ...).
- **derivative terms** d(t) sampled at the Runge-Kutta stage times and added to chosen state
  derivatives (the thesis's disturbance, eqs. 2.13/2.15).
- **plant force**: friction on the axis of each input (Appendix A, :mod:`nlcx.kernel.friction`).

A registered uncertainty (or loop element) implements :meth:`UncertaintyModel.apply`, which
adds to a :class:`Hooks` collector.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from nlcx.kernel.abi import HOOKS
from nlcx.plants.base import Plant


class UncertaintyConfig(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    kind: str


@dataclass
class Element:
    """One loop element at a hook point: its compiled function and the numbers it reads.

    ``params`` and ``state`` are this run's blocks (the element's own layout); ``data`` is a
    time series (K+1, n_cols), one row per sampling instant, or None."""

    hook: str
    function: Any
    params: np.ndarray = field(default_factory=lambda: np.zeros(0))
    state: np.ndarray = field(default_factory=lambda: np.zeros(0))
    data: np.ndarray | None = None
    name: str = ""

    def __post_init__(self) -> None:
        if self.hook not in HOOKS:
            raise ValueError(f"element {self.name!r}: hook {self.hook!r}; allowed: {', '.join(HOOKS)}")


@dataclass
class Hooks:
    """What the uncertainties and loop elements of one run add to its closed loop.

    ``t`` are the sampling instants; ``stage_times`` (K, s) the times t_k + c_i dt at which
    the integrator evaluates the right-hand side (derivative terms are sampled there).
    """

    plant: Plant
    t: np.ndarray
    stage_times: np.ndarray
    #: The random generator of the uncertainty being applied (set before each one's ``apply``).
    rng: np.random.Generator | None = None
    elements: list[Element] = field(default_factory=list)
    dist_columns: list[np.ndarray] = field(default_factory=list)
    dist_values: list[np.ndarray] = field(default_factory=list)
    #: (n_u, FRICTION_AXIS.size) friction of each input's axis, see nlcx.kernel.friction.
    friction: np.ndarray | None = None

    def add_element(self, element: Element) -> None:
        """Add a sensor or actuator element; elements at one hook act in the order added."""
        self.elements.append(element)

    def add_disturbance(self, column: np.ndarray, values: np.ndarray) -> None:
        """Add d(t) (sampled at ``stage_times``) times ``column`` to dx/dt."""
        self.dist_columns.append(np.asarray(column, dtype=float))
        self.dist_values.append(np.asarray(values, dtype=float))

    def set_friction(self, axes: np.ndarray) -> None:
        """The friction of each input's axis (one FRICTION_AXIS block per input)."""
        self.friction = axes

    def dist_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(dist (1, K, s, n_d), dist_map (n, n_d)) for the kernel."""
        n = len(self.plant.states)
        n_s = self.stage_times.shape[1]
        if not self.dist_columns:
            return np.zeros((1, 1, n_s, 0)), np.zeros((n, 0))
        dist = np.stack(self.dist_values, axis=-1)[None]
        return np.ascontiguousarray(dist), np.ascontiguousarray(np.stack(self.dist_columns, axis=-1))

    def element_data(self) -> np.ndarray | None:
        """The elements' time series side by side (K+1, n_cols), or None when no element has one."""
        series = [e.data for e in self.elements if e.data is not None]
        return np.ascontiguousarray(np.concatenate(series, axis=1)) if series else None


class UncertaintyModel:
    """A registered uncertainty or loop element. Subclasses set ``Config`` and implement :meth:`apply`."""

    Config: ClassVar[type[UncertaintyConfig]] = UncertaintyConfig

    def apply(self, cfg: Any, hooks: Hooks, path: str) -> None:
        """Add this uncertainty's elements, derivative terms or forces to ``hooks``."""
        raise NotImplementedError

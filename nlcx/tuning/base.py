"""What a tuner is: a step that fills in a controller's numbers before the run.

A controller section may list tuners under ``tune:``, applied in order, e.g.::

    controllers:
      zn:
        kind: pid
        tune: [{kind: ziegler_nichols, rule: pid}]
        loops: {y: {schedule: {kind: constant}}}

Each tuner receives the controller's configuration (a plain mapping), returns the updated
mapping and the rows it wants recorded in the run's ``tuning.csv`` (controller, tuner,
parameter, value). Tuners can leave results for the next tuner in ``TuneContext.shared``
(the Ziegler-Nichols gains, for instance, that the fuzzy ranges and the ANFIS teacher use).

A tuner that needs to simulate calls ``TuneContext.simulate`` (the engine's
:class:`~nlcx.engine.LoopSimulator`): the experiment's plant, references and uncertainties
under the controllers it passes, through the same batched pipeline as ``nlcx run``. Tuners
import neither the engine nor the config loader.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from pydantic import BaseModel, ConfigDict

from nlcx.errors import ConfigError
from nlcx.plants.base import Plant

if TYPE_CHECKING:
    import numpy as np

    from nlcx.controllers.base import ControllerInstance


class TunerConfig(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    kind: str


class SimulatedRun(Protocol):
    """What a tuner reads of one simulated run (:class:`nlcx.engine.Run`)."""

    @property
    def controller(self) -> ControllerInstance: ...
    @property
    def status(self) -> str: ...
    @property
    def t(self) -> np.ndarray: ...
    @property
    def x(self) -> np.ndarray: ...
    @property
    def r(self) -> np.ndarray: ...


class SimulatedSetup(Protocol):
    """What a tuner reads of a simulated experiment as prepared (:class:`nlcx.engine.Prepared`)."""

    @property
    def plant(self) -> Plant: ...


class Simulation(Protocol):
    """What a tuner reads of a simulation's result (:class:`nlcx.engine.ExperimentResult`)."""

    @property
    def runs(self) -> Sequence[SimulatedRun]: ...
    @property
    def prepared(self) -> SimulatedSetup: ...


class Simulate(Protocol):
    """Simulate the experiment under ``controllers`` (label -> configuration); returns a result
    with ``runs`` (one per controller, in order), ``prepared.plant`` and ``metrics``."""

    def __call__(
        self,
        controllers: Mapping[str, Mapping[str, object]],
        simulation: Mapping[str, object] | None = None,
        uncertainty: Mapping[str, object] | None = None,
        measure: bool = True,
    ) -> Simulation: ...


@dataclass
class TuneContext:
    """What a tuner may use: the built plant, the simulation step, a way to simulate the
    experiment under other controllers, and the results of earlier tuners."""

    plant: Plant
    label: str
    path: str
    dt: float
    simulate: Simulate
    #: Named numbers an earlier tuner found, by its name for them (``zn``: K_u, T_u and the gains).
    shared: dict[str, dict[str, float]] = field(default_factory=dict)
    #: Rows of tuning.csv: controller, tuner, parameter, value.
    rows: list[dict[str, object]] = field(default_factory=list)

    def record(self, tuner: str, parameter: str, value: object) -> None:
        self.rows.append({"controller": self.label, "tuner": tuner, "parameter": parameter, "value": value})


class TunerModel:
    """A registered tuner. Subclasses set ``Config`` and implement :meth:`tune`."""

    Config: ClassVar[type[TunerConfig]] = TunerConfig

    def tune(self, controller: dict[str, Any], cfg: Any, ctx: TuneContext) -> dict[str, Any]:
        raise NotImplementedError


def single_loop(controller: dict[str, Any], ctx: TuneContext, tuner: str) -> tuple[str, dict[str, Any]]:
    """The one loop of a SISO PID that a tuner fills in."""
    if controller.get("kind") != "pid":
        raise ConfigError(f"{ctx.path}.kind", controller.get("kind"), f"the {tuner} tuner tunes a pid controller")
    loops = controller.get("loops") or {}
    if len(loops) != 1:
        raise ConfigError(f"{ctx.path}.loops", list(loops), f"the {tuner} tuner needs exactly one loop (a SISO PID)")
    key = next(iter(loops))
    return key, loops[key]

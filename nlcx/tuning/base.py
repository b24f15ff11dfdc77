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
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict

from nlcx.errors import ConfigError


class TunerConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: str


@dataclass
class TuneContext:
    """What a tuner may use: the experiment, the built plant, and the results of earlier tuners."""

    experiment: Any
    plant: Any
    label: str
    path: str
    shared: dict[str, Any] = field(default_factory=dict)
    rows: list[dict[str, Any]] = field(default_factory=list)

    def record(self, tuner: str, parameter: str, value: Any) -> None:
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


def simulate_alone(experiment: Any, label: str, controller: dict[str, Any], **simulation: Any) -> tuple[Any, Any]:
    """(run, plant): the experiment with only ``controller`` (no tuners), e.g. the ZN loop.

    ``simulation`` overrides keys of the simulation section (t_end, ...).
    """
    import copy

    from nlcx import config as cfg
    from nlcx import engine

    raw = copy.deepcopy(experiment.raw)
    raw["controllers"] = {label: {k: v for k, v in controller.items() if k != "tune"}}
    raw.setdefault("simulation", {}).update(simulation)
    result = engine.run_experiment(cfg.build(raw))
    return result.runs[0], result.prepared.plant

"""The pipeline: experiments to trajectories and metrics, and the tuners' way back into it.

:func:`evaluate` takes experiments (or prepared ones) through :func:`prepare`, the kernel
(:mod:`nlcx.engine.simulate`) and the metrics (:mod:`nlcx.engine.measure`). A controller with
tuners is tuned while its experiment is prepared; its tuners simulate through a
:class:`LoopSimulator`, which calls :func:`evaluate` again: the two live here together.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

from nlcx import preflight
from nlcx.config import Experiment, MetricsSection, PluginSection, build, controller_section
from nlcx.engine.measure import controller_records, measure_experiments
from nlcx.engine.prepared import Prepared, check_memory, perturbations, reference_models, time_grid
from nlcx.engine.results import ExperimentResult, MetricBlock, Run
from nlcx.engine.simulate import simulate_experiments
from nlcx.plants.base import Plant
from nlcx.tuning.base import TuneContext

if TYPE_CHECKING:
    from nlcx.protocols import ControllerPlugin


def evaluate(
    experiments: Sequence[Experiment | Prepared],
    record_logs: bool = True,
    measure: bool = True,
) -> list[ExperimentResult]:
    """The pipeline: experiments (or prepared ones) to trajectories and metrics, batched.

    Every closed loop of every experiment on the same time grid goes through the kernel
    together (:func:`~nlcx.engine.simulate.simulate_items`), and the runs are measured together
    (:func:`~nlcx.engine.measure.measure_runs`). ``nlcx run``, sweeps, tuners (through
    :class:`LoopSimulator`), the calibration and the thesis reproduction all come through here.
    ``record_logs=False`` skips controller logs and friction forces; ``measure=False`` leaves
    the metrics empty (a tuner scoring runs itself).
    Timings are per experiment; a shared kernel call, and the measuring, are split evenly
    between their experiments.
    """
    prepared, timings = [], []
    for exp in experiments:
        start = time.perf_counter()
        prepared.append(exp if isinstance(exp, Prepared) else prepare(exp))
        timings.append({"prepare": time.perf_counter() - start})
    runs = simulate_experiments(prepared, record_logs, timings)
    start = time.perf_counter()
    blocks = measure_experiments(prepared, runs) if measure else [None] * len(prepared)
    for timing in timings:
        timing["metrics"] = (time.perf_counter() - start) / len(prepared)
    return [_result(p, rs, block, timing) for p, rs, block, timing in zip(prepared, runs, blocks, timings, strict=True)]


def _result(
    prepared: Prepared, runs: list[Run], block: MetricBlock | None, timings: dict[str, float]
) -> ExperimentResult:
    """An experiment's result; its tuning rows gain what its controllers report themselves."""
    prepared.tuning = [*prepared.tuning, *(row for run in runs for row in controller_records(run))]
    return ExperimentResult(prepared=prepared, runs=runs, rows=block, timings=timings)


def prepare(exp: Experiment) -> Prepared:
    """Build the plant, controllers (tuned first, where they have tuners), references and
    perturbations of ``exp``."""
    sec = exp.section
    sim = sec.simulation
    plant = exp.plant_model.build(sec.plant.name, exp.plant_params, sec.plant.x0, sim.bounds)
    preflight.check_signal_names(plant)
    references = reference_models(exp, plant)
    tuning: list[dict[str, object]] = []
    controllers = []
    for c in exp.controllers:
        section = _tuned_section(exp, c, plant, tuning)
        controllers.append(section.model.build(c.label, section.config, plant, f"controllers.{c.label}", dt=sim.dt))
    preflight.check_references(exp.references, exp.references, plant, controllers)
    preflight.check_reference_times(exp.references, sim.t_end, sim.dt)
    check_memory(exp, plant, [len(c.reference_signals) + len(c.log_names) for c in controllers])
    grid = time_grid(sim.t_end, sim.dt, sim.integrator)
    seed_sequence = np.random.SeedSequence(sec.seed)
    return Prepared(
        experiment=exp,
        plant=plant,
        controllers=controllers,
        tuning=tuning,
        references=references,
        grid=grid,
        hooks=perturbations(exp, plant, grid, seed_sequence),
        seed_sequence=seed_sequence,
    )


def _tuned_section(
    exp: Experiment, c: PluginSection[ControllerPlugin], plant: Plant, rows: list[dict[str, object]]
) -> PluginSection[ControllerPlugin]:
    """The controller section of ``c`` after its tuners (in order) filled in its numbers; their
    rows of tuning.csv are appended to ``rows``."""
    if not c.tuners:
        return c
    path = f"controllers.{c.label}"
    ctx = TuneContext(
        plant=plant, label=c.label, path=path, dt=exp.section.simulation.dt, simulate=LoopSimulator(exp.raw)
    )
    data = c.config.model_dump()
    for tuner in c.tuners:
        data = tuner.model.tune(data, tuner.config, ctx)
    rows += ctx.rows
    return controller_section(c.label, data, path)


def remeasure(results: Sequence[ExperimentResult], metrics: Mapping[str, object]) -> list[ExperimentResult]:
    """The runs of ``results`` (one :func:`evaluate` call) measured again under other metric
    definitions, without simulating them again: ``metrics`` updates the metrics section of
    every experiment (e.g. ``{"rise_limits": [0, 1], "settling_band": 0.05}``)."""
    prepared = []
    for r in results:
        section = r.prepared.experiment.section
        defined = MetricsSection.model_validate({**section.metrics.model_dump(), **metrics})
        experiment = dataclasses.replace(r.prepared.experiment, section=section.model_copy(update={"metrics": defined}))
        prepared.append(dataclasses.replace(r.prepared, experiment=experiment))
    blocks = measure_experiments(prepared, [r.runs for r in results])
    return [dataclasses.replace(r, prepared=p, rows=b) for r, p, b in zip(results, prepared, blocks, strict=True)]


def run_experiment(exp: Experiment | Prepared) -> ExperimentResult:
    """Prepare (unless prepared already), simulate and measure one experiment (:func:`evaluate`
    of one); timings in seconds."""
    (result,) = evaluate([exp])
    return result


@dataclass(frozen=True)
class LoopSimulator:
    """An experiment's plant, references and uncertainties under other controllers: what a
    tuner simulates (:attr:`nlcx.tuning.base.TuneContext.simulate`). Picklable, so a tuner can
    hand it to a process pool.

    ``controllers`` maps labels to controller configurations (their ``tune`` lists are
    dropped); ``simulation`` updates keys of the simulation section; ``uncertainty``, when
    given, replaces the uncertainty section (``{}``: the nominal plant).
    """

    raw: dict[str, object]

    def __call__(
        self,
        controllers: Mapping[str, Mapping[str, object]],
        simulation: Mapping[str, object] | None = None,
        uncertainty: Mapping[str, object] | None = None,
        measure: bool = True,
    ) -> ExperimentResult:
        raw = copy.deepcopy(self.raw)
        raw["controllers"] = {label: {k: v for k, v in c.items() if k != "tune"} for label, c in controllers.items()}
        # a mapping: the experiment was validated from ``raw``
        cast(dict[str, object], raw.setdefault("simulation", {})).update(simulation or {})
        if uncertainty is not None:
            raw["uncertainty"] = dict(uncertainty)
        (result,) = evaluate([build(raw)], measure=measure)
        return result

"""The question the thesis did not ask: AGS PID against well-designed baselines (``nlcx baselines``).

The four pendulums (x, x-y, x-z, x-y-z) under the thesis's conventional PID, its time- and
error-AGS PID, an LQR with integral action and, for the x pendulum (the one with a published
design), sliding-mode control; in the thesis's scenarios (nominal, the sinusoidal disturbance,
measurement noise with the disturbance, simple friction), and in a sweep of the plant's
masses and length within +-20 % of Table 2.1 (:data:`VARIANTS` random variants a pendulum).
The configs are generated (``scripts/make_baseline_configs.py``) from the thesis's own
building blocks and from the design rule of this module, stated before any run:

- the LQR's weights by Bryson's rule (:func:`bryson`): Q_ii = 1 / (the largest acceptable
  value of state i)^2, R_jj = 1 / (the largest acceptable force)^2, with :data:`ACCEPTABLE`;
  integral action on every position with a step reference;
- the sliding surface of the x pendulum (:mod:`nlcx.controllers.sliding_mode`) placing the
  motion on it at the three slowest closed-loop poles of that LQR without its integrator, so
  that both aim at the same speed of response (:func:`sliding_surface`), and the reaching and
  switching gains and the boundary layer of :data:`SWITCHING`;
- every design on the nominal plant (Table 2.1) and frozen there: the sweep tests one
  controller against many plants.

:func:`run` simulates every scenario config and sweeps every pendulum, and writes one
directory: ``runs/<config>/`` (each run's files), ``sweeps/<pendulum>/`` (each sweep),
``tables/comparison.csv`` (pendulum, scenario, controller, signal, metric, value, unit,
status), ``tables/robustness.csv`` (per pendulum, controller, signal and metric over the
sweep: the variants, the share that stayed stable, median, quartiles, min, max) and the report.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np
import pandas as pd

from nlcx.errors import ConfigError

if TYPE_CHECKING:
    from nlcx.plants.base import Plant

__all__ = [
    "ACCEPTABLE",
    "PENDULUMS",
    "SCENARIOS",
    "SWITCHING",
    "VARIANTS",
    "bryson",
    "comparison",
    "robustness",
    "run",
    "sliding_surface",
]

#: Pendulum key -> registered plant.
PENDULUMS = {"x": "x_pendulum", "xy": "xy_pendulum", "xz": "xz_pendulum", "xyz": "xyz_pendulum"}
#: Scenario -> the thesis's uncertainty block it adds (configs/thesis/uncertainty/), or None.
SCENARIOS = {
    "nominal": None,
    "disturbance": "disturbance.yaml",
    "noise": "noise.yaml",
    "friction": "simple_friction.yaml",
}
#: Variants of each pendulum's robustness sweep (M, m and l uniform within +-20 %).
VARIANTS = 200
#: Bryson's rule: the largest acceptable value of each kind of state, and of a force. A
#: position's is the unit step itself, a speed one step a second, an angle 0.2 rad (the
#: thesis's angle responses peak below it), an integral of the position error 1 m s, and a
#: force the weight of cart and pendulum, (M + m) g = 10.8 N, rounded to 10 N.
ACCEPTABLE = {"position": 1.0, "velocity": 1.0, "angle": 0.2, "angular_rate": 1.0, "integral": 1.0, "force": 10.0}
#: The sliding-mode controller's reaching rate kappa (1/s), switching gain eta and boundary
#: layer phi (eq. 2 of :mod:`nlcx.controllers.sliding_mode`): a reaching time constant of
#: 0.5 s, a switching term of 0.5 (units of dS/dt) and a layer of 0.05.
SWITCHING = {"kappa": 2.0, "eta": 0.5, "phi": 0.05}
#: Coordinates by kind (the states' names are the coordinate and its ``_dot``).
POSITIONS, ANGLES = ("x", "y", "z"), ("theta", "phi")


def _kind(state: str) -> str:
    """A pendulum state's kind for :data:`ACCEPTABLE`."""
    coordinate, dot = state.removesuffix("_dot"), state.endswith("_dot")
    if coordinate in POSITIONS:
        return "velocity" if dot else "position"
    if coordinate in ANGLES:
        return "angular_rate" if dot else "angle"
    raise ConfigError("plant", state, f"a pendulum's state ({', '.join(POSITIONS + ANGLES)} and their _dot)")


class BrysonWeights(TypedDict):
    """An LQR controller section weighted by Bryson's rule (:func:`bryson`)."""

    kind: str
    integral: list[str]
    q: list[float]
    r: list[float]


def bryson(states: Sequence[str], inputs: Sequence[str], references: Sequence[str]) -> BrysonWeights:
    """The LQR section of Bryson's rule for a pendulum: q per state, then per integrator of each
    position with a step reference (``references``), r per input."""
    integral = [s for s in states if s in POSITIONS and s in references]
    q = [_weight(ACCEPTABLE[_kind(s)]) for s in states] + [_weight(ACCEPTABLE["integral"])] * len(integral)
    return {"kind": "lqr", "integral": integral, "q": q, "r": [_weight(ACCEPTABLE["force"])] * len(inputs)}


def _weight(acceptable: float) -> float:
    """Bryson's weight 1 / acceptable^2, to 12 significant digits (1 / 0.2^2 is 25, not 24.999...)."""
    return float(f"{1.0 / acceptable**2:.12g}")


def sliding_surface(plant: Plant) -> dict[str, float]:
    """(c1, c2, alpha) of the x pendulum's sliding surface: the motion on it, linearised, at the
    three slowest closed-loop poles of Bryson's LQR without its integrator (:func:`bryson`)."""
    import control as ct

    from nlcx.analysis.linear import plant_system
    from nlcx.controllers.sliding_mode import surface_for_poles

    linear = plant_system(plant)
    weights = bryson(plant.state_names, plant.input_names, ())
    _, _, poles = ct.lqr(linear.A, linear.B, np.diag(weights["q"]), np.diag(weights["r"]))
    slowest = sorted(poles, key=lambda p: -p.real)[:3]
    return surface_for_poles(linear.A, linear.B, slowest)


def _frame(result: Any, pendulum: str, scenario: str) -> pd.DataFrame:
    """A run's metrics with its pendulum and scenario in front."""
    metrics = result.metrics if isinstance(result.metrics, pd.DataFrame) else pd.DataFrame(result.metrics)
    return metrics.assign(pendulum=pendulum, scenario=scenario)[
        ["pendulum", "scenario", "controller", "signal", "metric", "value", "unit", "status"]
    ]


def comparison(frames: Sequence[pd.DataFrame]) -> pd.DataFrame:
    """tables/comparison.csv: every scenario's metrics, long form."""
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def robustness(pendulum: str, variants: pd.DataFrame, metrics: pd.DataFrame) -> pd.DataFrame:
    """tables/robustness.csv's rows of one pendulum's sweep: per controller, signal and metric,
    the variants, the share of them whose run of the controller stayed stable (the others
    stopped: ``unstable``; a variant that failed as a whole has no run and counts as not stable),
    and the median, quartiles, min and max of the metric over the stable ones."""
    rows = []
    n = len(variants)
    share = {}
    for controller, group in metrics.groupby("controller", sort=False):
        ran, stopped = set(group.variant), set(group.variant[group.status != "ok"])
        share[controller] = len(ran - stopped) / n if n else np.nan
    measured = metrics[metrics.signal != "all"]  # a stopped run's failure time is no metric of the controller
    for (controller, signal, metric), group in measured.groupby(["controller", "signal", "metric"], sort=False):
        stable = group[group.status == "ok"]
        values = stable.value.to_numpy(dtype=float)
        values = values[np.isfinite(values)]
        q25, median, q75 = np.percentile(values, [25, 50, 75]) if values.size else (np.nan,) * 3
        rows.append({
            "pendulum": pendulum, "controller": controller, "signal": signal, "metric": metric,
            "variants": n, "stable_share": share[controller],
            "median": median, "q25": q25, "q75": q75,
            "min": values.min() if values.size else np.nan, "max": values.max() if values.size else np.nan,
        })  # fmt: skip
    return pd.DataFrame(rows)


def check_pendulums(pendulums: Sequence[str]) -> None:
    """Refuse (one line naming ``--only``) a pendulum the study does not know, or none at all."""
    unknown = [p for p in pendulums if p not in PENDULUMS]
    if unknown or not pendulums:
        raise ConfigError("--only", unknown[0] if unknown else "", f"a pendulum; allowed: {', '.join(PENDULUMS)}")


def configs_of(root: Path, pendulums: Sequence[str]) -> list[tuple[str, str, Path]]:
    """(pendulum, scenario, config) of every scenario config under ``root`` for ``pendulums``."""
    found = []
    for pendulum in pendulums:
        for scenario in SCENARIOS:
            path = root / f"{pendulum}_{scenario}.yaml"
            if not path.is_file():
                raise ConfigError("--configs", str(root), f"the baseline configs; {path.name} is missing")
            found.append((pendulum, scenario, path))
    return found


def run(
    root: Path,
    out: Path,
    *,
    pendulums: Sequence[str] = tuple(PENDULUMS),
    variants: int = VARIANTS,
    jobs: int = 2,
    overrides: Sequence[str] = (),
    progress: Callable[[str, float], None] | None = None,
) -> dict[str, pd.DataFrame]:
    """Run every scenario and sweep of ``pendulums`` from the configs in ``root`` into ``out``
    (as it stands: ``nlcx baselines`` hands it a staged directory); ``variants`` per sweep;
    ``overrides`` for every config (e.g. a shorter ``simulation.t_end``). The tables."""
    from nlcx import config as cfg
    from nlcx import engine, report
    from nlcx import sweeps as sweep_runs
    from nlcx.results import read_output_table

    check_pendulums(pendulums)
    frames, spreads = [], []
    for pendulum, scenario, path in configs_of(root, pendulums):
        start = time.perf_counter()
        applied = [*overrides, "outputs.figure=false"]
        result = engine.run_experiment(cfg.load(path, applied))
        report.write_run(result, out / "runs" / f"{pendulum}_{scenario}", result.timings, started=start,
                         overrides=applied)  # fmt: skip
        frames.append(_frame(result, pendulum, scenario))
        if progress is not None:
            progress(f"{pendulum} {scenario}", time.perf_counter() - start)
    for pendulum in pendulums:
        start = time.perf_counter()
        target = out / "sweeps" / pendulum
        sweep_overrides = [*overrides, "outputs.figure=false", f"sweep.random.n={variants}"]
        sweep_runs.run(root / f"{pendulum}_robustness.yaml", sweep_overrides, target, jobs=jobs, with_report=False)
        spreads.append(robustness(pendulum, read_output_table(target, "sweep"), read_output_table(target, "metrics")))
        if progress is not None:
            progress(f"{pendulum} robustness ({variants} variants)", time.perf_counter() - start)
    tables = {"comparison": comparison(frames), "robustness": pd.concat(spreads, ignore_index=True)}
    for name, table in tables.items():
        report.write_csv(out / "tables" / f"{name}.csv", table)
    return tables

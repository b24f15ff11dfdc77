"""The evolutionary optimiser every nlcx tuner uses: pymoo's genetic algorithm, seeded.

The objective is evaluated a whole population at a time (``objective(X) -> f`` with X of
shape (P, n)), which lets the batched kernel simulate every candidate in one call. With
``jobs > 1`` the population is split across a process pool; the result is the same as the
serial one because each candidate's loss depends only on the candidate.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

Objective = Callable[[np.ndarray], np.ndarray]


class GASettings(BaseModel):
    """Settings of the genetic algorithm (recorded with every tuning result)."""

    model_config = ConfigDict(extra="forbid")
    kind: str = Field("ga", description="the optimiser: ga (pymoo's genetic algorithm)")
    pop_size: int = Field(40, ge=4, description="population size")
    generations: int = Field(30, ge=1, description="generations evolved")
    seed: int = Field(1, ge=0, description="seed of the GA's random draws (same seed, same result)")
    crossover_eta: float = Field(
        15.0, gt=0, description="distribution index of the simulated binary crossover (pymoo's default)"
    )
    crossover_prob: float = Field(
        0.9, ge=0, le=1, description="probability of the simulated binary crossover (pymoo's default)"
    )
    mutation_eta: float = Field(20.0, gt=0, description="distribution index of the polynomial mutation")


def check_search_box(
    bounds: dict[str, tuple[float, float]], prefixes: tuple[str, ...], refusal: str
) -> dict[str, tuple[float, float]]:
    """Validate a search box of config keys: lower < upper, every key starting with one of
    ``prefixes`` (``refusal`` says which keys may be searched)."""
    for key, (lo, hi) in bounds.items():
        if not lo < hi:
            raise ValueError(f"bounds of {key} must be [lower, upper] with lower < upper")
        if not key.startswith(prefixes):
            raise ValueError(f"{key}: {refusal}")
    return bounds


@dataclass
class OptimResult:
    x: np.ndarray
    f: float
    history: list[tuple[int, int, float]] = field(default_factory=list)
    evaluations: int = 0


def split_evaluate(objective: Objective, X: np.ndarray, executor: Executor | None, chunks: int) -> np.ndarray:
    """objective over the rows of X, in ``chunks`` pieces on ``executor`` (or here)."""
    if executor is None or chunks <= 1 or len(X) < 2:
        return np.asarray(objective(X), dtype=float)
    parts = np.array_split(X, min(chunks, len(X)))
    return np.concatenate([np.asarray(r, dtype=float) for r in executor.map(objective, parts)])


def evolve(
    objective: Objective,
    lower: np.ndarray,
    upper: np.ndarray,
    settings: GASettings,
    executor: Executor | None = None,
    chunks: int = 1,
    callback: Callable[[int, float], None] | None = None,
    start: np.ndarray | None = None,
) -> OptimResult:
    """Minimise ``objective`` over the box [lower, upper] with pymoo's GA. ``start`` (rows of
    candidates) seeds the first population; the rest of it is drawn uniformly in the box from
    the seed (without ``start``, pymoo's own random sampling)."""
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.core.problem import Problem
    from pymoo.operators.crossover.sbx import SBX
    from pymoo.operators.mutation.pm import PM
    from pymoo.operators.sampling.rnd import FloatRandomSampling
    from pymoo.optimize import minimize

    history: list[tuple[int, int, float]] = []
    count = [0]

    class _Problem(Problem):
        def __init__(self) -> None:
            super().__init__(n_var=len(lower), n_obj=1, xl=np.asarray(lower), xu=np.asarray(upper))

        def _evaluate(self, X: np.ndarray, out: dict[str, Any], *args: Any, **kwargs: Any) -> None:
            f = split_evaluate(objective, np.ascontiguousarray(X), executor, chunks)
            count[0] += len(X)
            out["F"] = f[:, None]

    def record(algorithm: Any) -> None:
        best = float(algorithm.opt.get("F").min())
        history.append((algorithm.n_gen, count[0], best))
        if callback is not None:
            callback(algorithm.n_gen, best)

    algorithm = GA(
        pop_size=settings.pop_size,
        sampling=_first_population(start, lower, upper, settings) if start is not None else FloatRandomSampling(),
        crossover=SBX(eta=settings.crossover_eta, prob=settings.crossover_prob),
        mutation=PM(eta=settings.mutation_eta),
        eliminate_duplicates=True,
    )
    res = minimize(
        _Problem(), algorithm, ("n_gen", settings.generations), seed=settings.seed, callback=record, verbose=False
    )
    return OptimResult(
        x=np.atleast_1d(res.X).astype(float), f=float(np.atleast_1d(res.F)[0]), history=history, evaluations=count[0]
    )


def _first_population(start: np.ndarray, lower: np.ndarray, upper: np.ndarray, settings: GASettings) -> np.ndarray:
    """The rows of ``start`` (clipped to the box), then uniform draws in the box from the seed."""
    start = np.clip(np.atleast_2d(np.asarray(start, dtype=float)), lower, upper)[: settings.pop_size]
    rng = np.random.default_rng(settings.seed)
    drawn = rng.uniform(lower, upper, size=(settings.pop_size - len(start), len(lower)))
    return np.vstack([start, drawn])

"""The evolutionary optimiser every nlcx tuner uses: pymoo's genetic algorithm, seeded.

The objective is evaluated a whole population at a time (``objective(X) -> f`` with X of
shape (P, n)), which lets the batched kernel simulate every candidate in one call. With
``jobs > 1`` the population is split across a process pool; the result is the same as the
serial one because each candidate's loss depends only on the candidate.

pymoo comes with the optional extra ``tuning`` (``pip install 'nlcx[tuning]'``) and is imported
when a GA runs; what needs it and finds it missing says so in one line (:func:`require_pymoo`).
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from nlcx.errors import NlcxError

if TYPE_CHECKING:
    from pymoo.core.algorithm import Algorithm

Objective = Callable[[np.ndarray], np.ndarray]
#: The command that installs pymoo with nlcx.
TUNING_EXTRA = "pip install 'nlcx[tuning]'"


def require_pymoo(what: str) -> None:
    """Raise :class:`~nlcx.errors.NlcxError` (one line: ``WHAT: needs the optional extra: pip
    install 'nlcx[tuning]'``) where pymoo, the genetic algorithm's library, cannot be imported.

    Parameters
    ----------
    what : str
        What needs the genetic algorithm, as the user named it: a config key and its value
        (``controllers.ga.tune.kind = ga``) or a command (``nlcx identify``).
    """
    try:
        import pymoo  # noqa: F401
    except ImportError:
        raise NlcxError(f"{what}: needs the optional extra: {TUNING_EXTRA}") from None


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
    """Minimise ``objective`` over the box [lower, upper] with pymoo's GA (:func:`evolution`,
    each generation's population evaluated at once). ``start`` (rows of candidates) seeds the
    first population; the rest of it is drawn uniformly in the box from the seed (without
    ``start``, pymoo's own random sampling)."""
    generations = evolution(lower, upper, settings, callback, start)
    X = next(generations)
    while True:
        try:
            X = generations.send(split_evaluate(objective, X, executor, chunks))
        except StopIteration as done:
            result: OptimResult = done.value
            return result


def evolution(
    lower: np.ndarray,
    upper: np.ndarray,
    settings: GASettings,
    callback: Callable[[int, float], None] | None = None,
    start: np.ndarray | None = None,
) -> Generator[np.ndarray, np.ndarray, OptimResult]:
    """pymoo's GA over the box [lower, upper], one generation at a time (its ask and tell): the
    generator yields each population to evaluate (rows of X), is sent their losses (one per
    row), and returns the :class:`OptimResult`. Several GAs may be stepped side by side, their
    populations evaluated together; each draws from its own seeded random state, so the result
    is that of :func:`evolve` with the same settings."""
    require_pymoo("the genetic algorithm (pymoo)")
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.core.problem import Problem
    from pymoo.operators.crossover.sbx import SBX
    from pymoo.operators.mutation.pm import PM
    from pymoo.operators.sampling.rnd import FloatRandomSampling

    history: list[tuple[int, int, float]] = []
    count = [0]
    given: list[tuple[np.ndarray, np.ndarray]] = []  # the population sent out and its losses

    class _Problem(Problem):
        def __init__(self) -> None:
            super().__init__(n_var=len(lower), n_obj=1, xl=np.asarray(lower), xu=np.asarray(upper))

        def _evaluate(self, X: np.ndarray, out: dict[str, object], *args: object, **kwargs: object) -> None:
            asked, f = given.pop()
            if not np.array_equal(X, asked):
                raise RuntimeError("the GA evaluated another population than the one it asked for")
            count[0] += len(X)
            out["F"] = f[:, None]

    def record(algorithm: Algorithm) -> None:
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
    problem = _Problem()
    algorithm.setup(problem, termination=("n_gen", settings.generations), seed=settings.seed, callback=record)
    while algorithm.has_next():
        infills = algorithm.ask()
        X = np.ascontiguousarray(infills.get("X"))
        f = np.asarray((yield X), dtype=float)
        if f.shape != (len(X),):
            raise ValueError(f"{len(X)} losses expected, one per row of the population, got shape {f.shape}")
        given.append((X, f))
        algorithm.evaluator.eval(problem, infills, algorithm=algorithm)
        if given:
            raise RuntimeError("the GA did not evaluate the population it asked for")
        algorithm.tell(infills=infills)
    res = algorithm.result()
    return OptimResult(
        x=np.atleast_1d(res.X).astype(float), f=float(np.atleast_1d(res.F)[0]), history=history, evaluations=count[0]
    )


def _first_population(start: np.ndarray, lower: np.ndarray, upper: np.ndarray, settings: GASettings) -> np.ndarray:
    """The rows of ``start`` (clipped to the box), then uniform draws in the box from the seed."""
    start = np.clip(np.atleast_2d(np.asarray(start, dtype=float)), lower, upper)[: settings.pop_size]
    rng = np.random.default_rng(settings.seed)
    drawn = rng.uniform(lower, upper, size=(settings.pop_size - len(start), len(lower)))
    return np.vstack([start, drawn])

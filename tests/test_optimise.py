"""The GA every tuner and identification uses (:mod:`nlcx.tuning.optimise`), against pymoo itself."""

from __future__ import annotations

import numpy as np
import pytest

from nlcx.tuning.optimise import GASettings, OptimResult, evolution, evolve

LOWER, UPPER = np.array([-5.0, -4.0, -3.0]), np.array([5.0, 4.0, 6.0])


def rastrigin(X: np.ndarray) -> np.ndarray:
    X = np.atleast_2d(X)
    return np.sum(X**2 - 3.0 * np.cos(2.0 * np.pi * X), axis=1) + 0.1 * X[:, 0]


def _pymoo(settings: GASettings) -> tuple[np.ndarray, float, int]:
    """pymoo's GA run by pymoo's own ``minimize`` with the settings nlcx gives it."""
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.core.problem import Problem
    from pymoo.operators.crossover.sbx import SBX
    from pymoo.operators.mutation.pm import PM
    from pymoo.optimize import minimize

    class Box(Problem):
        def __init__(self) -> None:
            super().__init__(n_var=3, n_obj=1, xl=LOWER, xu=UPPER)

        def _evaluate(self, X: np.ndarray, out: dict[str, np.ndarray], *args: object, **kwargs: object) -> None:
            out["F"] = rastrigin(X)[:, None]

    algorithm = GA(
        pop_size=settings.pop_size, crossover=SBX(eta=settings.crossover_eta, prob=settings.crossover_prob),
        mutation=PM(eta=settings.mutation_eta), eliminate_duplicates=True,
    )  # fmt: skip
    res = minimize(Box(), algorithm, ("n_gen", settings.generations), seed=settings.seed)
    return np.atleast_1d(res.X).astype(float), float(np.atleast_1d(res.F)[0]), res.algorithm.evaluator.n_eval


@pytest.mark.parametrize("seed", [1, 5])
def test_evolve_is_pymoos_minimize(seed: int) -> None:
    """A generation at a time (ask and tell), the GA finds what pymoo's minimize finds, bit for bit."""
    settings = GASettings(pop_size=12, generations=6, seed=seed)
    result = evolve(rastrigin, LOWER, UPPER, settings)
    x, f, evaluations = _pymoo(settings)
    assert np.array_equal(result.x, x) and result.f == f and result.evaluations == evaluations
    assert [n for n, _, _ in result.history] == list(range(1, 7))
    assert result.history[-1][2] == f  # the best of the last generation is the result


def test_gas_stepped_side_by_side_are_each_ga_alone() -> None:
    """Two GAs stepped alternately, each sent its population's losses, end where each ends alone."""
    a, b = GASettings(pop_size=10, generations=5, seed=2), GASettings(pop_size=8, generations=5, seed=3)
    start = np.array([[1.0, 2.0, 0.5]])
    first, second = evolution(LOWER, UPPER, a), evolution(LOWER, UPPER, b, start=start)
    asked = [next(first), next(second)]
    assert np.array_equal(asked[1][0], start[0])  # the seeded row opens the first population
    done: list[OptimResult | None] = [None, None]
    while not all(done):
        for k, ga in enumerate((first, second)):
            if done[k] is None:
                try:
                    asked[k] = ga.send(rastrigin(asked[k]))
                except StopIteration as stop:
                    done[k] = stop.value
    alone = [evolve(rastrigin, LOWER, UPPER, a), evolve(rastrigin, LOWER, UPPER, b, start=start)]
    for result, own in zip(done, alone, strict=True):
        assert result is not None
        assert np.array_equal(result.x, own.x) and result.f == own.f and result.history == own.history


def test_a_wrong_number_of_losses_is_refused() -> None:
    ga = evolution(LOWER, UPPER, GASettings(pop_size=6, generations=2, seed=1))
    X = next(ga)
    with pytest.raises(ValueError, match="6 losses expected"):
        ga.send(rastrigin(X)[:-1])

"""The closed loop's one Runge-Kutta body, and the CPU's specialised copy of it.

:func:`nlcx.kernel.stepping.rk_step` is the one Runge-Kutta body of nlcx (the CPU kernel's
general tableaus, the friction path, the GPU); the CPU kernel steps the classic RK4 of a batch
without friction in flat loops of its own. Each step the kernel took in a recorded run must be
rk_step's from the recorded state with the recorded input held, bit for bit: with CLASSIC for
RK4, with SEQUENTIAL for any other tableau. The method's order is checked on a linear system.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from nlcx import config, engine
from nlcx.engine.prepared import TABLEAUS, items_of
from nlcx.engine.simulate import plant_call, plant_forces
from nlcx.kernel.abi import MAX_STAGES
from nlcx.kernel.stepping import CLASSIC, SEQUENTIAL, rk_step, stage_nodes


def _recorded(raw: dict[str, Any], integrator: str) -> tuple[Any, list[Any], Any, Any]:
    """A short run of ``raw`` with ``integrator``: its prepared experiment, runs, plant call and forces."""
    raw = copy.deepcopy(raw)
    raw["simulation"].update(t_end=0.5, integrator=integrator)
    prepared = engine.prepare(config.build(raw))
    runs = engine.evaluate([prepared])[0].runs
    items = items_of(prepared)
    return prepared, runs, plant_call(items[:1]), plant_forces(items[:1])


@pytest.mark.parametrize(("integrator", "combination"), [("rk4", CLASSIC), ("heun", SEQUENTIAL), ("euler", SEQUENTIAL)])
def test_each_recorded_step_is_rk_steps(x_error_raw: dict[str, Any], integrator: str, combination: int) -> None:
    prepared, runs, plant, forces = _recorded(x_error_raw, integrator)
    tableau, dt = TABLEAUS[integrator], prepared.grid.dt
    c = stage_nodes(tableau.a)
    run = runs[0]
    n = run.x.shape[1]
    p = np.ascontiguousarray(plant.p[:1].T)
    ks, xs, out = np.zeros((MAX_STAGES, n, 1)), np.zeros((n, 1)), np.zeros((n, 1))
    vid = np.zeros(1, dtype=np.int64)
    assert run.status == "ok" and run.x.shape[0] > 100
    for k in range(run.x.shape[0] - 1):
        x = np.ascontiguousarray(run.x[k][:, None])
        u = np.ascontiguousarray(run.u[k][:, None])
        kd = k if forces.dist.shape[1] > 1 else 0
        rk_step(plant.rhs, k * dt, dt, 1, x, out, u, p, ks, xs, tableau.a, tableau.b, c, combination,
                forces.dist, vid, kd, forces.dist_map, None)  # fmt: skip
        assert np.array_equal(out[:, 0].view(np.int64), run.x[k + 1].view(np.int64)), f"step {k}"


def test_the_orders_of_the_tableaus() -> None:
    """On dx/dt = -x (a rhs written as the ABI takes it), the error of one step of size h falls
    as h^(order + 1): RK4 4, Heun 2, Euler 1, both ways of adding up RK4's stages."""
    from numba import njit

    @njit
    def decay(t, x, u, p, dx, nb):  # pragma: no cover - compiled
        for b in range(nb):
            dx[0, b] = -x[0, b]

    dist, dist_map = np.zeros((1, 1, MAX_STAGES, 0)), np.zeros((1, 0))
    vid = np.zeros(1, dtype=np.int64)
    cases = [("rk4", CLASSIC, 4), ("rk4", SEQUENTIAL, 4), ("heun", SEQUENTIAL, 2), ("euler", SEQUENTIAL, 1)]
    for integrator, combination, order in cases:
        tableau = TABLEAUS[integrator]
        errors = []
        for h in (0.1, 0.05):
            ks, xs, out = np.zeros((MAX_STAGES, 1, 1)), np.zeros((1, 1)), np.zeros((1, 1))
            rk_step(decay, 0.0, h, 1, np.ones((1, 1)), out, np.zeros((0, 1)), np.zeros((0, 1)), ks, xs, tableau.a,
                    tableau.b, stage_nodes(tableau.a), combination, dist, vid, 0, dist_map, None)  # fmt: skip
            errors.append(abs(out[0, 0] - np.exp(-h)))
        assert np.log2(errors[0] / errors[1]) == pytest.approx(order + 1, abs=0.15), integrator

"""A plant written in plain Python (nlcx.plant): its equations, its checks, its registration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

import nlcx
from nlcx import registry
from nlcx.errors import ConfigError
from nlcx.plants.base import PlantModel, Signal, evaluate_rhs


def _register_mass_spring(name: str = "test_mass_spring") -> None:
    @nlcx.plant(name, states={"x": "m", "v": ("m/s", "Velocity")}, inputs={"F": "N"}, outputs=["x"],
                params={"k": (4.0, "N/m", "spring stiffness"), "mass": (1.0, "kg")})  # fmt: skip
    def mass_spring(t, x, u, p):
        return (x[1], (u[0] - p.k * x[0]) / p.mass)


def _open_loop(name: str, force: float, t_end: float, params: dict[str, float] | None = None) -> nlcx.Result:
    return nlcx.run({
        "name": "open", "plant": {"name": name, "params": params or {}, "x0": {"x": 0.0}},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {"F": {"kind": "constant", "value": force}},
        "simulation": {"t_end": t_end, "dt": 1e-3},
    })  # fmt: skip


def test_the_right_hand_side_is_the_users_function_for_every_variant_of_a_batch() -> None:
    """Columns are variants: dx of each column equals the user's equations on that column."""
    _register_mass_spring()
    model = registry.plants.get("test_mass_spring")
    plant = model.build("test_mass_spring", model.Params(k=2.5, mass=0.5), {}, {})
    rng = np.random.default_rng(1)
    X, U = rng.normal(size=(7, 2)), rng.normal(size=(7, 1))
    P = np.column_stack([rng.uniform(1, 5, 7), rng.uniform(0.5, 2, 7)])
    got = evaluate_rhs(plant.rhs, X, U, P)
    expected = np.column_stack([X[:, 1], (U[:, 0] - P[:, 0] * X[:, 0]) / P[:, 1]])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)
    assert plant.param_units == {"k": "N/m", "mass": "kg"}
    assert model.Params.model_fields["k"].description == "spring stiffness"


def test_a_constant_force_moves_the_mass_as_the_analytic_solution() -> None:
    """m x'' + k x = F from rest: x(t) = F/k (1 - cos(w t)), w = sqrt(k/m) (RK4 at 1 ms: ~1e-12)."""
    _register_mass_spring()
    result = _open_loop("test_mass_spring", force=2.0, t_end=3.0, params={"k": 9.0, "mass": 0.25})
    frame = result.trajectory("open")
    w = math.sqrt(9.0 / 0.25)
    expected = 2.0 / 9.0 * (1 - np.cos(w * frame.t.to_numpy()))
    np.testing.assert_allclose(frame.x.to_numpy(), expected, rtol=0, atol=1e-9)
    assert result.status("open") == "ok"


def test_the_thesis_pid_closes_a_loop_on_a_python_plant() -> None:
    """A PID with integral action removes the steady-state error of a step."""
    _register_mass_spring()
    result = nlcx.run({
        "name": "spring", "plant": {"name": "test_mass_spring"},
        "controllers": {"pid": {"kind": "pid", "loops": {"x": {"schedule": {
            "kind": "constant", "kp": 20.0, "ki": 10.0, "kd": 5.0}}}}},
        "reference": {"x": {"kind": "step", "final": 1.0}}, "simulation": {"t_end": 15.0, "dt": 0.01},
    })  # fmt: skip
    metrics = result.metrics.set_index(["signal", "metric"]).value
    assert abs(metrics[("x", "steady_state_error")]) < 1e-3
    assert 0 < metrics[("x", "rise_time")] < 2.0


def test_a_wrong_number_of_derivatives_is_refused_at_registration() -> None:
    with pytest.raises(ConfigError, match=r"test_bad_plant.*one finite derivative per declared state"):

        @nlcx.plant("test_bad_plant", states=["x", "v"], inputs=["F"])
        def bad(t, x, u, p):
            return (x[1], 0.0, 1.0)


def test_a_function_numba_cannot_compile_is_one_line() -> None:
    with pytest.raises(ConfigError, match=r"cannot be compiled or called as f\(t, x, u, p\)") as info:

        @nlcx.plant("test_uncompilable", states=["x"], inputs=["F"])
        def bad(t, x, u, p):
            return (object(),)

    assert "\n" not in str(info.value)


def test_undeclared_names_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"outputs = 'y': not a declared state; allowed: x, v"):
        nlcx.plant("test_bad_outputs", states=["x", "v"], inputs=["F"], outputs=["y"])
    with pytest.raises(ConfigError, match=r"params.k = 'stiff': a finite number"):
        nlcx.plant("test_bad_params", states=["x"], inputs=["F"], params={"k": "stiff"})  # type: ignore[dict-item]


def test_a_builtin_plant_is_never_replaced() -> None:
    with pytest.raises(ConfigError, match=r"plant = 'x_pendulum': already registered"):

        @nlcx.plant("x_pendulum", states=["x"], inputs=["F"])
        def shadow(t, x, u, p):
            return (u[0],)


def test_a_compiled_rhs_assigned_without_staticmethod_works() -> None:
    """``rhs = my_rhs`` in a PlantModel subclass: stored as a plain function, not bound as a method."""
    from nlcx.kernel.abi import RHS_SIG

    @njit(RHS_SIG)
    def integrator_rhs(t, x, u, p, dx, nb):  # pragma: no cover - compiled
        for b in range(nb):
            dx[0, b] = p[0, b] * u[0, b]

    class Gain(PlantModel):
        states = (Signal("y", ""),)
        inputs = (Signal("u", ""),)
        outputs = ("y",)
        rhs = integrator_rhs

        def parameter_vector(self, params: object) -> np.ndarray:
            return np.array([3.0])

    plant = Gain().build("gain", Gain.Params(), {}, {})
    np.testing.assert_array_equal(plant.f(np.array([0.0]), np.array([2.0])), [6.0])


def test_a_plain_python_rhs_in_a_plant_class_names_the_fix() -> None:
    def plain(t, x, u, p, dx, nb):  # not compiled
        pass

    with pytest.raises(ConfigError, match=r"Broken.rhs = 'plain': a numba-compiled function.*@nlcx.plant"):

        class Broken(PlantModel):
            rhs = plain

"""ANFIS (section 5.4.3): hybrid learning fits known functions; the compiled schedule equals predict."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from nlcx import config, engine
from nlcx.controllers.anfis import ANFIS, ANFISConfig, anfis_gains, anfis_surface
from nlcx.controllers.fuzzy import FuzzyConfig, fuzzy_surface
from nlcx.errors import ConfigError
from nlcx.tuning.anfis import (
    MODEL,
    AnfisModel,
    anfis_schedule,
    fit_consequents,
    initial_model,
    premise_gradient,
    rmse,
    train_anfis,
    vector_size,
)
from nlcx.validation import validate_model


def grid(lo: float, hi: float, n: int) -> np.ndarray:
    x = np.linspace(lo, hi, n)
    return np.array(np.meshgrid(x, x, indexing="ij")).reshape(2, -1).T


def sin_cos(X: np.ndarray) -> np.ndarray:
    return np.sin(X[:, 0]) * np.cos(X[:, 1])


def sinc2(X: np.ndarray) -> np.ndarray:
    """Jang (1993), example 1: z = sin(x) / x * sin(y) / y."""
    return np.sinc(X[:, 0] / np.pi) * np.sinc(X[:, 1] / np.pi)


HELD_OUT = np.random.default_rng(123).uniform(0.0, 1.0, (400, 2))


# --------------------------------------------------------------------------- fitting


@pytest.mark.parametrize("mf", ["gbell", "gauss"])
def test_fits_sin_cos(mf: str) -> None:
    """z = sin x cos y on a 15 x 15 grid over [-3, 3]^2, 3 MFs per input, 100 epochs:
    training RMSE < 0.01 and RMSE < 0.01 on 400 random held-out points (measured about 0.006, 0.005)."""
    X = grid(-3.0, 3.0, 15)
    model, history = train_anfis(X, sin_cos(X), n_mfs=3, epochs=100, mf=mf)
    assert history[-1] == pytest.approx(rmse(model, X, sin_cos(X)), rel=1e-12)
    assert history[-1] < 0.01
    assert history[-1] < 0.5 * history[0]
    Xt = -3.0 + 6.0 * HELD_OUT
    assert rmse(model, Xt, sin_cos(Xt)) < 0.01


def test_fits_jangs_sinc_with_jangs_rule() -> None:
    """Jang's example: 121 grid points over [-10, 10]^2, 4 bell MFs per input (16 rules), 100 epochs of
    the verbatim rule: training RMSE < 0.015 (measured 0.0086), held-out RMSE < 0.05 (0.035)."""
    X = grid(-10.0, 10.0, 11)
    model, history = train_anfis(X, sinc2(X), n_mfs=4, epochs=100, safeguard=False)
    assert rmse(model, X, sinc2(X)) == pytest.approx(min(history), rel=1e-12)  # the best epoch is returned
    assert min(history) < 0.015 < history[0]
    Xt = -10.0 + 20.0 * HELD_OUT
    assert rmse(model, Xt, sinc2(Xt)) < 0.05


def test_hybrid_loss_is_non_increasing_with_the_safeguard() -> None:
    """A large step size makes some epochs overshoot: rejected with the safeguard, kept without."""
    X = grid(-3.0, 3.0, 11)
    _, safe = train_anfis(X, sin_cos(X), epochs=40, step_size=0.3)
    _, raw = train_anfis(X, sin_cos(X), epochs=40, step_size=0.3, safeguard=False)
    assert len(safe) == len(raw) == 41 and safe[0] == raw[0]
    assert np.all(np.diff(safe) <= 0.0)
    assert safe[-1] < safe[0]
    assert np.any(np.diff(raw) > 0.0)  # the case the safeguard guards against does occur


def test_least_squares_step_reproduces_an_affine_target() -> None:
    """Premise fixed (and deliberately irregular): y = 0.7 x1 - 1.3 x2 + 0.25 is exactly representable."""
    rng = np.random.default_rng(4)
    X = np.column_stack([rng.uniform(-1.44, 1.56, 200), rng.uniform(-15.7, 4.3, 200)])
    y = 0.7 * X[:, 0] - 1.3 * X[:, 1] + 0.25
    for mf in ("gbell", "gauss"):
        model = initial_model(X, 3, mf)
        model.centres += rng.normal(0.0, 0.1, model.centres.shape) * np.array([[1.0], [6.0]])
        model.slopes += rng.uniform(0.0, 1.0, model.slopes.shape)
        premise = model.to_vector()[: MODEL.size + 6 * 3]
        fit_consequents(model, X, y)
        assert np.array_equal(model.to_vector()[: MODEL.size + 6 * 3], premise)
        assert np.max(np.abs(model.predict(X) - y)) < 1e-10
        assert np.allclose(model.consequents, [0.7, -1.3, 0.25], rtol=0, atol=1e-8)  # unique: every rule


@pytest.mark.parametrize("mf", ["gbell", "gauss"])
def test_premise_gradient_matches_finite_differences(mf: str) -> None:
    rng = np.random.default_rng(2)
    X = np.column_stack([rng.uniform(-2, 2, 60), rng.uniform(-10, 10, 60)])
    y = np.sin(X[:, 0]) * np.cos(X[:, 1] / 5)
    model = fit_consequents(initial_model(X, 3, mf), X, y)
    model.centres += rng.normal(0.0, 0.05, model.centres.shape)
    model.slopes += 0.3

    def loss(m: AnfisModel) -> float:
        return 0.5 * float(np.sum((m.predict(X) - y) ** 2))

    grad = premise_gradient(model, X, y)
    h = 1e-6
    for k, attr in enumerate(("centres", "widths", "slopes")):
        for idx in np.ndindex(2, 3):
            plus, minus = model.copy(), model.copy()
            getattr(plus, attr)[idx] += h
            getattr(minus, attr)[idx] -= h
            numeric = (loss(plus) - loss(minus)) / (2 * h)
            assert grad[(k, *idx)] == pytest.approx(numeric, rel=1e-5, abs=1e-8)


def test_training_is_reproducible_by_seed() -> None:
    X = grid(-3.0, 3.0, 11)
    y = sin_cos(X)
    a, ha = train_anfis(X, y, epochs=15, batch_size=16, seed=7)
    b, hb = train_anfis(X, y, epochs=15, batch_size=16, seed=7)
    c, _ = train_anfis(X, y, epochs=15, batch_size=16, seed=8)
    assert np.array_equal(a.to_vector(), b.to_vector()) and ha == hb
    assert not np.array_equal(a.to_vector(), c.to_vector())  # the minibatch order comes from the seed
    d, _ = train_anfis(X, y, epochs=15, seed=1)
    e, _ = train_anfis(X, y, epochs=15, seed=2)
    assert np.array_equal(d.to_vector(), e.to_vector())  # full batch: nothing random


def test_initial_premise_is_evenly_spaced_from_the_data_ranges() -> None:
    X = np.array([[-1.0, 10.0], [3.0, 0.0], [0.0, 5.0]])
    for mf in ("gbell", "gauss"):
        m = initial_model(X, 5, mf)
        assert np.allclose(m.centres, [np.linspace(-1, 3, 5), np.linspace(0, 10, 5)], rtol=0, atol=1e-15)
        assert np.array_equal(m.ranges, [[-1, 3], [0, 10]])
        mid = 0.5 * (m.centres[:, :-1] + m.centres[:, 1:])  # neighbours cross at 1/2 midway
        mu1, mu2 = m.memberships(np.column_stack([mid[0], mid[1]]))
        assert np.allclose(mu1[np.arange(4), np.arange(4)], 0.5) and np.allclose(
            mu2[np.arange(4), np.arange(1, 5)], 0.5
        )


# ------------------------------------------------------------------------- packing


def test_vector_and_config_round_trips() -> None:
    X = grid(-3.0, 3.0, 7)
    model, _ = train_anfis(X, sin_cos(X), n_mfs=2, epochs=3, mf="gauss")
    v = model.to_vector()
    assert v.size == vector_size(2)
    again = AnfisModel.from_vector(v)
    assert np.array_equal(again.to_vector(), v) and again.mf == "gauss"
    cfg = ANFISConfig.model_validate(
        {"kind": "anfis", "kp": model.to_config(), "ki": model.to_config(), "kd": model.to_config()}
    )
    assert np.array_equal(AnfisModel.from_config(cfg.kp).to_vector(), v)
    with pytest.raises(ValueError, match="entries"):
        AnfisModel.from_vector(v[:-1])


# --------------------------------------------------------------------- the schedule


@pytest.fixture(scope="module")
def trained() -> dict:
    """Three gain models taught by the fuzzy self-tuning surface over the universes of Table 5.2."""
    fuzzy = FuzzyConfig(kp={"min": 1.0, "max": 2.0}, ki={"min": 1.0, "max": 2.5}, kd={"min": 0.05, "max": 0.2})
    E, D = np.meshgrid(np.linspace(-1.44, 1.56, 13), np.linspace(-15.7, 4.3, 13))
    X = np.column_stack([E.ravel(), D.ravel()])
    gains = np.column_stack([k.ravel() for k in fuzzy_surface(fuzzy, E, D)])
    cfg, histories = anfis_schedule(X, gains, n_mfs=3, epochs=20)
    for h in histories.values():
        assert h[-1] < h[0]
    return cfg


@pytest.mark.parametrize("clip_inputs", [True, False])
def test_compiled_schedule_equals_predict(trained: dict, clip_inputs: bool) -> None:
    raw = {**trained, "clip_inputs": clip_inputs}
    cfg = ANFISConfig.model_validate(raw)
    sp = ANFIS().pack(cfg)
    es, ds = np.linspace(-2.5, 2.5, 31), np.linspace(-25.0, 10.0, 29)
    X = np.array(np.meshgrid(es, ds, indexing="ij")).reshape(2, -1).T
    expected = np.column_stack(
        [AnfisModel.from_config(raw[k]).predict(X, clip=clip_inputs) for k in ("kp", "ki", "kd")]
    )
    row = np.concatenate([np.full(5, 9.0), sp])  # the schedule's parameters at an offset, as in a PID
    p = np.stack([row, np.zeros_like(row)])
    for x, want in zip(X, expected, strict=True):
        out = np.array(anfis_gains(0.0, x[0], x[1], p, 0, 5))
        assert np.max(np.abs(out - want)) < 1e-12
    lo, hi = np.array(raw["kp"]["ranges"]).T  # the three models share the training data's ranges
    inside = np.all(np.clip(X, lo, hi) == X, axis=1)
    clipped = np.column_stack([AnfisModel.from_config(raw[k]).predict(X, clip=True) for k in ("kp", "ki", "kd")])
    assert np.array_equal(expected[inside], clipped[inside])
    assert clip_inputs == np.array_equal(expected, clipped)


def test_gain_clipping_and_gauss_models(trained: dict) -> None:
    X = grid(-3.0, 3.0, 9)
    gauss, _ = train_anfis(X, sin_cos(X), n_mfs=3, epochs=5, mf="gauss")
    raw = {**trained, "kd": gauss.to_config(), "clip": {"kp": {"min": 1.2, "max": 1.8}}}
    cfg = ANFISConfig.model_validate(raw)
    sp = ANFIS().pack(cfg)
    E, D = np.meshgrid(np.linspace(-3, 3, 15), np.linspace(-20, 8, 15))
    surface = np.stack(anfis_surface(cfg, E, D), axis=-1)
    assert surface[..., 0].min() == 1.2 and surface[..., 0].max() == 1.8
    for idx in np.ndindex(E.shape):
        out = np.array(anfis_gains(0.0, E[idx], D[idx], sp[None], 0, 0))
        assert np.max(np.abs(out - surface[idx])) < 1e-12
    assert np.allclose(
        surface[..., 2], gauss.predict(np.column_stack([E.ravel(), D.ravel()]), clip=True).reshape(E.shape)
    )


def _bad(trained: dict, key: str, value) -> dict:
    raw = copy.deepcopy(trained)
    target = raw
    *parents, last = key.split(".")
    for p in parents:
        target = target[p]
    target[last] = value
    return raw


@pytest.mark.parametrize(
    ("key", "value", "path", "message"),
    [
        ("kp.centres", [0.0] * 5, "kp", "centres has 5 values; 3 MFs per input need 6"),
        ("ki.widths", [1.0, 1.0, 0.0, 1.0, 1.0, 1.0], "ki", "widths must be positive"),
        ("kd.mf", "trimf", "kd.mf", "allowed values"),
        ("kp.ranges", [[1.0, -1.0], [0.0, 1.0]], "kp.ranges", "min <= max"),
        ("clip", {"kp": {"min": 2.0, "max": 1.0}}, "clip", "kp: min 2 must not exceed max 1"),
        ("clip", {"kq": {"min": 0.0, "max": 1.0}}, "clip.kq.[key]", "allowed values"),
    ],
)
def test_bad_configs_are_one_line_errors(trained: dict, key: str, value, path: str, message: str) -> None:
    where = "controllers.a.loops.y.schedule"
    with pytest.raises(ConfigError) as info:
        validate_model(ANFISConfig, _bad(trained, key, value), where)
    assert info.value.path == f"{where}.{path}" and message in info.value.allowed


def test_closed_loop_logs_the_scheduled_gains(trained: dict) -> None:
    cstr = {"num": [-1.117, 3.1472], "den": [1.0, 4.6429, 5.3821]}  # eq. 5.10
    dt = 1e-3
    raw = {
        "name": "anfis_test",
        "plant": {"name": "transfer_function", "params": cstr},
        "controllers": {"a": {"kind": "pid", "loops": {"y": {"schedule": copy.deepcopy(trained)}}}},
        "reference": {"y": {"kind": "step", "time": 0.5}},
        "simulation": {"t_end": 6.0, "dt": dt},
    }
    (run,) = engine.run_experiment(config.build(raw)).runs
    assert run.status == "ok"
    e = run.r[:, 0] - run.x @ np.array(cstr["num"][::-1])
    edot = np.concatenate([[0.0], np.diff(e) / dt])
    expected = np.column_stack(anfis_surface(trained, e, edot))
    assert np.max(np.abs(run.log[:, :3] - expected)) < 1e-12
    assert np.ptp(run.log[:, 0]) > 0.05

"""The kernel and engine: accuracy, order, disturbance, divergence, batching, determinism."""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any

import control
import numpy as np
import pytest
from conftest import run_raw

from nlcx import config, engine
from nlcx.errors import ConfigError
from nlcx.report import write_csv

CSTR = {"num": [-1.117, 3.1472], "den": [1.0, 4.6429, 5.3821]}  # eq. 5.10


def tf_raw(params: dict, controllers: dict, reference: dict, t_end: float, dt: float, **extra) -> dict:
    return {
        "name": "tf_test",
        "plant": {"name": "transfer_function", "params": params},
        "controllers": controllers,
        "reference": reference,
        "simulation": {"t_end": t_end, "dt": dt, **extra.pop("simulation", {})},
        **extra,
    }


def test_open_loop_step_matches_python_control() -> None:
    raw = tf_raw(CSTR, {"open": {"kind": "open_loop"}}, {"u": {"kind": "step"}}, 5.0, 1e-3)
    (run,) = run_raw(raw).runs
    y = (run.x @ np.array(CSTR["num"][::-1])).ravel()
    _, y_ref = control.step_response(control.tf(CSTR["num"], CSTR["den"]), T=run.t)
    assert np.max(np.abs(y - y_ref)) < 1e-9


@pytest.mark.parametrize(("integrator", "order"), [("euler", 1), ("heun", 2), ("rk4", 4)])
def test_integrator_convergence_order(integrator: str, order: int) -> None:
    """Max error of a step response against the exact one falls as dt^order."""
    G = control.tf(CSTR["num"], CSTR["den"])
    errs = []
    for dt in (0.05, 0.025):
        raw = tf_raw(
            CSTR,
            {"open": {"kind": "open_loop"}},
            {"u": {"kind": "step"}},
            2.0,
            dt,
            simulation={"integrator": integrator},
        )
        (run,) = run_raw(raw).runs
        _, y_exact = control.step_response(G, T=run.t)
        errs.append(np.max(np.abs(run.x @ np.array(CSTR["num"][::-1]) - np.asarray(y_exact))))
    assert math.log2(errs[0] / errs[1]) == pytest.approx(order, abs=0.2)


def test_closed_loop_pid_matches_continuous_feedback() -> None:
    """ZOH-sampled PID at dt = 1e-4 against python-control's continuous loop C G / (1 + C G).

    The step comes at t = 0.5 s so that both loops see the derivative kick of the filtered
    derivative (the discrete PID starts its derivative from the first sample).
    """
    kp, ki, kd, N = 1.2, 1.5, 0.1, 50.0
    ctrl = {
        "pid": {
            "kind": "pid",
            "derivative": {"method": "filtered", "N": N},
            "loops": {"y": {"schedule": {"kind": "constant", "kp": kp, "ki": ki, "kd": kd}}},
        }
    }
    raw = tf_raw(CSTR, ctrl, {"y": {"kind": "step", "time": 0.5}}, 6.0, 1e-4)
    (run,) = run_raw(raw).runs
    y = run.x @ np.array(CSTR["num"][::-1])
    s = control.tf("s")
    C = kp + ki / s + kd * N * s / (s + N)
    T = control.feedback(C * control.tf(CSTR["num"], CSTR["den"]), 1)
    after = run.t >= 0.5
    _, y_ref = control.step_response(T, T=run.t[after] - 0.5)
    assert np.all(y[~after] == 0.0)
    assert np.max(np.abs(y[after] - np.asarray(y_ref))) < 5e-4  # O(dt) from the zero-order hold


def test_disturbance_enters_the_chosen_derivative() -> None:
    """Double integrator x1'' = d(t), d = A sin(2 pi f t): x1 = A/w (t - sin(w t)/w)."""
    A, f = 3.0, 2.0
    raw = tf_raw(
        {"num": [1.0], "den": [1.0, 0.0, 0.0]},
        {"open": {"kind": "open_loop"}},
        {},
        2.0,
        1e-3,
        uncertainty={"d": {"kind": "disturbance", "amplitude": A, "frequency": f, "states": ["x2"]}},
    )
    (run,) = run_raw(raw).runs
    w = 2 * math.pi * f
    exact = A / w * (run.t - np.sin(w * run.t) / w)
    assert np.max(np.abs(run.x[:, 0] - exact)) < 1e-10


def test_divergence_is_a_result_not_a_crash(x_time_raw: dict) -> None:
    """A wrong loop sign makes the pendulum fall: status unstable, early stop, metrics say so."""
    x_time_raw["controllers"]["conventional"]["loops"]["theta"]["sign"] = 1
    res = run_raw(x_time_raw)
    conv, prop = res.runs
    assert conv.status == "unstable" and prop.status == "ok"
    assert 0 < conv.t_fail < 5 and conv.t.size < prop.t.size
    assert abs(conv.x[-1, 2]) <= math.pi / 2 < abs(conv.x[-1, 2]) + 0.2
    assert "theta" in conv.reason and "bounds" in conv.reason
    rows = res.metrics[res.metrics.controller == "conventional"]
    assert set(rows.status) == {"unstable"}
    assert rows.set_index("metric").loc["t_fail", "value"] == pytest.approx(conv.t_fail)


def test_non_finite_state_stops_the_run() -> None:
    raw = tf_raw(
        {"num": [1.0], "den": [1.0, -400.0]},
        {"open": {"kind": "open_loop"}},
        {"u": {"kind": "step"}},
        5.0,
        1e-3,
    )
    (run,) = run_raw(raw).runs
    assert run.status == "unstable" and "non-finite" in run.reason
    assert np.all(np.isfinite(run.x))


def test_batch_equals_single_runs_bit_for_bit(x_error_raw: dict) -> None:
    both = run_raw(x_error_raw)
    for label in ("conventional", "proposed"):
        single_raw = {**x_error_raw, "controllers": {label: x_error_raw["controllers"][label]}}
        (single,) = run_raw(single_raw).runs
        batched = next(r for r in both.runs if r.label == label)
        assert np.array_equal(single.x, batched.x) and np.array_equal(single.u, batched.u)
        assert np.array_equal(single.log, batched.log)


@pytest.mark.parametrize("integrator", ["rk4", "heun"])
def test_lock_step_batch_equals_single_runs_with_friction_noise_and_divergence(
    x_error_raw: dict, integrator: str
) -> None:
    """One kernel call over variants that differ in plant, friction model, noise and
    disturbance, some of which diverge at different times (they leave the batch), equals
    each variant run alone, bit for bit: states, inputs, logs, friction forces, status."""
    rng = np.random.default_rng(11)
    prepared = []
    for k in range(18):
        raw = copy.deepcopy(x_error_raw)
        raw["seed"] = k
        raw["simulation"].update(t_end=4.0, integrator=integrator)
        raw["plant"]["params"].update(M=float(rng.uniform(0.7, 1.3)), l=float(rng.uniform(0.2, 0.9)))
        uncertainty = {}
        model = ("none", "simple", "exponential")[k % 3]
        if model != "none":
            uncertainty["friction"] = {"kind": "friction", "model": model, "mu_s": 0.2, "mu_c": 0.15, "viscous": 0.1}
        if k % 2:
            uncertainty["noise"] = {"kind": "noise", "power": 1e-7, "sample_time": 0.01}
        if k % 4 == 1:
            uncertainty["disturbance"] = {"kind": "disturbance", "amplitude": 2.0, "frequency": 10.0}
        raw["uncertainty"] = uncertainty
        prepared.append(engine.prepare(config.build(raw)))
    items = [item for p in prepared for item in engine.items_of(p)]
    batched = engine.simulate_items(items, prepared[0].grid, integrator)
    assert {r.status for r in batched} == {"ok", "unstable"}  # some variants leave the batch early
    assert len({r.t.size for r in batched}) > 2
    k = 0
    for p in prepared:
        for run in engine.evaluate([p], measure=False)[0].runs:
            other = batched[k]
            k += 1
            assert run.status == other.status and run.reason == other.reason
            for name in ("x", "u", "log", "friction"):
                assert np.array_equal(getattr(run, name), getattr(other, name)), name


def test_a_right_hand_side_that_ignores_the_columns_is_refused() -> None:
    """A plant written for one state (RHS_SIG's columns are variants) is caught before it runs."""
    from numba import njit

    from nlcx.kernel.abi import RHS_SIG
    from nlcx.plants.base import check_rows

    @njit(RHS_SIG)
    def one_state_rhs(t, x, u, p, dx, nb):  # pragma: no cover - compiled
        dx[0, 0] = x[1, 0]
        dx[1, 0] = -p[0, 0] * x[0, 0] + u[0, 0]

    prep = engine.prepare(config.build(tf_raw(CSTR, {"ol": {"kind": "open_loop"}}, {"u": {"kind": "step"}}, 1, 0.1)))
    plant = dataclasses.replace(prep.plant, rhs=one_state_rhs)
    with pytest.raises(ConfigError, match="first nb columns"):
        check_rows(plant)
    check_rows(prep.plant)  # the companion form loops over the columns


@pytest.mark.parametrize("declared", [False, True])
def test_a_right_hand_side_written_for_rows_is_refused_in_one_line(declared: bool) -> None:
    """A plant with the ABI before columns, rhs(t, x, u, p, dx) over the rows, is refused with a
    one-line config error naming the plant, whether numba compiles it lazily or it declares the
    old signature, instead of a numba traceback."""
    from numba import njit, types

    from nlcx.kernel.abi import F64, MAT
    from nlcx.plants.base import check_rows

    def rows_rhs(t, x, u, p, dx):  # pragma: no cover - compiled
        for b in range(x.shape[0]):
            dx[b, 0] = x[b, 1]
            dx[b, 1] = -p[b, 0] * x[b, 0] + u[b, 0]

    compiled = njit(types.void(F64, MAT, MAT, MAT, MAT))(rows_rhs) if declared else njit(rows_rhs)
    prep = engine.prepare(config.build(tf_raw(CSTR, {"ol": {"kind": "open_loop"}}, {"u": {"kind": "step"}}, 1, 0.1)))
    plant = dataclasses.replace(prep.plant, rhs=compiled)
    with pytest.raises(ConfigError) as info:
        check_rows(plant)
    message = str(info.value)
    assert "\n" not in message and "plant.name" in message and "rhs(t, x, u, p, dx, nb)" in message


def test_same_config_same_bytes(x_time_raw: dict, tmp_path) -> None:
    a, b = run_raw(x_time_raw), run_raw(x_time_raw)
    write_csv(tmp_path / "a.csv", a.metrics)
    write_csv(tmp_path / "b.csv", b.metrics)
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


def test_t_end_must_be_whole_steps(x_time_raw: dict) -> None:
    x_time_raw["simulation"]["dt"] = 0.003
    with pytest.raises(ConfigError, match=r"simulation\.t_end"):
        engine.prepare(config.build(x_time_raw))


@pytest.mark.parametrize("rows", [1, 3])
def test_metrics_measured_in_blocks_of_runs_equal_one_block(x_error_raw: dict, monkeypatch, rows: int) -> None:
    """The engine gathers the rows it measures (outputs, references, inputs) a block of runs at
    a time (:data:`nlcx.engine.measure.ROWS_ELEMENTS` samples); every metric of every run is the
    same to the last bit whatever the block size."""
    from nlcx.engine import measure

    prepared = []
    for k, M in enumerate((0.8, 1.0, 1.2, 1.4, 9.0)):
        raw = copy.deepcopy(x_error_raw)
        raw["simulation"]["t_end"] = 3.0
        raw["plant"]["params"]["M"] = M
        raw["seed"] = k
        prepared.append(engine.prepare(config.build(raw)))
    results = engine.evaluate(prepared)
    whole = engine.shared_metrics(results)
    assert len({r.prepared.plant.p.tobytes() for r in results}) == 5 and len(whole) > 100
    runs = [run for r in results for run in r.runs]
    monkeypatch.setattr(measure, "ROWS_ELEMENTS", rows * runs[0].t.size)
    assert len(measure._row_ranges(len(runs), runs[0].t.size)[0]) == rows
    blocks = engine.shared_metrics(engine.remeasure(results, {}))
    assert whole.equals(blocks)
    assert (whole.status == "ok").any() and not whole.value.isna().all()


def test_controllers_of_several_structures_share_a_call_of_few_rows_and_split_when_many(
    x_error_raw: dict, monkeypatch
) -> None:
    """A conventional and an error-AGS PID (two loop structures, two compiled steps) are one
    kernel call of the general PID step when they are few (a single run); with eight rows or
    more each, each structure runs its own step in a call of its own. The runs are the same to
    the bit either way."""
    from nlcx.controllers import pid
    from nlcx.kernel import integrator

    steps: list[list[Any]] = []
    original = integrator.simulate

    def recording(integration, plant, controller, *rest):
        steps[-1].append(controller.step)
        return original(integration, plant, controller, *rest)

    monkeypatch.setattr(integrator, "simulate", recording)
    runs = {}
    for n in (1, 8):
        prepared = []
        for k in range(n):
            raw = copy.deepcopy(x_error_raw)
            raw["simulation"]["t_end"] = 2.0
            raw["plant"]["params"]["M"] = 1.0 + 0.01 * k
            prepared.append(engine.prepare(config.build(raw)))
        steps.append([])
        runs[n] = engine.evaluate(prepared, measure=False)
    few, many = steps
    controllers = runs[8][0].prepared.controllers
    assert few == [pid.pid_step]
    assert sorted(map(id, many)) == sorted(id(c.step) for c in controllers) and pid.pid_step not in many
    for a, b in zip(runs[1][0].runs, runs[8][0].runs, strict=True):
        assert a.label == b.label and np.array_equal(a.x, b.x) and np.array_equal(a.u, b.u)
        assert np.array_equal(a.log, b.log)


def _kernel_arguments(x_error_raw: dict, monkeypatch, **uncertainty: Any) -> tuple[tuple[Any, ...], list[Any]]:
    """The arguments of the kernel call of ``x_error_raw`` (2 s, ``uncertainty``), as the engine
    makes them, and their numba types when the kernel is called."""
    import numba

    from nlcx.kernel import integrator

    calls: list[tuple[Any, ...]] = []
    typed: list[Any] = []
    original = integrator.simulate

    def recording(*args: Any) -> None:
        calls.append(args)
        typed.extend(numba.typeof(a) for a in args)
        original(*args)

    monkeypatch.setattr(integrator, "simulate", recording)
    raw = copy.deepcopy(x_error_raw)
    raw["simulation"]["t_end"] = 2.0
    raw["uncertainty"] = uncertainty
    engine.evaluate([config.build(raw)], measure=False)
    (call,) = calls
    return call, typed


@pytest.mark.parametrize("friction", [False, True])
def test_the_kernels_structures_are_typed_as_its_signature_declares(
    x_error_raw: dict, monkeypatch, friction: bool
) -> None:
    """Every argument the engine hands the kernel is a named structure, typed by a lookup as the
    very type of the kernel's signature (its function tables and the friction path included),
    whatever plugins it carries; a structure holding an array of another dtype, dimension or
    layout, a read-only one or a plain tuple where a function table belongs is refused with a
    message naming the field."""
    import numba

    from nlcx.kernel import structures
    from nlcx.kernel.friction_path import FRICTIONAL, FRICTIONLESS

    unc = {"friction": {"kind": "friction", "model": "simple", "mu_s": 0.2, "mu_c": 0.15}} if friction else {}
    args, typed = _kernel_arguments(x_error_raw, monkeypatch, **unc)
    declared = structures.SIMULATE_SIG.args
    assert len(args) == len(typed) == len(declared) == 9
    kinds = (structures.Integration, structures.PlantCall, structures.ControllerCall, structures.LoopElements,
             structures.PlantForces, structures.Records, structures.Outcome, structures.FrictionPath,
             structures.Working)  # fmt: skip
    for arg, kind, numba_type, declared_type in zip(args, kinds, typed, declared, strict=True):
        assert type(arg) is kind and numba_type == declared_type == kind.numba_type
    assert args[7] is (FRICTIONAL if friction else FRICTIONLESS)
    records = structures.Records(*(np.zeros_like(a) for a in args[5]))  # the kernel's are read-only after it
    numba.typeof(records)
    for field, bad in (
        ("X", records.X.astype(np.float32)),
        ("U", records.U[:, ::2]),
        ("LOG", np.zeros(3)),
        ("FRICTION", np.broadcast_to(records.FRICTION, records.FRICTION.shape)),
    ):
        with pytest.raises(TypeError, match=rf"Records\.{field}: a writeable C-contiguous 3-d float64 array"):
            numba.typeof(records._replace(**{field: bad}))
    controller = args[2]
    with pytest.raises(TypeError, match=r"ControllerCall\.callbacks: a FunctionTable"):
        numba.typeof(controller._replace(callbacks=tuple(controller.callbacks)))
    with pytest.raises(TypeError, match=r"Integration\.dt: a float"):
        numba.typeof(args[0]._replace(dt=1))


def test_the_integration_method_is_chosen_by_the_integrators_name(x_error_raw: dict, monkeypatch) -> None:
    """``rk4`` is stepped by the kernel's written-out classic Runge-Kutta method, any other
    integrator by its tableau; the tableau path given rk4's tableau computes the same
    trajectory to rounding, so the written-out method is the classic one."""
    from nlcx.engine import simulate
    from nlcx.kernel import structures

    assert structures.method_of("rk4") == structures.CLASSIC_RK4
    assert {structures.method_of(name) for name in ("euler", "heun")} == {structures.ANY_TABLEAU}
    assert _kernel_arguments(x_error_raw, monkeypatch)[0][0].method == structures.CLASSIC_RK4
    raw = copy.deepcopy(x_error_raw)
    raw["simulation"]["t_end"] = 2.0
    written_out = engine.evaluate([config.build(raw)], measure=False)[0].runs
    monkeypatch.setattr(simulate, "method_of", lambda name: structures.ANY_TABLEAU)
    tableau = engine.evaluate([config.build(raw)], measure=False)[0].runs
    for a, b in zip(written_out, tableau, strict=True):
        assert a.status == b.status == "ok"
        np.testing.assert_allclose(a.x, b.x, rtol=1e-9, atol=1e-12)


def test_paddings_are_handed_over_by_address_called_anyway_run_and_pickle_by_reference() -> None:
    """The slots the kernel never calls (a table's padding, the friction path of a batch
    without friction) are paddings: numba takes their address, and a compiled caller that
    calls one anyway runs its function; they, and the tables holding them, pickle to the
    very same objects."""
    import pickle

    from numba import njit, types

    from nlcx.kernel import abi
    from nlcx.kernel.friction_path import FRICTIONLESS, no_frictional_sample, no_frictional_step
    from nlcx.kernel.structures import FrictionPath

    table = abi.callback_slots()
    assert all(slot is abi.no_callback for slot in table) and len(table) == abi.CALLBACK_SLOTS
    assert all(slot is abi.no_element for slot in abi.element_slots())
    assert FRICTIONLESS.sample is no_frictional_sample and FRICTIONLESS.step is no_frictional_step
    assert isinstance(abi.no_callback.__wrapper_address__(), int) and abi.no_callback.__wrapper_address__() > 0

    @njit(types.UniTuple(types.float64, 3)(abi.CallbackTuple))
    def call_slot_3(callbacks):  # pragma: no cover - compiled
        return callbacks[3](0.5, 1.0, 2.0, np.zeros((1, 1)), 0, 0)

    assert call_slot_3(table) == (0.0, 0.0, 0.0)
    again = pickle.loads(pickle.dumps((table, FRICTIONLESS)))
    assert all(slot is abi.no_callback for slot in again[0]) and again[0].numba_type == table.numba_type
    assert again[1] == FRICTIONLESS and type(again[1]) is FrictionPath


def test_reference_cache_shares_an_array_per_key_and_drops_the_least_recently_used() -> None:
    """Equal channels on the same grid share one array; a new key beyond the cache's size drops
    the array used longest ago, which is then computed anew (equal, not the same object)."""
    from types import SimpleNamespace

    from nlcx.engine.prepared import Reference, ReferenceCache

    class Ramp:
        calls = 0

        def values(self, cfg: Any, t: np.ndarray) -> np.ndarray:
            Ramp.calls += 1
            return cfg.slope * t

    class Slope(SimpleNamespace):
        def model_dump(self) -> dict[str, float]:
            return {"slope": self.slope}

    grid = SimpleNamespace(dt=0.1, n_steps=10, t=np.arange(11) * 0.1)
    prepared = SimpleNamespace(
        grid=grid, references={f"r{k}": Reference(Ramp(), Slope(slope=float(k))) for k in range(3)}
    )
    cache = ReferenceCache(size=2)
    first = cache.array(prepared, ("r0",))
    assert cache.array(prepared, ("r0",), (0.0,)) is first and Ramp.calls == 1
    np.testing.assert_array_equal(
        cache.array(prepared, ("r1", "r2"), (0.0, 0.1)), np.stack([grid.t, 2 * (grid.t + 0.1)], -1)
    )
    cache.array(prepared, ("r1",))
    assert Ramp.calls == 4
    again = cache.array(prepared, ("r0",))
    assert again is not first and np.array_equal(again, first) and Ramp.calls == 5


_BOUNDS_SCRIPT = """
import copy, itertools, yaml
from nlcx import config, engine
raw0 = yaml.safe_load(open("configs/x_error_ags.yaml"))
models = ["none", "simple", "exponential"]
for integrator, model, noise, dist in itertools.product(["rk4", "euler"], models, [0, 1], [0, 1]):
    raw = copy.deepcopy(raw0)
    raw["simulation"].update(t_end=0.02, integrator=integrator)
    u = {}
    if model != "none":
        u["friction"] = {"kind": "friction", "model": model, "mu_s": 0.2, "mu_c": 0.15, "viscous": 0.1}
    if noise:
        u["noise"] = {"kind": "noise", "power": 1e-7, "sample_time": 0.01}
    if dist:
        u["disturbance"] = {"kind": "disturbance", "amplitude": 2.0, "frequency": 10.0}
    raw["uncertainty"] = u
    prepared = engine.prepare(config.build(raw))
    engine.simulate_items(engine.items_of(prepared), prepared.grid, integrator)
print("in bounds")
"""


def test_the_kernel_reads_and_writes_only_inside_its_arrays() -> None:
    """The kernel run as Python (``NUMBA_DISABLE_JIT=1``), where every index is checked, over
    each combination of friction model, noise and disturbance: no index leaves its array
    (compiled, an index past the end reads or writes whatever memory follows)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    done = subprocess.run([sys.executable, "-c", _BOUNDS_SCRIPT], cwd=root, env=env, capture_output=True, text=True)
    assert done.returncode == 0 and "in bounds" in done.stdout, done.stderr[-2000:]


def test_a_reference_shared_between_runs_is_read_only(x_error_raw: dict) -> None:
    """Runs that read the same reference channels share one array (engine.REFERENCES): it is
    read-only, so no run, metric or caller can change the reference another run reads."""
    first, second = (run_raw(x_error_raw).runs for _ in range(2))
    assert np.shares_memory(first[0].r, second[0].r)
    with pytest.raises(ValueError, match="read-only"):
        first[0].r[-1, 0] = 0.0
    assert np.array_equal(first[0].r, second[0].r)

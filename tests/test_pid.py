"""The PID step function against its equations (one controller, several loops)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from conftest import CONFIGS

from nlcx import config, engine, registry
from nlcx.controllers import pid
from nlcx.controllers.pid import HEAD, INPUT, LOOP, LOOP_STATE, pid_step
from nlcx.controllers.schedules import schedule_slots
from nlcx.kernel.abi import callback_slots


def build(raw_ctrl: dict) -> engine.Prepared:
    raw = {
        "name": "pid_test",
        "plant": {"name": "x_pendulum"},
        "controllers": {"c": raw_ctrl},
        "reference": {"x": {"kind": "step", "final": 1.0}},
        "simulation": {"t_end": 1.0, "dt": 0.01},
    }
    return engine.prepare(config.build(raw))


def drive(prep: engine.Prepared, ys: np.ndarray, rs: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Call the compiled step on a prescribed measurement sequence; returns (u, log)."""
    c = prep.controllers[0]
    cp, cs = c.cp[None].copy(), c.cs0[None].copy()  # one row: one variant
    us, logs = [], []
    for k, (y, r) in enumerate(zip(ys, rs, strict=True)):
        u = np.zeros((1, 1))
        log = np.zeros((1, len(c.log_names)))
        pid_step(k * dt, dt, np.zeros((1, 4)), np.array([y], dtype=float), np.array([r], dtype=float), cp, cs, u,
                 log, schedule_slots())  # fmt: skip
        us.append(u[0, 0])
        logs.append(log[0])
    return np.array(us), np.array(logs)


CONST = {
    "kind": "pid",
    "loops": {
        "theta": {"sign": -1, "schedule": {"kind": "constant", "kp": 30, "ki": 2, "kd": 4}},
        "x": {"sign": 1, "schedule": {"kind": "constant", "kp": -3, "ki": -1, "kd": -2}},
    },
}


def reference_pid(e: np.ndarray, kp: float, ki: float, kd: float, dt: float) -> np.ndarray:
    """u_k = kp e_k + ki sum_{j<=k} e_j dt + kd (e_k - e_{k-1})/dt, with e_{-1} = e_0."""
    integral = np.cumsum(e) * dt
    de = np.diff(e, prepend=e[0]) / dt
    return kp * e + ki * integral + kd * de


def test_two_loops_sum_into_one_force() -> None:
    dt = 0.01
    prep = build(CONST)
    rng = np.random.default_rng(3)
    n = 50
    y = np.column_stack([rng.normal(size=n).cumsum() * 0.01, rng.normal(size=n) * 0.05])  # (x, theta)
    r = np.column_stack([np.ones(n), np.zeros(n)])
    u, log = drive(prep, y, r, dt)
    u_theta = -reference_pid(r[:, 1] - y[:, 1], 30, 2, 4, dt)
    u_x = reference_pid(r[:, 0] - y[:, 0], -3, -1, -2, dt)
    assert np.allclose(u, u_theta + u_x, rtol=0, atol=1e-9)
    names = prep.controllers[0].log_names
    assert np.allclose(log[:, names.index("theta.u")], u_theta, atol=1e-9)
    assert np.allclose(log[:, names.index("x.kp")], -3)


def test_bias_is_added() -> None:
    prep = build({**CONST, "bias": {"F_x": 2.5}})
    u, _ = drive(prep, np.zeros((3, 2)), np.zeros((3, 2)), 0.01)
    assert np.allclose(u, 2.5)


def test_filtered_derivative_is_backward_euler_of_N_s_over_s_plus_N() -> None:
    dt, N = 0.01, 20.0
    ctrl = {
        "kind": "pid",
        "derivative": {"method": "filtered", "N": N},
        "loops": {
            "theta": {"schedule": {"kind": "constant", "kd": 1.0}},
            "x": {"schedule": {"kind": "constant"}},
        },
    }
    prep = build(ctrl)
    n = 40
    theta = np.sin(np.arange(n) * 0.3)
    y = np.column_stack([np.zeros(n), theta])
    u, _ = drive(prep, y, np.zeros((n, 2)), dt)
    e = -theta
    d = np.zeros(n)
    for k in range(1, n):
        d[k] = (d[k - 1] + N * (e[k] - e[k - 1])) / (1 + N * dt)
    assert np.allclose(u, d, atol=1e-12)


def test_derivative_on_measurement_ignores_reference_steps() -> None:
    dt = 0.01
    ctrl = {
        "kind": "pid",
        "derivative": {"on": "measurement"},
        "loops": {
            "x": {"schedule": {"kind": "constant", "kd": 1.0}},
            "theta": {"schedule": {"kind": "constant"}},
        },
    }
    prep = build(ctrl)
    r = np.zeros((4, 2))
    r[2:, 0] = 1.0  # reference step between samples 1 and 2, measurement constant
    u, _ = drive(prep, np.zeros((4, 2)), r, dt)
    assert np.allclose(u, 0.0)
    prep_err = build({**ctrl, "derivative": {"on": "error"}})
    u_err, _ = drive(prep_err, np.zeros((4, 2)), r, dt)
    assert u_err[2] == pytest.approx(1.0 / dt)  # the kick


@pytest.mark.parametrize("where", ["outside", "inside"])
def test_integral_with_time_varying_gain(where: str) -> None:
    """outside: u = k_i(t) * sum(e dt); inside: u = sum(k_i(t) e dt)."""
    dt = 0.1
    sched = {
        "kind": "time_ags",
        "kp": {"min": 0, "max": 0},
        "ki": {"min": 1, "max": 3},
        "kd": {"min": 0, "max": 0},
        "rate": {"kp": 0, "ki": 0.5, "kd": 0},
    }
    ctrl = {
        "kind": "pid",
        "integral": where,
        "loops": {"x": {"schedule": sched}, "theta": {"schedule": {"kind": "constant"}}},
    }
    prep = build(ctrl)
    n = 30
    r = np.column_stack([np.ones(n), np.zeros(n)])
    u, _ = drive(prep, np.zeros((n, 2)), r, dt)
    t = np.arange(n) * dt
    ki = 3 - 2 * np.exp(-0.5 * t)
    expected = ki * np.cumsum(np.ones(n)) * dt if where == "outside" else np.cumsum(ki * dt)
    assert np.allclose(u, expected, atol=1e-12)


def test_state_layout_matches_loop_count() -> None:
    prep = build(CONST)
    assert prep.controllers[0].cs0.size == 2 * LOOP_STATE.size


@pytest.mark.parametrize("kind", ["constant", "time_ags", "error_ags"])
def test_built_in_schedules_called_directly_equal_the_slot_table(x_error_raw: dict, kind: str) -> None:
    """The PID calls the built-in schedules directly; the same schedule registered by a third
    party (a distinct compiled function) goes through its slot. Both give the same run."""
    from typing import Literal

    from numba import njit
    from pydantic import create_model

    from nlcx.controllers import schedules as sch
    from nlcx.kernel.abi import CALLBACK_SIG

    builtin = registry.schedules.get(kind)
    copy_fn = njit(CALLBACK_SIG, error_model="numpy")(builtin.gains.py_func)
    name = f"{kind}_third_party"
    config_model = create_model(f"Config_{name}", __base__=builtin.Config, kind=(Literal[name], name))
    attributes = {"gains": staticmethod(copy_fn), "Config": config_model}
    third_party = type("ThirdParty", (type(builtin),), attributes)()
    registry.schedules.register(name, third_party)
    try:
        x_error_raw["controllers"].pop("conventional")
        loops = x_error_raw["controllers"]["proposed"]["loops"]
        ags = {k: v for k, v in loops["theta"]["schedule"].items() if k in ("kp", "ki", "kd", "rate")}
        schedule = {
            "constant": {"kind": "constant", "kp": 30, "ki": 2.5, "kd": 4},
            "time_ags": {**ags, "kind": "time_ags"},
            "error_ags": {**ags, "kind": "error_ags", "error": "abs"},
        }[kind]
        loops["theta"]["schedule"] = schedule
        direct = engine.run_experiment(config.build(copy.deepcopy(x_error_raw)))
        loops["theta"]["schedule"] = {**schedule, "kind": name}
        via_slot = engine.run_experiment(config.build(x_error_raw))
        cp_direct, cp_slot = direct.prepared.controllers[0].cp, via_slot.prepared.controllers[0].cp
        first_loop = HEAD.size + INPUT.size  # after the head and the one input's block
        direct_field, slot_field = LOOP.unpack(cp_direct, first_loop), LOOP.unpack(cp_slot, first_loop)
        assert direct_field["direct_schedule"] != 0 and slot_field["direct_schedule"] == 0
        (a,), (b,) = direct.runs, via_slot.runs
        assert np.array_equal(a.x, b.x) and np.array_equal(a.log, b.log)
        assert sch.schedule_index(name) >= 5
    finally:
        registry.schedules._entries.pop(name)
        registry.schedules._loaded.pop(name, None)


def saturated(anti_windup: str, ki: float, kb: float = 1.0) -> engine.Prepared:
    """x loop k_p = 10, k_i = ``ki`` on F_x limited to 5 N; the theta loop contributes nothing."""
    return build(
        {
            "kind": "pid",
            "loops": {
                "theta": {"sign": -1, "schedule": {"kind": "constant", "kp": 0, "ki": 0, "kd": 0}},
                "x": {"sign": 1, "schedule": {"kind": "constant", "kp": 10, "ki": ki, "kd": 0}},
            },
            "saturation": {"limits": {"F_x": 5.0}, "anti_windup": anti_windup, "kb": kb},
        }
    )


def drive_integral(prep: engine.Prepared, steps: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(u_k, the x loop's integral after step k) for e = r - y = 1 held."""
    c = prep.controllers[0]
    cp, cs = c.cp[None].copy(), c.cs0[None].copy()
    x_integral = LOOP_STATE.size * 1 + LOOP_STATE.at.integral  # loops in order theta, x
    us, integrals = [], []
    for k in range(steps):
        u = np.zeros((1, 1))
        log = np.zeros((1, len(c.log_names)))
        y = np.array([[0.0, 0.0]])  # (x, theta)
        r = np.array([[1.0, 0.0]])
        pid_step(k * dt, dt, np.zeros((1, 4)), y, r, cp, cs, u, log, schedule_slots())
        us.append(u[0, 0])
        integrals.append(cs[0, x_integral])
    return np.array(us), np.array(integrals)


def test_saturation_without_anti_windup_clips_and_winds_up() -> None:
    dt = 0.01
    u, integral = drive_integral(saturated("none", ki=4.0), 50, dt)
    assert np.all(u == 5.0)  # 10 e + 4 I > 5: clipped
    assert np.allclose(integral, dt * np.arange(1, 51), rtol=1e-12)  # I keeps integrating e


def test_clamping_holds_the_integral_only_while_it_pushes_into_the_limit() -> None:
    dt = 0.01
    u, integral = drive_integral(saturated("clamping", ki=4.0), 50, dt)
    assert np.all(u == 5.0) and np.all(integral == 0.0)  # k_i e > 0 would push further: held
    u, integral = drive_integral(saturated("clamping", ki=-4.0), 200, dt)
    # k_i e < 0 pulls the output back from the limit: the integral runs until 10 - 4 I = 5
    assert np.allclose(integral[:100], dt * np.arange(1, 101), rtol=1e-12)
    assert np.all(u <= 5.0) and u[-1] < 5.0


def test_back_calculation_feeds_back_the_excess() -> None:
    """I_k = I_{k-1} + e dt - K_b (u - u_sat) dt / k_i (gain outside the integral, sign +1)."""
    dt, ki, kb = 0.01, 4.0, 2.5
    u, integral = drive_integral(saturated("back_calculation", ki=ki, kb=kb), 300, dt)
    expected, i_k = [], 0.0
    for _ in range(300):
        i_k += 1.0 * dt
        v = 10.0 * 1.0 + ki * i_k
        i_k -= kb * (v - min(max(v, -5.0), 5.0)) * dt / ki
        expected.append(i_k)
    np.testing.assert_allclose(integral, expected, rtol=1e-12, atol=1e-15)
    assert np.all(u == 5.0)
    # the tracking loop drives 10 + k_i I towards the limit: I -> (5 - 10) / k_i from the excess
    assert integral[-1] < 0.0


def test_saturation_end_to_end_keeps_every_force_within_its_limit() -> None:
    raw = copy.deepcopy(CONST) | {"saturation": {"limits": {"F_x": 2.0}, "anti_windup": "clamping"}}
    (run,) = engine.run_experiment(build(raw).experiment).runs
    assert np.max(np.abs(run.u)) <= 2.0 and np.isclose(np.max(np.abs(run.u)), 2.0)


def test_a_limit_on_an_unknown_input_is_a_config_error() -> None:
    from nlcx.errors import ConfigError

    with pytest.raises(ConfigError, match=r"controllers\.c\.saturation\.limits\.F_y"):
        build(copy.deepcopy(CONST) | {"saturation": {"limits": {"F_y": 2.0}}})


@pytest.mark.parametrize("form", ["parallel", "ideal", "series"])
def test_pid_forms_are_simulinks(form: str) -> None:
    """ideal: u = k_p (e + k_i I + k_d D); series: u = k_p (1 + k_i/s)(1 + k_d s) e
    = k_p ((1 + k_i k_d) e + k_i I + k_d D); logged gains are the parallel ones."""
    dt, kp, ki, kd = 0.01, 3.0, 0.5, 0.2
    raw = {
        "kind": "pid",
        "form": form,
        "loops": {
            "theta": {"sign": 1, "schedule": {"kind": "constant", "kp": 0, "ki": 0, "kd": 0}},
            "x": {"sign": 1, "schedule": {"kind": "constant", "kp": kp, "ki": ki, "kd": kd}},
        },
    }
    e = np.sin(np.linspace(0, 3, 60))
    ys = np.column_stack([-e, np.zeros_like(e)])  # y_x = -e with r_x = 0
    u, logs = drive(build(raw), ys, np.zeros_like(ys), dt)
    parallel = {
        "parallel": (kp, ki, kd),
        "ideal": (kp, kp * ki, kp * kd),
        "series": (kp * (1 + ki * kd), kp * ki, kp * kd),
    }[form]
    np.testing.assert_allclose(u, reference_pid(e, *parallel, dt), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(logs[0, 4:7], parallel, rtol=1e-15)


def test_a_loop_in_degrees_sees_y_and_r_scaled() -> None:
    """scale = 180/pi: the loop's error, and so its output, is that of the angle in degrees."""
    dt = 0.01
    raw = copy.deepcopy(CONST)
    rng = np.random.default_rng(5)
    ys, rs = rng.normal(size=(30, 2)) * 0.1, np.zeros((30, 2))
    u_rad, _ = drive(build(raw), ys, rs, dt)
    raw["loops"]["theta"]["scale"] = 180 / np.pi
    u_deg, _ = drive(build(raw), ys, rs, dt)
    scaled = ys.copy()
    scaled[:, 1] *= 180 / np.pi
    u_manual, _ = drive(build(copy.deepcopy(CONST)), scaled, rs, dt)
    np.testing.assert_allclose(u_deg, u_manual, rtol=1e-12, atol=1e-12)
    assert not np.allclose(u_deg, u_rad)


def test_discrete_pid_is_the_difference_equation_at_its_samples_held_between() -> None:
    """T_s = 5 dt: at t_k = k T_s, u_k = k_p e_k + k_i T_s sum e_j + k_d (e_k - e_{k-1}) / T_s
    of the sampled errors; between samples the output is held (zero-order hold)."""
    dt, every = 0.01, 5
    raw = copy.deepcopy(CONST) | {"sample_time": every * dt}
    rng = np.random.default_rng(11)
    n = 60
    ys = np.column_stack([rng.normal(size=n).cumsum() * 0.01, rng.normal(size=n) * 0.05])
    rs = np.column_stack([np.ones(n), np.zeros(n)])
    u, logs = drive(build(raw), ys, rs, dt)
    picks = np.arange(0, n, every)
    ts = every * dt
    expected = -reference_pid(rs[picks, 1] - ys[picks, 1], 30, 2, 4, ts) + reference_pid(
        rs[picks, 0] - ys[picks, 0], -3, -1, -2, ts
    )
    np.testing.assert_allclose(u[picks], expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(u, np.repeat(u[picks], every)[:n])
    names = build(raw).controllers[0].log_names
    np.testing.assert_allclose(logs[picks, names.index("x.kp")], -3)


def test_a_discrete_pid_in_the_loop_holds_force_and_log_between_samples() -> None:
    """T_s = 5 dt over 1 s: the applied force and every logged value change only at t = k T_s."""
    (run,) = engine.run_experiment(build(copy.deepcopy(CONST) | {"sample_time": 0.05}).experiment).runs
    for signal in (run.u[:100, 0], *run.log[:100].T):
        blocks = signal.reshape(20, 5)
        np.testing.assert_array_equal(blocks, np.repeat(blocks[:, :1], 5, axis=1))
    assert len(np.unique(run.u[:100, 0])) == 20


def test_a_discrete_pid_sampled_every_step_is_the_continuous_one_bit_for_bit() -> None:
    raw = copy.deepcopy(CONST) | {"saturation": {"limits": {"F_x": 3.0}, "anti_windup": "back_calculation"}}
    continuous = engine.run_experiment(build(raw).experiment).runs[0]
    sampled = engine.run_experiment(build(raw | {"sample_time": 0.01}).experiment).runs[0]
    np.testing.assert_array_equal(continuous.u, sampled.u)
    np.testing.assert_array_equal(continuous.x, sampled.x)


def test_a_sample_time_below_the_step_is_a_config_error() -> None:
    from nlcx.errors import ConfigError

    with pytest.raises(ConfigError, match=r"controllers\.c\.sample_time = 0\.001: allowed: .*0\.01"):
        build(copy.deepcopy(CONST) | {"sample_time": 0.001})


_LOOP_SCHEDULES = {
    "constant": {"kind": "constant", "kp": 30, "ki": 2, "kd": 4},
    "time_ags": {"kind": "time_ags", "kp": {"min": 20, "max": 40}, "ki": {"min": 1, "max": 3},
                 "kd": {"min": 2, "max": 6}, "rate": {"kp": 1.5, "ki": 1.5, "kd": 0.5}},
    "error_ags": {"kind": "error_ags", "kp": {"min": 20, "max": 40}, "ki": {"min": 1, "max": 3},
                  "kd": {"min": 2, "max": 6}, "rate": {"kp": 2.0, "ki": 3.0, "kd": 2.0}, "error": "signed"},
    "fuzzy": {"kind": "fuzzy", "kp": {"min": 20, "max": 40}, "ki": {"min": 1, "max": 3}, "kd": {"min": 2, "max": 6}},
}  # fmt: skip

SIGNS = {"theta": -1, "x": 1}
STRUCTURES = {
    "constant, defaults": {"theta": "constant", "x": "constant"},
    "error-AGS, filtered on the measurement, gain inside, ideal form": {
        "theta": "error_ags", "x": "error_ags",
        "derivative": {"method": "filtered", "N": 50.0, "on": "measurement"}, "integral": "inside", "form": "ideal",
    },
    "time-AGS and constant, series form, set-point weight, clamping": {
        "theta": "time_ags", "x": "constant", "form": "series", "setpoint_weight": 0.5,
        "saturation": {"limits": {"F_x": 20.0}, "anti_windup": "clamping"},
    },
    "fuzzy through its slot, discrete, back-calculation": {
        "theta": "fuzzy", "x": "error_ags", "sample_time": 0.03,
        "saturation": {"limits": {"F_x": 20.0}, "anti_windup": "back_calculation", "kb": 3.0},
    },
}  # fmt: skip


@pytest.mark.parametrize("name", list(STRUCTURES))
def test_the_step_made_for_a_structure_equals_the_general_step_bit_for_bit(name: str) -> None:
    """A built PID runs the step compiled for its loop structure (``pid.step_for``). On three
    rows driven by random outputs and references, with schedules called directly and through
    their slot, every option of the loop and the head, its inputs, logs and state equal
    :func:`pid_step`'s, which reads the structure from the parameters, to the last bit."""
    options = dict(STRUCTURES[name])
    loops = {key: {"sign": sign, "schedule": _LOOP_SCHEDULES[options.pop(key)]} for key, sign in SIGNS.items()}
    prep = build({"kind": "pid", "loops": loops, **options})
    c = prep.controllers[0]
    structure = pid.structure_of(c.cp)
    assert c.step is not pid_step and c.step is pid.step_for(structure)
    assert (pid.VIA_SLOT in structure.direct) == ("fuzzy" in name)
    dt, rows = 0.01, 3
    states = []
    for step in (pid_step, c.step):
        cp, cs = np.tile(c.cp, (rows, 1)), np.tile(c.cs0, (rows, 1))
        u, log = np.zeros((rows, 1)), np.zeros((rows, len(c.log_names)))
        trace = []
        rng = np.random.default_rng(5)
        for k in range(120):
            y, r = rng.normal(scale=0.5, size=(rows, 2)), rng.normal(scale=0.5, size=(rows, 2))
            step(k * dt, dt, np.zeros((rows, 4)), y, r, cp, cs, u, log, callback_slots(c.callbacks))
            trace.append(np.concatenate([u.ravel(), log.ravel(), cs.ravel()]))
        states.append(np.array(trace))
    general, made = states
    assert np.array_equal(general.view(np.int64), made.view(np.int64))
    assert np.ptp(general[:, :rows]) > 1.0  # the inputs moved


def test_one_compiled_step_per_structure() -> None:
    """Controllers of the same structure share their step (one kernel group, one compiled
    function); another schedule, option or loop count gives another one."""
    first = build(CONST).controllers[0]
    other_gains = build({**CONST, "loops": {**CONST["loops"], "theta": {"sign": -1, "schedule": {
        "kind": "constant", "kp": 10, "ki": 0, "kd": 1}}}}).controllers[0]  # fmt: skip
    filtered = build({**CONST, "derivative": {"method": "filtered"}}).controllers[0]
    assert first.step is other_gains.step
    assert first.step is not filtered.step
    assert first.step.targetoptions.get("_nrt") is False  # the hot-loop rule (tests/test_hot_loop.py)
    assert pid.structure_of(first.cp).filtered == (0, 0) and pid.structure_of(filtered.cp).filtered == (1, 1)


def test_a_controller_is_built_once_for_variants_that_change_only_plant_numbers() -> None:
    """A sweep's variants share their validated controller section (``config.build(raw,
    like=base)``); a PID built for it is shared by the variants whose plant signals and
    equilibrium bias are the same, and equals one built afresh. With the equilibrium
    feed-forward the bias follows the plant's masses, and so does the controller."""
    raw = config.read_config(CONFIGS / "xyz_error_ags.yaml")
    raw["simulation"]["t_end"] = 0.1
    base = config.build(config.interpolate(raw))
    assert base.controllers[0].config.feedforward == "equilibrium"
    variants = []
    for M in (1.0, 1.0, 1.3):
        changed = copy.deepcopy(raw)
        changed["plant"]["params"]["M"] = M
        variants.append(engine.prepare(config.build(config.interpolate(changed), like=base)))
    same, again, heavier = (p.controllers[0] for p in variants)
    assert same is again  # equal plant numbers: one controller
    assert heavier is not same  # another bias: (M + m) g
    bias = [pid.input_blocks(c.cp)[-1]["bias"] for c in (same, heavier)]
    assert bias[1] > bias[0] > 0.0
    pid._BUILT.clear()
    fresh = engine.prepare(config.build(config.interpolate(copy.deepcopy(variants[2].experiment.raw)))).controllers[0]
    assert fresh is not heavier and np.array_equal(fresh.cp, heavier.cp) and fresh.step is heavier.step
    assert fresh.log_names == heavier.log_names and fresh.config == heavier.config


def test_the_build_cache_keeps_the_most_recently_used_controllers() -> None:
    """:class:`pid.BuiltControllers` holds at most ``size`` controllers, by the config object
    they were built from (and the plant's signals and bias): a config equal to a kept one but
    another object is another entry; the least recently used entry is dropped first."""
    prep = build(CONST)
    cfg, plant, controller = prep.experiment.controllers[0].config, prep.plant, prep.controllers[0]
    cache = pid.BuiltControllers(size=2)
    bias = np.zeros(1)
    keys = [cache.key(label, cfg, plant, "controllers.c", 0.01, bias) for label in ("a", "b", "c")]
    twin = cfg.model_copy()
    assert twin == cfg and cache.key("a", twin, plant, "controllers.c", 0.01, bias) != keys[0]
    for key in keys[:2]:
        cache.put(key, cfg, controller)
    assert cache.get(keys[0]) is controller  # "a" used last: "b" goes first
    cache.put(keys[2], cfg, controller)
    assert cache.get(keys[1]) is None and cache.get(keys[0]) is controller and cache.get(keys[2]) is controller


def test_build_takes_a_config_whose_schedules_are_still_mappings() -> None:
    """``config.build`` hands the PID its section with every schedule validated; a section
    built by hand, its schedules plain mappings, is normalized by ``build`` and gives the same
    controller."""
    prep = build(CONST)
    by_hand = pid.PIDConfig.model_validate(CONST)
    assert isinstance(by_hand.loops["x"].schedule, dict)
    c = pid.MultiLoopPID().build("c", by_hand, prep.plant, "controllers.c", dt=0.01)
    assert np.array_equal(c.cp, prep.controllers[0].cp) and c.step is prep.controllers[0].step
    assert c.config == prep.controllers[0].config


def test_the_step_factory_gives_the_general_step_for_no_structure() -> None:
    """``step_for(None)`` is :func:`pid_step` (the structure read from each row); a built
    controller carries it as its general step beside its own."""
    c = build(CONST).controllers[0]
    assert pid.step_for(None) is pid_step and c.general_step is pid_step
    assert pid.step_for(pid.structure_of(c.cp)) is c.step is not pid_step


def test_each_structure_s_step_compiles_under_a_symbol_of_its_own() -> None:
    """numba names a compiled function's symbol after its qualified name and a counter unique
    only within one process; steps of different structures cached by different processes
    must not share a symbol (a process loading both would run one's code for the other), so
    the structure is in the name of its step and of the compiled symbol."""
    from nlcx.controllers import pid_step
    from nlcx.kernel.abi import CONTROLLER_SIG

    exp = config.load(CONFIGS / "x_error_ags.yaml", ["simulation.t_end=0.1"])
    steps = {item.controller.step for item in engine.items_of(engine.prepare(exp))}
    assert len(steps) == 2  # the conventional and the error-AGS loop structures
    symbols = set()
    for step in steps:
        step.compile(CONTROLLER_SIG)  # compiled, or loaded from the disk cache
        structure = step.py_func.__closure__[0].cell_contents
        assert step.py_func.__qualname__ == pid_step.structure_name(structure)
        (overload,) = step.overloads.values()
        assert pid_step.structure_name(structure) in overload.fndesc.mangled_name
        symbols.add(overload.fndesc.mangled_name)
    assert len(symbols) == 2

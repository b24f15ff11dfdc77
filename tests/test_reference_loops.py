"""The benchmark's hand-written loops (benchmarks/reference.py) simulate nlcx's closed loop, so
the speeds the benchmark compares are those of the same computation: the loop whose PID reads
nlcx's packed rows equals nlcx's kernel bit for bit; the limit, with libm's sin and cos where
nlcx has its own (within 1 ulp, nlcx.kernel.trig), stops at the same samples and differs by
rounding; the limit's loop stepped in lock step with nlcx's sin and cos equals nlcx's kernel bit
for bit. The reference's PID and plant are its own copies: an independent check of nlcx's."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from nlcx import config, engine

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import reference  # noqa: E402

#: nominal, heavier, lighter and one that falls (theta leaves its bound): both ways a run ends
PARAMS = [(1.0, 0.1, 0.3), (1.2, 0.12, 0.36), (0.8, 0.08, 0.24), (0.05, 2.0, 0.05)]


def _nlcx_runs(params: list[tuple[float, float, float]]) -> tuple[dict, list, list[engine.Run], np.ndarray]:
    """(config, items, nlcx's runs, p rows) of the x pendulum's error-AGS loop for 4 s, one
    variant per (M, m, l), simulated by nlcx in one batch."""
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    del raw["controllers"]["conventional"]
    raw["simulation"]["t_end"] = 4.0
    prepared = []
    for M, m, l in params:
        raw["plant"]["params"].update(M=M, m=m, l=l)
        prepared.append(engine.prepare(config.build(config.interpolate(raw))))
    items = [item for p in prepared for item in engine.items_of(p)]
    ours = engine.simulate_items(items, prepared[0].grid, "rk4", record_logs=False)
    assert {run.status for run in ours} == {"ok", "unstable"}
    p = np.array([[M, m, l, raw["plant"]["params"]["g"]] for M, m, l in params])
    return raw, items, ours, p


def test_reference_loops_compute_nlcx_closed_loop() -> None:
    raw, items, ours, p = _nlcx_runs(PARAMS)
    dt, n_k = raw["simulation"]["dt"], ours[0].t.size
    loops = raw["controllers"]["proposed"]["loops"]
    pid = reference.packed_pid([item.controller for item in items])
    for loop in ("limit", "nlcx_pid"):
        X, U, n_valid = np.empty((len(PARAMS), n_k, 4)), np.empty((len(PARAMS), n_k)), np.empty(len(PARAMS), int)
        if loop == "limit":
            theta, x = (reference.loop_parameters(loops[s]["schedule"]) for s in ("theta", "x"))
            reference.simulate(p, theta, x, dt, n_k - 1, np.pi / 2, X, U, n_valid, True)
        else:
            reference.simulate_nlcx_pid(p, pid, items[0].ref, dt, n_k - 1, np.pi / 2, X, U, n_valid)
        for b, run in enumerate(ours):
            assert n_valid[b] == run.t.size, (loop, b)
            x_ref, u_ref = X[b, : n_valid[b]], U[b, : n_valid[b]]
            if loop == "nlcx_pid":
                assert np.array_equal(x_ref, run.x) and np.array_equal(u_ref, run.u[:, 0]), b
            else:
                assert np.max(np.abs(x_ref - run.x)) < 1e-10 and np.max(np.abs(u_ref - run.u[:, 0])) < 1e-9, b
                assert not np.array_equal(x_ref, run.x), "the limit's libm sin/cos should differ somewhere"


@pytest.fixture(scope="module")
def batch_of_37() -> tuple[dict, list, list[engine.Run], np.ndarray]:
    """37 variants, a quarter of them falling: a vector loop over them (8 lanes on AVX-512,
    unrolled up to 4 times) and its scalar remainder both run, before and after variants leave
    the batch. Simulated by nlcx once for the tests that compare with it."""
    return _nlcx_runs((PARAMS * 10)[:37])


def test_lockstep_loop_computes_nlcx_bits_in_vector_code_and_its_remainder(batch_of_37: tuple) -> None:
    raw, _, ours, p = batch_of_37
    dt, n_k = raw["simulation"]["dt"], ours[0].t.size
    theta, x = (
        reference.loop_parameters(raw["controllers"]["proposed"]["loops"][s]["schedule"]) for s in ("theta", "x")
    )
    X, U, n_valid = np.full((37, n_k, 4), np.nan), np.full((37, n_k), np.nan), np.empty(37, int)
    reference.simulate_lockstep(p, theta, x, dt, n_k - 1, np.pi / 2, X, U, n_valid)
    _assert_same_bits(ours, X, U, n_valid)


def _assert_same_bits(ours: list[engine.Run], X: np.ndarray, U: np.ndarray, n_valid: np.ndarray) -> None:
    """Each of nlcx's runs ends at the same sample as the loop's and has its states and inputs
    to the last bit (compared as int64: signed zeros count)."""
    for b, run in enumerate(ours):
        assert n_valid[b] == run.t.size, b
        assert np.array_equal(X[b, : n_valid[b]].view(np.int64), run.x.view(np.int64)), b
        assert np.array_equal(U[b, : n_valid[b]].view(np.int64), run.u[:, 0].view(np.int64)), b


def test_the_reference_writes_its_pid_and_plant_out() -> None:
    """Of nlcx's compiled functions the reference calls only the sine and cosine (by design: the
    loops that compute nlcx's bits use them); what it takes from nlcx's PID are the layout
    offsets and codes of the packed rows."""
    taken = {name: value for name, value in vars(reference).items() if _from_nlcx(value)}
    compiled = {name for name, value in taken.items() if hasattr(value, "py_func")}  # numba's compiled functions
    assert compiled == {"sincos", "_sincos_reduced"}
    assert {"H", "I", "L", "S", "EA"} <= set(taken)


def _from_nlcx(value: Any) -> bool:
    module = getattr(value, "__module__", None) or getattr(getattr(value, "py_func", None), "__module__", "")
    return isinstance(module, str) and module.startswith("nlcx.")


def test_the_reference_refuses_a_pid_it_is_not_written_for() -> None:
    """Its PID is the error-AGS loop of benchmark (b): a conventional PID's rows are refused,
    not simulated wrongly."""
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    raw["simulation"]["t_end"] = 0.1
    prepared = engine.prepare(config.build(config.interpolate(raw)))
    by_label = {c.label: c for c in prepared.controllers}
    proposed, conventional = by_label["proposed"], by_label["conventional"]
    cp, cs = reference.packed_pid([proposed])
    assert cp.shape == (1, proposed.cp.size) and cs.shape == (1, proposed.cs0.size)
    with pytest.raises(ValueError, match="not written for"):
        reference.packed_pid([conventional])

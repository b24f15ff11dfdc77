"""The benchmark's hand-written loops (benchmarks/reference.py) simulate nlcx's closed loop, so
the speeds the benchmark compares are those of the same computation: the loop with nlcx's PID
equals nlcx's kernel bit for bit; the limit, with libm's sin and cos where nlcx has its own
(within 1 ulp, nlcx.kernel.trig), stops at the same samples and differs by rounding."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import yaml

from nlcx import config, engine

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import reference  # noqa: E402


def test_reference_loops_compute_nlcx_closed_loop() -> None:
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    del raw["controllers"]["conventional"]
    raw["simulation"]["t_end"] = 4.0
    # nominal, heavier, lighter and one that falls (theta leaves its bound): both ways a run ends
    params = [(1.0, 0.1, 0.3), (1.2, 0.12, 0.36), (0.8, 0.08, 0.24), (0.05, 2.0, 0.05)]
    prepared = []
    for M, m, l in params:
        raw["plant"]["params"].update(M=M, m=m, l=l)
        prepared.append(engine.prepare(config.build(config.interpolate(raw))))
    items = [item for p in prepared for item in engine.items_of(p)]
    ours = engine.simulate_items(items, prepared[0].grid, "rk4", record_logs=False)
    assert {run.status for run in ours} == {"ok", "unstable"}
    p = np.array([[M, m, l, raw["plant"]["params"]["g"]] for M, m, l in params])
    dt, n_k = raw["simulation"]["dt"], prepared[0].grid.t.size
    loops = raw["controllers"]["proposed"]["loops"]
    pid = reference.packed_pid([item.controller for item in items])
    for loop in ("limit", "nlcx_pid"):
        X, U, n_valid = np.empty((len(params), n_k, 4)), np.empty((len(params), n_k)), np.empty(len(params), int)
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

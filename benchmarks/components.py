"""Where benchmark (b)'s time goes, part by part, in one process. Run from the repository root:

    python benchmarks/components.py | tee benchmarks/components.txt

The kernel, in ns per variant-step on batches of 100 of (b)'s variants (CPU time, best of a
few repeats):
- the whole closed loop, as a sweep batch calls it (benchmark (b)'s "kernel alone");
- the controller step alone: nlcx's PID driven by the outputs the closed loop recorded, called
  through a controller function value as the kernel calls it, at 100, 8, 2 and 1 rows, less
  the same loop with a step that does nothing (the copies of x, y and r and the call); the
  inputs it computes are checked, bit for bit, against those the closed loop recorded; at 100
  rows also the general ``pid_step``, which reads the loop structure from each row, where the
  controller runs the step compiled for its structure (``pid.step_for``);
- the plant's right-hand side alone (four calls a Runge-Kutta step) and, inside it, the sine
  and cosine of the batch's angles;
- libm's exp, as often as the PID calls it (the thesis's schedules share k_p's rate with
  k_i's, so two a loop).
A sweep batch, in ms per batch of 100 variants, with a timer around each stage (no profiler):
resolving, validating and preparing the variants' configs, the kernel, the metrics, writing
the part files, and the rest of the batch.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit, types

from nlcx import config, engine, report
from nlcx import sweeps as sweep
from nlcx.controllers import pid
from nlcx.controllers.base import ControllerInstance
from nlcx.engine import pipeline as engine_pipeline
from nlcx.engine import simulate as engine_simulate
from nlcx.kernel.abi import ARR3, F64, I64, MAT, CallbackTuple, ControllerFn, RhsFn, callback_slots
from nlcx.kernel.trig import sincos_column

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run import kernel_batches, kernel_pass, planned_batches, prepared_variants, sweep_config


def cpu_best(fn: Callable[[], Any], repeats: int = 5) -> float:
    """The least CPU time of ``repeats`` calls of ``fn``, s."""
    best = math.inf
    for _ in range(repeats):
        start = time.process_time()
        fn()
        best = min(best, time.process_time() - start)
    return best


@njit(types.void(F64, F64, MAT, MAT, MAT, MAT, MAT, MAT, MAT, CallbackTuple), cache=True)
def idle_step(t, dt, x, y, r, cp, cs, u, log, callbacks):  # pragma: no cover - compiled
    """A controller step that does nothing (the call's own cost)."""


@njit(types.void(ControllerFn, CallbackTuple, MAT, MAT, ARR3, ARR3, ARR3, F64, I64, ARR3), cache=True)
def drive_controller(step, callbacks, cp, cs0, X, Y, R, dt, n_log, U):  # pragma: no cover - compiled
    """``step`` on the rows of cp at every sample of the recorded X, Y, R (K+1, B, .), each
    sample's values copied into the work rows first, as the kernel's sampling does; its
    inputs into U (K+1, B, n_u)."""
    n_rows = cp.shape[0]
    x, y, r = np.empty((n_rows, X.shape[2])), np.empty((n_rows, Y.shape[2])), np.empty((n_rows, R.shape[2]))
    u, log = np.zeros((n_rows, U.shape[2])), np.zeros((n_rows, n_log))
    cs = cs0[:n_rows].copy()
    for k in range(X.shape[0]):
        for b in range(n_rows):
            for i in range(X.shape[2]):
                x[b, i] = X[k, b, i]
            for i in range(Y.shape[2]):
                y[b, i] = Y[k, b, i]
            for i in range(R.shape[2]):
                r[b, i] = R[k, b, i]
        step(k * dt, dt, x, y, r, cp, cs, u, log, callbacks)
        for b in range(n_rows):
            for j in range(U.shape[2]):
                U[k, b, j] = u[b, j]


@njit(types.float64(RhsFn, MAT, MAT, MAT, MAT, I64, I64), cache=True)
def drive_rhs(rhs, x, u, p, dx, nb, calls):  # pragma: no cover - compiled
    """``calls`` calls of the plant's right-hand side on the first nb columns."""
    total = 0.0
    for _ in range(calls):
        rhs(0.0, x, u, p, dx, nb)
        total += dx[1, 0]
    return total


@njit(cache=True)
def drive_sincos(angles, nb, calls, sines, cosines):  # pragma: no cover - compiled
    """``calls`` calls of the sine and cosine column of nb angles."""
    total = 0.0
    for _ in range(calls):
        sincos_column(angles, nb, sines, cosines)
        total += sines[0]
    return total


@njit(cache=True)
def drive_exp(arguments, calls):  # pragma: no cover - compiled
    """libm's exp of every argument, ``calls`` times."""
    total = 0.0
    for _ in range(calls):
        for a in arguments:
            total += math.exp(a)
    return total


def kernel_parts(prepared: list[engine.Prepared]) -> dict[str, float]:
    """ns per variant-step of the closed loop and of its parts (see the module docstring)."""
    grid = prepared[0].grid
    batches = kernel_batches(prepared)
    runs = [run for items in batches for run in engine.simulate_items(items, grid, "rk4", record_logs=False)]
    steps = sum(run.t.size - 1 for run in runs)
    out = {"closed loop": 1e9 * cpu_best(lambda: kernel_pass(batches, grid)) / steps}
    items = [item for items in batches for item in items]
    ok = [i for i, run in enumerate(runs) if run.status == "ok"][:100]
    plant = items[0].plant
    picks = [int(np.flatnonzero(row)[0]) for row in plant.C]
    X = np.ascontiguousarray(np.stack([runs[i].x for i in ok], axis=1))
    Y = np.ascontiguousarray(X[:, :, picks])
    R = np.ascontiguousarray(np.stack([runs[i].r for i in ok], axis=1))
    controllers: list[ControllerInstance] = [items[i].controller for i in ok]
    cp = np.ascontiguousarray(np.stack([c.cp for c in controllers]))
    cs0 = np.ascontiguousarray(np.stack([c.cs0 for c in controllers]))
    slots = callback_slots(controllers[0].callbacks)
    n_u, n_log, dt, n_k = len(plant.inputs), len(controllers[0].log_names), grid.dt, X.shape[0]
    recorded = np.stack([runs[i].u for i in ok], axis=1)
    for rows in (100, 8, 2, 1):
        rec = (np.ascontiguousarray(a[:, :rows]) for a in (X, Y, R))  # only the rows driven: no cache misses
        U = np.empty((n_k, rows, n_u))
        args = (np.ascontiguousarray(cp[:rows]), cs0, *rec, dt, n_log, U)
        step = cpu_best(functools.partial(drive_controller, controllers[0].step, slots, *args), 3)
        same = np.array_equal(U.view(np.int64), recorded[:, :rows].view(np.int64))
        idle = cpu_best(functools.partial(drive_controller, idle_step, slots, *args), 3)
        out[f"controller step, {rows} rows"] = 1e9 * (step - idle) / (n_k * rows)
        out[f"idle step and copies, {rows} rows"] = 1e9 * idle / (n_k * rows)
        if not same:
            raise SystemExit(f"the controller driven alone ({rows} rows) did not reproduce the closed loop's inputs")
        if rows == 100:  # the general PID step, which reads the loop structure from each row
            general = cpu_best(functools.partial(drive_controller, pid.pid_step, slots, *args), 3)
            if not np.array_equal(U.view(np.int64), recorded[:, :rows].view(np.int64)):
                raise SystemExit("the general PID step did not reproduce the closed loop's inputs")
            out["general pid_step, 100 rows"] = 1e9 * (general - idle) / (n_k * rows)
    rng = np.random.default_rng(0)
    x = np.ascontiguousarray(X[1000].T)  # (n, 100): the batch's state at t = 1 s, by columns
    u = np.ascontiguousarray(rng.normal(size=(n_u, 100)))
    p = np.ascontiguousarray(np.stack([items[i].plant.p for i in ok], axis=1))
    dx = np.zeros_like(x)
    calls = 100_000
    out["plant rhs, 4 calls"] = 4e9 * cpu_best(lambda: drive_rhs(plant.rhs, x, u, p, dx, 100, calls)) / (calls * 100)
    angles = np.ascontiguousarray(x[2])
    out["of which sin and cos, 4 columns"] = (
        4e9 * cpu_best(lambda: drive_sincos(angles, 100, calls, dx[1], dx[3])) / (calls * 100)
    )
    arguments = -0.1 * np.abs(rng.normal(size=100))
    out["libm exp, 4 calls"] = 4e9 * cpu_best(lambda: drive_exp(arguments, calls // 10)) / (calls // 10 * 100)
    return out


def batch_stages(batches: int = 6) -> dict[str, float]:
    """ms per batch of 100 variants of each stage of a sweep batch (timers around each)."""
    spent: dict[str, float] = {}
    originals = []

    def timed(owner: Any, name: str, stage: str) -> None:
        original = getattr(owner, name)
        originals.append((owner, name, original))

        @functools.wraps(original)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                spent[stage] = spent.get(stage, 0.0) + time.perf_counter() - start

        setattr(owner, name, wrapper)

    runs = planned_batches(batches + 1)
    sweep.run_batch(runs[0])  # loaded and warm
    for owner, name, stage in (
        (sweep.Variant, "resolve", "resolve the variant's config"),
        (config, "build", "validate it"),
        (engine, "prepare", "prepare it (plant, controller, references)"),
        (engine_simulate, "simulate_items", "kernel"),
        (engine_pipeline, "measure_experiments", "metrics"),
        (report, "write_csv", "write the part files"),
    ):
        timed(owner, name, stage)
    try:
        start = time.perf_counter()
        for batch in runs[1:]:
            sweep.run_batch(batch)
        wall = time.perf_counter() - start
    finally:
        for owner, name, original in originals:
            setattr(owner, name, original)
    out = {stage: 1e3 * seconds / batches for stage, seconds in spent.items()}
    out["rest of the batch"] = 1e3 * wall / batches - sum(out.values())
    out["batch"] = 1e3 * wall / batches
    return out


def main() -> None:
    prepared = prepared_variants(sweep_config(600), 600)
    print(f"nlcx components of benchmark (b), {time.strftime('%Y-%m-%d')}, one process")
    parts = kernel_parts(prepared)
    print("kernel, ns per variant-step (CPU time, batches of 100 of (b)'s variants):")
    for name, ns in parts.items():
        print(f"  {name:40s} {ns:6.1f}")
    print("sweep batch, ms per batch of 100 variants (wall time):")
    for name, ms in batch_stages().items():
        print(f"  {name:40s} {ms:6.1f}")


if __name__ == "__main__":
    main()

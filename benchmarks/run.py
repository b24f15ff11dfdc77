"""nlcx speed benchmarks (targets a-f). Run from the repository root:

    python benchmarks/run.py | tee benchmarks/latest.txt      (or: make bench)

It also rewrites the speed table of README.md (between the ``speed-table`` markers) from the
figures it measured; ``python benchmarks/run.py --table-from benchmarks/latest.txt`` rewrites
the table from a saved output without running anything.

(a) configs/xyz_error_ags.yaml: simulation of both controllers after warm-up (target <= 0.2 s),
    `nlcx run` end to end with a warm numba cache (target <= 1.5 s); and the first
    `nlcx run configs/x_error_ags.yaml` after `pip install .` in a clean venv, its numba cache
    empty, compiling everything it needs (the median of three, target <= 10 s), with where its
    time went.
(b) a 10 000-variant x-pendulum sweep (error-AGS PID, M, m, l within +-20 %, 20 s at 1 ms) with
    --jobs 2 (target <= 30 s wall, <= 2 GB peak memory of the whole process tree), beside the
    limit reference (benchmarks/reference.py) of the same variants, alternated in one run:
    ns per variant-step, simulated seconds per wall second and their ratio (goal <= 1.3); and
    the kernels alone in one process: nlcx's kernel, the reference's loop with its PID reading
    nlcx's packed rows (and nlcx's sin/cos) and the limit, per variant-step; that loop checked bit
    for bit against nlcx's,
    the limit (libm's sin and cos, nlcx's own: docs/assumptions.md A30) to rounding; and the
    floor of the sweep at this kernel's speed: the parent's serial time (its manifest.json's
    timings) plus the kernel's CPU time on two cores; and the limit's loop stepped in lock step
    (reference.simulate_lockstep, checked bit for bit against nlcx): what nlcx's kernel would cost
    with the plant and the PID compiled into it, and the sweep's time at that kernel speed.
(c) `nlcx reproduce` of every thesis figure and table, calibration excluded (target <= 120 s).
(d) the experiment of (a), proposed controller, through python-control's input_output_response
    and scipy's solve_ivp (RK45, the PID integrators in the ODE), with the speed ratios and the
    agreement of the trajectories.
(f) (b)'s loop over 0.1 s, a million variants, the default `nlcx sweep --jobs 2` (target <= 30 s and
    <= 2 GB, <= 10 us a variant outside the kernel), its first 10 000 variants checked against the
    per-variant path; and the parent's serial time (target <= 0.5 s + 1 us a variant).
(e) with --fresh-clone: `make run` in a fresh clone with pip's cache off (target <= 90 s).
(i) (b)'s 10 000-variant sweep with its PID replaced by an LQR law written in plain Python
    (`@nlcx.controller`, named by the config's `imports:`), alternated in one run with (b)'s
    sweep (the built-in PID), the default command (report on): their wall times and their
    ratio (target <= 1.3).
(h) `nlcx identify benchmarks/identify_subset.yaml --jobs 2`: eight hypotheses of the pendulum
    identification study, the literal fit first (best of two runs, its kernels compiled).
Machines are noisy: each timing is the best of a few repeats, and ratios come from one run.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
NLCX = [sys.executable, "-m", "nlcx.cli"]


@functools.cache
def _scratch_root() -> tempfile.TemporaryDirectory:
    """The benchmark's one temporary directory; Python removes it, and all in it, at exit."""
    return tempfile.TemporaryDirectory(prefix="nlcx-bench-")


def scratch() -> Path:
    """A new empty directory inside the benchmark's temporary directory (gone when it ends: a
    fresh clone and a sweep's outputs take about a gigabyte)."""
    return Path(tempfile.mkdtemp(dir=_scratch_root().name))


def best(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def _process_memory_kb(pid: int) -> tuple[int, int]:
    """(Rss, Pss) of one process in kB. Pss splits each page among the processes that share it
    (fork's copy-on-write pages, libraries), so Pss summed over processes counts each page once."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as fh:
            fields = {k: int(v.split()[0]) for k, _, v in (line.partition(":") for line in fh) if k in ("Rss", "Pss")}
        return fields["Rss"], fields["Pss"]
    except (FileNotFoundError, KeyError, ValueError):
        with open(f"/proc/{pid}/status") as fh:
            rss = next((int(line.split()[1]) for line in fh if line.startswith("VmRSS:")), 0)
        return rss, rss


def tree_memory_kb(pid: int) -> tuple[int, int]:
    """(Rss summed, Pss summed) over a process and all its descendants (Linux /proc), kB."""
    rss_total, pss_total, stack = 0, 0, [pid]
    while stack:
        p = stack.pop()
        try:
            rss, pss = _process_memory_kb(p)
            rss_total, pss_total = rss_total + rss, pss_total + pss
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as fh:
                    stack += [int(c) for c in fh.read().split()]
        except (FileNotFoundError, ProcessLookupError, StopIteration):
            continue
    return rss_total, pss_total


def run_timed(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> tuple[float, str]:
    """(wall s, stdout) of a command, nothing else running beside it in this process."""
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stdout}")
    return wall, proc.stdout


def run_measured(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> tuple[float, tuple[int, int], str]:
    """(wall s, (peak tree Rss kB, peak tree Pss kB), stdout) of a command, sampling memory every
    50 ms. The Rss sum counts a page shared by forked workers once per worker, so it overstates;
    the Pss sum is the memory the tree occupies. A sample reads every process's smaps_rollup,
    which walks its page tables: a sizeable share of a core, which a 2-core machine takes from
    the command. So the speed targets are timed by
    :func:`run_timed`, and memory is measured in a run of its own."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    peak = [0, 0]

    def sample() -> None:
        while proc.poll() is None:
            rss, pss = tree_memory_kb(proc.pid)
            peak[0], peak[1] = max(peak[0], rss), max(peak[1], pss)
            time.sleep(0.05)

    watcher = threading.Thread(target=sample, daemon=True)
    watcher.start()
    out, _ = proc.communicate()
    watcher.join()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{out}")
    return time.perf_counter() - start, (peak[0], peak[1]), out


def bench_a() -> dict[str, float]:
    from nlcx import config, engine

    start = time.perf_counter()
    exp = config.load(ROOT / "configs" / "xyz_error_ags.yaml")
    prepared = engine.prepare(exp)
    engine.evaluate([prepared], measure=False)
    warmup = time.perf_counter() - start
    sim = best(lambda: engine.evaluate([prepared], measure=False), 5)
    out = scratch()
    cmd = [*NLCX, "run", "configs/xyz_error_ags.yaml", "--out", str(out / "a"), "-q"]
    subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True)
    end_to_end = best(lambda: subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True), 3)
    return {"simulate_s": sim, "warmup_in_process_s": warmup, "end_to_end_s": end_to_end, **cold_runs()}


#: The config of the first run after installing (benchmark (a)'s cold run).
COLD_CONFIG = "configs/x_error_ags.yaml"
#: The phases of a run's manifest.json (``timings_s``) that the cold run's breakdown names.
COLD_PHASES = ("simulate", "metrics", "write")


def clean_install() -> Path:
    """A new virtual environment with nlcx installed from this working tree as a user installs it
    (``pip install .``: not editable, no extras); its ``bin`` directory."""
    venv = scratch() / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = [str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", str(ROOT)]
    subprocess.run(pip, check=True, capture_output=True)
    return venv / "bin"


def emptied_cache(bin_dir: Path) -> None:
    """Remove the numba cache of the nlcx installed beside ``bin_dir`` (its files and its source stamp)."""
    code = "from nlcx import compiled_cache as c\nfor path in [*c.cache_files(), c.STAMP]: path.unlink(missing_ok=True)"
    subprocess.run([str(bin_dir / "python"), "-c", code], cwd=bin_dir, check=True)  # not the checkout's nlcx


def cold_runs(repeats: int = 3) -> dict[str, Any]:
    """The first ``nlcx run`` of :data:`COLD_CONFIG` after ``pip install .`` in a clean venv, run from
    the repository root as a user of the clone runs it (notice on), its cache emptied before
    each repeat: the wall times, their median, and where the median run's time went (before the
    run's clock starts: the process's start, the imports and the kernel's compile; then the
    manifest's phases)."""
    start = time.perf_counter()
    bin_dir = clean_install()
    install = time.perf_counter() - start
    runs = []
    for _ in range(repeats):
        emptied_cache(bin_dir)
        out = scratch() / "cold"
        wall, _ = run_timed([str(bin_dir / "nlcx"), "run", COLD_CONFIG, "--out", str(out)], ROOT)
        manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
        phases = {k: float(manifest["timings_s"].get(k, 0.0)) for k in COLD_PHASES}
        runs.append({"wall_s": wall, "before_clock_s": wall - float(manifest["duration_s"]), **phases})
    median = sorted(runs, key=lambda r: r["wall_s"])[len(runs) // 2]
    return {"cold_compile_run_s": median["wall_s"], "cold_walls_s": [r["wall_s"] for r in runs],
            "cold_median_phases_s": median, "clean_install_s": install}  # fmt: skip


def sweep_config(n: int) -> dict[str, Any]:
    """Benchmark (b)'s sweep: the error-AGS PID of configs/x_error_ags.yaml on the x pendulum,
    M, m, l uniform within +-20 %, batches of 100."""
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    del raw["controllers"]["conventional"]
    raw.update(name="bench_sweep", outputs={"figure": False, "timeseries": False, "gains_figure": False})
    params = {k: {"dist": "uniform", "relative": 0.2} for k in ("plant.params.M", "plant.params.m", "plant.params.l")}
    raw["sweep"] = {"seed": 1, "random": {"n": n, "params": params}, "batch_size": 100}
    return raw


def prepared_variants(raw: dict[str, Any], n: int) -> list[Any]:
    """The first ``n`` variants of the sweep ``raw``, prepared as a sweep batch prepares them."""
    from nlcx import config, engine
    from nlcx import sweeps as sweep

    base_raw = {k: v for k, v in raw.items() if k != "sweep"}
    spec = sweep.SweepSection.model_validate({**raw["sweep"], "random": {**raw["sweep"]["random"], "n": n}})
    interpolated = config.Interpolated.of(base_raw)
    base = config.build(interpolated.resolved)
    return [engine.prepare(config.build(v.resolve(interpolated), like=base))
            for v in sweep.expand(spec, interpolated.resolved)]  # fmt: skip


def kernel_batches(prepared: list[Any]) -> list[list[Any]]:
    """The closed loops of ``prepared`` in kernel calls of 100 variants, as a sweep batch makes them."""
    from nlcx import engine

    return [[item for p in prepared[k : k + 100] for item in engine.items_of(p)] for k in range(0, len(prepared), 100)]


def kernel_pass(batches: list[list[Any]], grid: Any) -> None:
    """Every batch through nlcx's kernel, as a sweep batch calls it."""
    from nlcx import engine

    for items in batches:
        engine.simulate_items(items, grid, "rk4", record_logs=False)


def planned_batches(n_batches: int) -> list[Any]:
    """Benchmark (b)'s sweep of 100 * n_batches variants, written to a scratch directory and
    planned in batches of 100 (``sweep.run_batch`` runs one; its part files go there too)."""
    from nlcx import sweeps as sweep

    work = scratch()
    path = work / "sweep.yaml"
    path.write_text(yaml.safe_dump(sweep_config(100 * n_batches)))
    base_raw, spec, _ = sweep.load(path)
    variants, hashes = sweep.plan(base_raw, spec)
    return [sweep.Batch(base_raw, variants[k : k + 100], hashes[k : k + 100], work / "out", False)
            for k in range(0, len(variants), 100)]  # fmt: skip


def _children_cpu_s() -> float:
    """CPU seconds (user + system) of this process's finished children and their descendants."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def report_seconds(output: str) -> float:
    """The report's time in the output of ``nlcx sweep`` (its line ``report PATH (S s)``)."""
    match = re.search(r"^report .* \(([0-9.]+) s\)$", output, re.MULTILINE)
    if match is None:
        raise RuntimeError(f"no report line in the sweep's output:\n{output}")
    return float(match.group(1))


def bench_b(n: int = 10_000, repeats: int = 2) -> dict[str, Any]:
    """nlcx's sweep and the hand-written limit reference (benchmarks/reference.py) of the same
    variants on two processes each, alternated, in one run: wall times and their ratio."""
    raw = sweep_config(n)
    work = scratch()
    path = work / "sweep.yaml"
    path.write_text(yaml.safe_dump(raw))
    walls, cpus, limits, reports = [], [], [], []

    def command(out: str) -> list[str]:  # the default command (report on); a fresh directory: nothing resumed
        return [*NLCX, "sweep", str(path), "--jobs", "2", "--out", str(work / out)]

    for repeat in range(repeats):
        before = _children_cpu_s()
        wall, out = run_timed(command(f"out{repeat}"), ROOT)
        cpus.append(_children_cpu_s() - before)
        walls.append(wall)
        reports.append(report_seconds(out))
        limits.append(limit_reference(raw))
    sampled_wall, peak_kb, _ = run_measured(command("memory"), ROOT)
    summary = next(line for line in out.splitlines() if " variants (" in line).replace(str(work), "<tmp>")
    alone = kernels_alone(raw)
    steps = limits[0]["variant_steps"]
    nlcx_s, limit_s = min(walls), min(x["wall_s"] for x in limits)
    best = walls.index(nlcx_s)
    batches_s = json.loads((work / f"out{best}" / "manifest.json").read_text())["timings_s"]["batches"]
    simulated = steps * raw["simulation"]["dt"]
    return {
        "variants": n, "wall_s": nlcx_s, "walls_s": walls, "summary": summary,
        "peak_memory_mb": peak_kb[0] / 1024, "peak_pss_mb": peak_kb[1] / 1024, "sampled_wall_s": sampled_wall,
        "limit_s": limit_s, "limit_walls_s": [x["wall_s"] for x in limits],
        "limit_kernel_s": min(x["kernel_s"] for x in limits),
        "variant_steps": steps, "ns_per_step": 1e9 * nlcx_s / steps * 2, "limit_ns_per_step": 1e9 * limit_s / steps * 2,
        "sim_per_wall": simulated / nlcx_s, "limit_sim_per_wall": simulated / limit_s, "ratio": nlcx_s / limit_s,
        "max_dev": limits[0]["max_dev"], "alone": alone, "cpu_s": cpus[best],
        "kernel_cpu_s": 1e-9 * alone["ns"]["nlcx"] * steps, "serial_s": nlcx_s - batches_s,
        "report_s": reports[best], "report_share": reports[best] / nlcx_s,
    }  # fmt: skip


#: The LQR law of (i): the x pendulum's Bryson LQR with integral action (configs/baselines/x_lqr.yaml's K).
LAW = """
import nlcx

K = (-23.938507, -23.652606, -113.277674, -20.235708, -10.0)


@nlcx.controller("bench_lqi", measures=["x", "x_dot", "theta", "theta_dot"], references=["x", "theta"],
                 inputs=["F_x"], states={"z": 0.0}, params=dict(zip(("k1", "k2", "k3", "k4", "ki"), K)))
def bench_lqi(t, dt, y, r, s, p):
    u = -(p.k1 * (y[0] - r[0]) + p.k2 * y[1] + p.k3 * (y[2] - r[1]) + p.k4 * y[3] + p.ki * s[0])
    return (u,), (s[0] + dt * (y[0] - r[0]),)
"""


def bench_i(n: int = 10_000, repeats: int = 2) -> dict[str, Any]:
    """(b)'s sweep with its PID and with the LQR law of :data:`LAW`, alternated: wall times and ratio."""
    work = scratch()
    (work / "law.py").write_text(LAW)
    pid = sweep_config(n)
    law = {**pid, "imports": ["law.py"], "controllers": {"lqi": {"kind": "bench_lqi"}}}
    for name, raw in (("pid", pid), ("law", law)):
        (work / f"{name}.yaml").write_text(yaml.safe_dump(raw))
    walls: dict[str, list[float]] = {"pid": [], "law": []}
    summaries = {}
    for repeat in range(repeats + 1):  # the first of each compiles what it needs: not counted
        for name in ("pid", "law") if repeat % 2 == 0 else ("law", "pid"):
            wall, out = run_timed([*NLCX, "sweep", str(work / f"{name}.yaml"), "--jobs", "2",
                                   "--out", str(work / f"{name}{repeat}")], ROOT)  # fmt: skip
            summaries[name] = next(line for line in out.splitlines() if " variants (" in line)
            if repeat:
                walls[name].append(wall)
    return {"variants": n, "pid_s": min(walls["pid"]), "law_s": min(walls["law"]), "walls": walls,
            "ratio": min(walls["law"]) / min(walls["pid"]),
            "summaries": {k: v.replace(str(work), "<tmp>") for k, v in summaries.items()}}  # fmt: skip


def print_i(g: dict[str, Any]) -> None:
    walls = {k: ", ".join(f"{w:.1f}" for w in v) for k, v in g["walls"].items()}
    print(
        f"(i) {g['variants']} variants of (b) with an LQR law written in plain Python (@nlcx.controller, imports:), "
        f"`nlcx sweep --jobs 2` (report on): {g['law_s']:.1f} s (best of {walls['law']}); the same sweep with the "
        f"built-in PID {g['pid_s']:.1f} s (best of {walls['pid']}), alternated; ratio law / PID {g['ratio']:.2f} "
        "[target <= 1.3]"
    )
    print(f"    law: {g['summaries']['law']}; PID: {g['summaries']['pid']}")


def bench_f(n: int = 1_000_000, subset: int = 10_000) -> dict[str, Any]:
    """Benchmark (b)'s loop over a 0.1 s horizon (100 steps), ``n`` variants, the default
    ``nlcx sweep --jobs 2`` (report on, Parquet tables): wall time, CPU time of the process tree
    beside the kernel's own CPU time for the same variants (so the cost per variant outside the
    kernel), the parent's serial time (manifest.json's phases outside the batches, and the
    report), peak memory in a run of its own; and the first ``subset`` variants' statuses and
    metrics against the per-variant path (``sweep.columnar: false``) run on the same values."""
    import pandas as pd

    from nlcx.results import read_output_table

    raw = sweep_config(n)
    raw["simulation"]["t_end"] = 0.1
    work = scratch()
    path = work / "sweep.yaml"
    path.write_text(yaml.safe_dump(raw))
    command = [*NLCX, "sweep", str(path), "--jobs", "2", "--out", str(work / "out")]
    before = _children_cpu_s()
    wall, out = run_timed(command, ROOT)
    cpu = _children_cpu_s() - before
    manifest = json.loads((work / "out" / "manifest.json").read_text())
    timings = manifest["timings_s"]
    report_s = report_seconds(out)
    sampled_wall, peak_kb, _ = run_measured([*command[:-1], str(work / "memory")], ROOT)
    kernel_s = ensemble_kernel_cpu_s(raw, n)
    index = read_output_table(work / "out", "sweep")
    metrics = read_output_table(work / "out", "metrics")
    values = {k: index[f"value:{k}"].iloc[:subset].tolist() for k in raw["sweep"]["random"]["params"]}
    alone = {**raw, "sweep": {"seed": 1, "zip": values, "batch_size": 100, "columnar": False}}
    (work / "subset.yaml").write_text(yaml.safe_dump(alone))
    subset_command = [*NLCX, "sweep", str(work / "subset.yaml"), "--jobs", "2", "--no-report"]
    run_timed([*subset_command, "--out", str(work / "sub")], ROOT)
    sub_index, sub_metrics = read_output_table(work / "sub", "sweep"), read_output_table(work / "sub", "metrics")
    ours = metrics[metrics.variant < subset].reset_index(drop=True)
    same_status = list(index.status.iloc[:subset]) == list(sub_index.status)
    try:
        pd.testing.assert_frame_equal(ours, sub_metrics, check_exact=True)
        same_metrics = True
    except AssertionError:
        same_metrics = False
    serial = wall - timings["batches"] - report_s  # the parent alone: start, planning, assembling
    return {
        "variants": n, "wall_s": wall, "cpu_s": cpu, "kernel_cpu_s": kernel_s,
        "outside_us": 1e6 * (cpu - kernel_s - report_s) / n, "serial_s": serial, "report_s": report_s,
        "timings": timings, "peak_memory_mb": peak_kb[0] / 1024, "peak_pss_mb": peak_kb[1] / 1024,
        "sampled_wall_s": sampled_wall, "same_status": same_status, "same_metrics": same_metrics,
        "subset": subset, "rows": len(metrics), "statuses": manifest["status"], "path": manifest["path"],
    }  # fmt: skip


def ensemble_kernel_cpu_s(raw: dict[str, Any], n: int, sample: int = 100_000) -> float:
    """The kernel's CPU time alone for ``n`` variants of the columnar sweep ``raw``: ``sample``
    of them packed and simulated in this process (batches as the sweep cuts them), scaled."""
    from nlcx import config, engine
    from nlcx import sweeps as sweep
    from nlcx.engine import ensembles
    from nlcx.sweeps import columnar, planning

    base_raw = {k: v for k, v in raw.items() if k != "sweep"}
    spec = sweep.SweepSection.model_validate({**raw["sweep"], "random": {**raw["sweep"]["random"], "n": sample}})
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    found = columnar.packing(base_raw, spec, plan)
    assert isinstance(found, columnar.Packing) and plan is not None
    size = columnar.batch_size(spec.model_copy(update={"batch_size": 1}), n, found.record_bytes)
    template = columnar._Probe(base_raw).template(plan.values(0), int(plan.seeds[0]))
    engine.load_kernel()
    ensembles.simulate_ensemble(template, found.slots, {k: c[:size] for k, c in plan.columns.items()}, size)
    start = time.process_time()
    for k in range(0, sample, size):
        cols = {key: c[k : k + size] for key, c in plan.columns.items()}
        ensembles.simulate_ensemble(template, found.slots, cols, len(next(iter(cols.values()))))
    return (time.process_time() - start) * n / sample


def print_f(f: dict[str, Any]) -> None:
    n = f["variants"]
    print(
        f"(f) {n} x-pendulum variants of (b)'s loop over 0.1 s (100 steps), `nlcx sweep --jobs 2` (report on, "
        f"Parquet): {f['wall_s']:.1f} s wall [target <= 30]; peak {f['peak_memory_mb']:.0f} MB [target <= 2048] "
        f"(Rss summed; Pss {f['peak_pss_mb']:.0f} MB; sampled in a run of its own, {f['sampled_wall_s']:.1f} s); "
        f"path {f['path']}; statuses {f['statuses']}; {f['rows']} metric rows"
    )
    print(
        f"    CPU of the process tree {f['cpu_s']:.1f} s: the kernel alone {f['kernel_cpu_s']:.1f} s, the report "
        f"{f['report_s']:.1f} s, the rest (start, imports, planning, packing, metrics, files, assembling) "
        f"{f['outside_us']:.1f} us a variant [target <= 10]; the parent's serial time without the report "
        f"(wall - batches - report) {f['serial_s']:.2f} s = 0.5 s + {1e6 * (f['serial_s'] - 0.5) / n:.2f} us a "
        f"variant [target <= 0.5 s + 1 us a variant]; phases {f['timings']}"
    )
    print(
        f"    the first {f['subset']} variants on the per-variant path (sweep.columnar: false, the same values): "
        f"statuses equal: {f['same_status']}; metrics equal (exact): {f['same_metrics']}"
    )


def _reference_batch(task: tuple[np.ndarray, np.ndarray, np.ndarray, float, int, bool]) -> tuple[int, float]:
    """One batch of the limit reference in a worker: (variant-steps simulated, seconds)."""
    import reference

    p, theta_loop, x_loop, dt, n_steps, record = task
    start = time.perf_counter()
    X = np.empty((len(p), n_steps + 1, 4))
    U = np.empty((len(p), n_steps + 1))
    n_valid = np.empty(len(p), dtype=np.int64)
    reference.simulate(p, theta_loop, x_loop, dt, n_steps, np.pi / 2, X, U, n_valid, record)
    return int(np.sum(n_valid - 1)), time.perf_counter() - start


def limit_reference(raw: dict[str, Any], jobs: int = 2) -> dict[str, Any]:
    """The hand-written closed loop (benchmarks/reference.py) over the sweep's variants (the
    same draws of M, m, l), batches of 100 on ``jobs`` processes, recording X and U as nlcx
    does; its trajectories checked against nlcx's on the first variants (max |difference|)."""
    from concurrent.futures import ProcessPoolExecutor

    import reference

    from nlcx import config, engine
    from nlcx import sweeps as sweep

    base = config.interpolate({k: v for k, v in raw.items() if k != "sweep"})
    spec = sweep.SweepSection.model_validate(raw["sweep"])
    variants = sweep.expand(spec, base)
    g = base["plant"]["params"]["g"]
    p = np.array([[v.values["plant.params.M"], v.values["plant.params.m"], v.values["plant.params.l"], g]
                  for v in variants])  # fmt: skip
    loops = base["controllers"]["proposed"]["loops"]
    theta_loop = reference.loop_parameters(loops["theta"]["schedule"])
    x_loop = reference.loop_parameters(loops["x"]["schedule"])
    dt, n_steps = base["simulation"]["dt"], round(base["simulation"]["t_end"] / base["simulation"]["dt"])
    tasks = [(p[k : k + 100], theta_loop, x_loop, dt, n_steps, True) for k in range(0, len(p), 100)]
    _reference_batch((*tasks[0][:4], 10, True))  # compiled (or loaded) here, not in the timing
    with ProcessPoolExecutor(max_workers=jobs, initializer=_import_reference) as pool:
        list(pool.map(_reference_batch, [(*t[:4], 10, True) for t in tasks[:jobs]]))  # workers warm
        start = time.perf_counter()
        done = list(pool.map(_reference_batch, tasks))
        wall = time.perf_counter() - start
    interpolated = config.Interpolated.of({k: x for k, x in raw.items() if k != "sweep"})
    first = [config.build(sweep.Variant(0, v.values, v.seed).resolve(interpolated)) for v in variants[:20]]
    ours = engine.evaluate(first, record_logs=False)
    X = np.empty((20, n_steps + 1, 4))
    U = np.empty((20, n_steps + 1))
    n_valid = np.empty(20, dtype=np.int64)
    reference.simulate(p[:20], theta_loop, x_loop, dt, n_steps, np.pi / 2, X, U, n_valid, True)
    dev = max(float(np.max(np.abs(r.runs[0].x - X[b, : n_valid[b]]))) for b, r in enumerate(ours))
    return {
        "wall_s": wall, "variant_steps": sum(s for s, _ in done), "kernel_s": sum(t for _, t in done), "max_dev": dev,
    }  # fmt: skip


def kernels_alone(raw: dict[str, Any], n: int = 600, repeats: int = 3) -> dict[str, Any]:
    """The first ``n`` variants of the sweep in this process, batches of 100, through three
    loops, alternated, CPU time of the best of ``repeats``: nlcx's kernel (with its array
    packing, as a sweep batch calls it), the reference's loop
    with its PID reading nlcx's packed rows (:func:`reference.simulate_nlcx_pid`: the plant state in
    registers) and the
    limit reference. Where a sweep's time goes beyond the kernel (metrics, configs, files,
    processes) is the difference to (b)'s ratio."""
    import reference

    from nlcx import engine

    base_raw = {k: v for k, v in raw.items() if k != "sweep"}
    prepared = prepared_variants(raw, n)
    grid = prepared[0].grid
    dt = grid.dt
    batches = kernel_batches(prepared)
    n_k = grid.t.size
    X, U, n_valid = np.empty((100, n_k, 4)), np.empty((100, n_k)), np.empty(100, dtype=np.int64)
    theta_loop, x_loop = (reference.loop_parameters(base_raw["controllers"]["proposed"]["loops"][s]["schedule"])
                          for s in ("theta", "x"))  # fmt: skip

    def register_level(loop: str, keep: bool = False) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """The batches through one of the reference's loops; the trajectories copied out if ``keep``."""
        xs, us = [], []
        for items in batches:
            p = np.stack([item.plant.p for item in items])
            if loop == "nlcx_pid":
                pid = reference.packed_pid([item.controller for item in items])
                reference.simulate_nlcx_pid(p, pid, items[0].ref, dt, n_k - 1, np.pi / 2, X, U, n_valid)
            elif loop == "lockstep":
                reference.simulate_lockstep(p, theta_loop, x_loop, dt, n_k - 1, np.pi / 2, X, U, n_valid)
            else:
                reference.simulate(p, theta_loop, x_loop, dt, n_k - 1, np.pi / 2, X, U, n_valid, True)
            if keep:
                xs += [X[b, : n_valid[b]].copy() for b in range(len(items))]
                us += [U[b, : n_valid[b]].copy() for b in range(len(items))]
        return xs, us

    ours = [run for items in batches for run in engine.simulate_items(items, grid, "rk4", record_logs=False)]
    steps = sum(run.t.size - 1 for run in ours)
    xs, us = register_level("nlcx_pid", keep=True)
    same = all(np.array_equal(r.x, x) and np.array_equal(r.u[:, 0], u) for r, x, u in zip(ours, xs, us, strict=True))
    xs, us = register_level("lockstep", keep=True)
    lockstep_same = all(_same_bits(r.x, x) and _same_bits(r.u[:, 0], u) for r, x, u in zip(ours, xs, us, strict=True))
    xs, _ = register_level("limit", keep=True)
    pairs = zip(ours, xs, strict=True)
    limit_dev = max(float(np.max(np.abs(r.x - x))) if r.x.shape == x.shape else np.inf for r, x in pairs)
    cpu: dict[str, list[float]] = {"nlcx": [], "nlcx_pid": [], "lockstep": [], "limit": []}
    for _ in range(repeats):
        for name in cpu:
            start = time.process_time()
            kernel_pass(batches, grid) if name == "nlcx" else register_level(name)
            cpu[name].append(time.process_time() - start)
    ns = {name: 1e9 * min(times) / steps for name, times in cpu.items()}
    return {"variants": n, "ns": ns, "same": same, "lockstep_same": lockstep_same, "limit_dev": limit_dev}


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """The same shape and the same bits (signed zeros and NaN payloads count)."""
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _import_reference() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import reference  # noqa: F401


def bench_c() -> dict[str, float]:
    out = scratch() / "thesis"
    wall, text = run_timed([*NLCX, "reproduce", "--jobs", "2", "--out", str(out)], ROOT)
    sampled_wall, peak_kb, _ = run_measured([*NLCX, "reproduce", "--jobs", "2", "--out", str(out.parent / "m")], ROOT)
    summary = " | ".join(text.strip().splitlines()[-3:]).replace(str(out.parent), "<tmp>")
    return {
        "wall_s": wall, "sampled_wall_s": sampled_wall, "peak_memory_mb": peak_kb[0] / 1024,
        "peak_pss_mb": peak_kb[1] / 1024, "summary": summary,
    }  # fmt: skip


def bench_h(repeats: int = 2) -> dict[str, Any]:
    spec = ROOT / "benchmarks" / "identify_subset.yaml"
    walls = []
    for k in range(repeats):
        out = scratch() / f"identify{k}"
        wall, text = run_timed([*NLCX, "identify", str(spec), "--jobs", "2", "--out", str(out)], ROOT)
        walls.append(wall)
    study = json.loads((out / "study.json").read_text())
    summary = text.strip().splitlines()[-1].replace(str(out), "<tmp>")
    return {"wall_s": min(walls), "walls": walls, "fitted": study["fitted_now"], "summary": summary}


def bench_d() -> dict[str, float]:
    """The proposed (error-AGS) controller of configs/xyz_error_ags.yaml three ways."""
    import control as ct
    from scipy.integrate import solve_ivp

    from nlcx import config, engine
    from nlcx.controllers.pid import input_blocks
    from nlcx.controllers.schedules import ErrorAGS, ErrorAGSConfig, error_ags_gains

    exp = config.load(ROOT / "configs" / "xyz_error_ags.yaml")
    prepared = engine.prepare(exp)
    plant = prepared.plant
    proposed = next(c for c in prepared.controllers if c.label == "proposed")
    prepared.controllers = [proposed]
    engine.evaluate([prepared], measure=False)
    ours_s = best(lambda: engine.evaluate([prepared], measure=False), 20)
    (ours,) = engine.evaluate([prepared], measure=False)[0].runs

    # the same closed loop as a continuous ODE: plant states + one integrator per loop
    loops = exp.controllers[1].config.loops
    names = plant.state_names
    order = list(loops)
    info = []
    for key in order:
        loop = loops[key]
        signal = loop.signal or key
        sched = loop.schedule if isinstance(loop.schedule, dict) else loop.schedule.model_dump()
        sp = ErrorAGS().pack(ErrorAGSConfig.model_validate(sched))  # the schedule's own layout
        info.append(
            (
                names.index(signal),
                names.index(f"{signal}_dot"),
                plant.input_names.index(plant.features.loop_inputs[signal]),
                loop.sign,
                sp,
                prepared.references[signal][1],
            )
        )
    bias = np.array([b["bias"] for b in input_blocks(proposed.cp)])
    n = len(names)

    def field(t: float, z: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(z[:n])
        u = bias.copy()
        dz = np.zeros_like(z)
        for k, (pi, vi, ui, sign, sp, ref) in enumerate(info):
            if ref.kind == "step":
                r = ref.final if t >= ref.time else ref.initial
            else:
                r = ref.value
            e = r - x[pi]
            edot = -x[vi]
            kp, ki, kd = error_ags_gains(t, e, edot, sp[None], 0, 0)
            u[ui] += sign * (kp * e + ki * z[n + k] + kd * edot)
            dz[n + k] = e
        dz[:n] = plant.f(x, u, t)
        return dz

    z0 = np.concatenate([plant.x0, np.zeros(len(info))])
    t_eval = ours.t
    sol_box: list = []
    scipy_s = best(
        lambda: sol_box.append(solve_ivp(field, (0, t_eval[-1]), z0, t_eval=t_eval, rtol=1e-6, atol=1e-9)), 3
    )
    sol = sol_box[-1]
    sys_ct = ct.nlsys(lambda t, z, u, params: field(t, z), None, states=len(z0), inputs=0, outputs=len(z0))
    ct_box: list = []
    control_s = best(
        lambda: ct_box.append(
            ct.input_output_response(sys_ct, t_eval, 0, z0, solve_ivp_kwargs={"rtol": 1e-6, "atol": 1e-9})
        ),
        3,
    )
    resp = ct_box[-1]
    x_idx = [names.index(s) for s in ("x", "y", "z", "theta", "phi")]
    dev_scipy = float(np.max(np.abs(sol.y[x_idx].T - ours.x[:, x_idx])))
    dev_ct = float(np.max(np.abs(np.asarray(resp.states)[x_idx].T - ours.x[:, x_idx])))
    return {
        "nlcx_s": ours_s, "scipy_solve_ivp_s": scipy_s, "python_control_s": control_s,
        "ratio_scipy": scipy_s / ours_s, "ratio_python_control": control_s / ours_s,
        "max_dev_vs_scipy": dev_scipy, "max_dev_vs_python_control": dev_ct, "rhs_evals_scipy": sol.nfev,
    }  # fmt: skip


def bench_fresh_clone() -> dict[str, Any]:
    """``make run`` in a fresh clone of this repository's HEAD, pip's cache off (every package
    downloaded, as on a fresh machine): install, the warm-up compile and the main job."""
    work = scratch()
    subprocess.run(["git", "clone", "-q", str(ROOT), str(work / "nlcx")], check=True)
    env = {**os.environ, "PIP_NO_CACHE_DIR": "1"}
    wall = run_timed(["make", "run"], work / "nlcx", env)[0]
    start = time.perf_counter()
    subprocess.run([str(work / "nlcx" / ".venv" / "bin" / "nlcx"), "run", "configs/xyz_error_ags.yaml", "-q"],
                   cwd=work / "nlcx", check=True, capture_output=True)  # fmt: skip
    return {"make_run_s": wall, "next_run_s": time.perf_counter() - start}


def print_a(a: dict[str, float]) -> None:
    print(
        "(a) xyz_error_ags: simulate (2 controllers, 20 s, dt 1 ms) "
        f"{a['simulate_s']:.3f} s [target <= 0.2]; `nlcx run` end to end (warm cache) {a['end_to_end_s']:.2f} s "
        "[target <= 1.5]"
    )
    print(f"    warm-up in process (imports, cache load, first call) {a['warmup_in_process_s']:.2f} s")
    walls, phases = ", ".join(f"{w:.1f}" for w in a["cold_walls_s"]), a["cold_median_phases_s"]
    print(
        f"    first `nlcx run {COLD_CONFIG}` after `pip install .` in a clean venv (empty numba cache, compiles) "
        f"{a['cold_compile_run_s']:.1f} s [target <= 10] (median of {walls}; the install {a['clean_install_s']:.0f} s; "
        "make install compiles the main job's kernels before the first run)"
    )
    print(
        f"    where the median cold run's time went: start, imports and the kernel's compile (the helper "
        f"compiling the controllers' and metric functions beside it) {phases['before_clock_s']:.1f} s; simulate "
        f"(the plant's compile, the simulation) {phases['simulate']:.1f} s; metrics (the wait for the helper, "
        f"measuring) {phases['metrics']:.1f} s; files and report {phases['write']:.1f} s"
    )


def print_b(b: dict[str, Any]) -> None:
    walls = ", ".join(f"{w:.1f}" for w in b["walls_s"])
    limits = ", ".join(f"{w:.1f}" for w in b["limit_walls_s"])
    print(
        f"(b) {b['variants']} x-pendulum variants (error-AGS, M, m, l +-20 %, 20 s, dt 1 ms), `nlcx sweep --jobs 2` "
        f"(report on): {b['wall_s']:.1f} s wall [target <= 30; stretch <= 12] (best of {walls}); its report "
        f"{b['report_s']:.2f} s, {100 * b['report_share']:.1f} % of the wall [target <= 10 %]; "
        f"peak {b['peak_memory_mb']:.0f} MB "
        f"[target <= 2048] (Rss summed over the processes; shared pages counted once, Pss: {b['peak_pss_mb']:.0f} MB; "
        f"memory sampled in a run of its own: {b['sampled_wall_s']:.1f} s with the sampler's /proc reads beside it)"
    )
    print(f"    {b['summary']}")
    print(
        f"    limit reference (benchmarks/reference.py, same variants, 2 processes, X and U recorded): "
        f"{b['limit_s']:.1f} s (best of {limits}); {b['variant_steps'] / 1e6:.0f} M variant-steps"
    )
    print(
        f"    nlcx {b['ns_per_step']:.0f} ns per variant-step on a core, "
        f"{b['sim_per_wall']:.0f} simulated s per wall s; "
        f"limit {b['limit_ns_per_step']:.0f} ns, {b['limit_sim_per_wall']:.0f} s/s; ratio nlcx / limit "
        f"{b['ratio']:.2f} [goal <= 1.3]; trajectories max |difference| {b['max_dev']:.1e}"
    )
    ns, alone = b["alone"]["ns"], b["alone"]
    print(
        f"    kernels alone, one process, {b['alone']['variants']} of the variants in batches of 100 (CPU time): "
        f"nlcx's kernel {ns['nlcx']:.0f} ns per variant-step; the reference's loop with its PID on nlcx's rows "
        f"and sin/cos (plant state in registers) {ns['nlcx_pid']:.0f} ns; limit {ns['limit']:.0f} ns; ratios to the "
        f"limit {ns['nlcx'] / ns['limit']:.2f} and {ns['nlcx_pid'] / ns['limit']:.2f}; trajectories: the loop with "
        f"its PID on nlcx's rows bit-identical to nlcx's: {alone['same']}; the limit (libm's sin/cos) max |difference| "
        f"{alone['limit_dev']:.1e}"
    )
    lockstep_cpu_s = 1e-9 * ns["lockstep"] * b["variant_steps"]
    projected = b["wall_s"] - (b["kernel_cpu_s"] - lockstep_cpu_s) / 2
    print(
        f"    the limit's loop in lock step (every variant of a batch stepped together as nlcx's kernel steps "
        f"them, plant and PID written out, nlcx's sin/cos): {ns['lockstep']:.0f} ns per variant-step, "
        f"{ns['lockstep'] / ns['limit']:.2f}x the limit, bit-identical to nlcx's (X, U): "
        f"{alone['lockstep_same']}; "
        f"nlcx's sweep with a kernel that fast, all else as measured: ~{projected:.1f} s "
        f"({b['wall_s']:.1f} - ({b['kernel_cpu_s']:.1f} - {lockstep_cpu_s:.1f}) / 2), "
        f"{projected / b['limit_s']:.2f}x the limit"
    )
    print(
        f"    where the sweep's time goes: its processes used {b['cpu_s']:.1f} s of CPU in {b['wall_s']:.1f} s on 2 "
        f"cores; the kernel ~{b['kernel_cpu_s']:.1f} s of it ({b['variant_steps'] / 1e6:.0f} M variant-steps at its "
        f"speed alone), the rest (configs, metrics, files, imports, planning, assembling) "
        f"{b['cpu_s'] - b['kernel_cpu_s']:.1f} s; the limit's loop {b['limit_kernel_s']:.1f} s"
    )
    floor = b["serial_s"] + b["kernel_cpu_s"] / 2
    print(
        f"    the parent alone (start, imports, planning before the pool; assembling after it; manifest.json's "
        f"timings) {b['serial_s']:.1f} s; with nothing but the kernel in the workers the sweep would still take "
        f"~{floor:.1f} s ({b['serial_s']:.1f} + {b['kernel_cpu_s']:.1f} / 2), {floor / b['limit_s']:.2f}x the limit"
    )


#: Where the speed table sits in README.md.
README = ROOT / "README.md"
TABLE_START, TABLE_END = "<!-- speed-table:start -->", "<!-- speed-table:end -->"
#: How latest.txt prints each figure of the table: key -> the pattern of its value.
FIGURE_PATTERNS = {
    "machine": r"^nlcx benchmarks, [^,]*, (.+)$",
    "a_simulate_s": r"^\(a\) .*?: simulate \(.*?\) ([\d.]+) s",
    "a_end_to_end_s": r"end to end \(warm cache\) ([\d.]+) s",
    "a_cold_run_s": r"in a clean venv \(empty numba cache, compiles\) ([\d.]+) s",
    "b_variants": r"^\(b\) (\d+) x-pendulum variants",
    "b_wall_s": r"^\(b\) .*?\(report on\): ([\d.]+) s wall",
    "b_report_pct": r"its report [\d.]+ s, ([\d.]+) % of the wall",
    "b_peak_mb": r"^\(b\) .*? peak (\d+) MB",
    "b_ratio": r"ratio nlcx / limit ([\d.]+)",
    "c_wall_s": r"^\(c\) .*?: ([\d.]+) s \[target",
    "c_peak_mb": r"^\(c\) .*? peak (\d+) MB",
    "d_nlcx_ms": r"^\(d\) .*?: nlcx ([\d.]+) ms",
    "d_ratio": r"input_output_response [\d.]+ s \(x(\d+)\)",
    "e_make_run_s": r"^\(e\) .*?: (\d+) s \[target",
    "f_wall_s": r"^\(f\) .*?: ([\d.]+) s wall",
    "f_peak_mb": r"^\(f\) .*? peak (\d+) MB",
    "f_outside_us": r"the rest \(start, .*?\) ([\d.]+) us a variant",
    "h_wall_s": r"^\(h\) .*?: ([\d.]+) s wall",
    "i_ratio": r"^\(i\) .*? ratio law / PID ([\d.]+)",
    "i_law_s": r"^\(i\) .*?\(report on\): ([\d.]+) s",
}


def figures_from_text(text: str) -> dict[str, Any]:
    """The speed table's figures from a saved output of this script (benchmarks/latest.txt);
    a benchmark the output lacks has none of its figures."""
    figures: dict[str, Any] = {}
    for key, pattern in FIGURE_PATTERNS.items():
        match = re.search(pattern, text, flags=re.MULTILINE)
        if match:
            figures[key] = match.group(1) if key == "machine" else float(match.group(1))
    return figures


def figures_measured(
    a: dict[str, float] | None, b: dict[str, Any] | None, c: dict[str, float] | None,
    d: dict[str, float] | None, e: dict[str, Any] | None, f: dict[str, Any] | None = None,
    h: dict[str, Any] | None = None, i: dict[str, Any] | None = None,
) -> dict[str, Any]:  # fmt: skip
    """The speed table's figures from the benchmarks' results, rounded as the output prints them."""
    figures: dict[str, Any] = {"machine": machine()}
    if a:
        figures |= {"a_simulate_s": round(a["simulate_s"], 3), "a_end_to_end_s": round(a["end_to_end_s"], 2),
                    "a_cold_run_s": round(a["cold_compile_run_s"], 1)}  # fmt: skip
    if b:
        figures |= {"b_variants": float(b["variants"]), "b_wall_s": round(b["wall_s"], 1),
                    "b_peak_mb": round(b["peak_memory_mb"]), "b_ratio": round(b["ratio"], 2),
                    "b_report_pct": round(100 * b["report_share"], 1)}  # fmt: skip
    if c:
        figures |= {"c_wall_s": round(c["wall_s"], 1), "c_peak_mb": round(c["peak_memory_mb"])}
    if d:
        figures |= {"d_nlcx_ms": round(d["nlcx_s"] * 1e3, 1), "d_ratio": round(d["ratio_python_control"])}
    if e:
        figures |= {"e_make_run_s": round(e["make_run_s"])}
    if f:
        figures |= {"f_wall_s": round(f["wall_s"], 1), "f_peak_mb": round(f["peak_memory_mb"]),
                    "f_outside_us": round(f["outside_us"], 1)}  # fmt: skip
    if h:
        figures |= {"h_wall_s": round(h["wall_s"], 1)}
    if i:
        figures |= {"i_ratio": round(i["ratio"], 2), "i_law_s": round(i["law_s"], 1)}
    return figures


def table_rows(f: dict[str, Any]) -> list[tuple[str, str, str, str]]:
    """(benchmark, what is measured, the figure, the target) for each benchmark in ``f``."""
    rows = []
    if "a_simulate_s" in f:
        rows += [
            ("a", "simulating `configs/xyz_error_ags.yaml` (both controllers, 20 s at dt = 1 ms)",
             f"{f['a_simulate_s']:.3f} s", "≤ 0.2 s"),
            ("a", "`nlcx run configs/xyz_error_ags.yaml` end to end, warm cache", f"{f['a_end_to_end_s']:.2f} s",
             "≤ 1.5 s"),
            ("a", "the first `nlcx run configs/x_error_ags.yaml` after `pip install .` in a clean venv (empty numba "
             "cache; the median of three)", f"{f['a_cold_run_s']:.1f} s", "≤ 10 s"),
        ]  # fmt: skip
    if "b_wall_s" in f:
        variants = f"{f['b_variants']:,.0f}".replace(",", " ")
        rows += [
            ("b", f"`nlcx sweep` of {variants} x-pendulum variants (error-AGS PID), `--jobs 2`, report on: wall "
             "time, peak memory", f"{f['b_wall_s']:.1f} s, {f['b_peak_mb']:.0f} MB", "≤ 30 s, ≤ 2 GB"),
            ("b", "that sweep's report, share of its wall time", f"{f['b_report_pct']:.1f} %", "≤ 10 %"),
            ("b", "that sweep's time over its limit reference's (`benchmarks/reference.py`)",
             f"{f['b_ratio']:.2f}×", "≤ 1.3×"),
        ]  # fmt: skip
    if "c_wall_s" in f:
        rows.append(("c", "`nlcx reproduce` (every figure and table of chapters 2–5): wall time, peak memory",
                     f"{f['c_wall_s']:.1f} s, {f['c_peak_mb']:.0f} MB", "≤ 120 s, ≤ 2 GB"))  # fmt: skip
    if "d_ratio" in f:
        rows.append(("d", "one trajectory of (a)'s proposed controller against python-control's "
                     "`input_output_response`", f"{f['d_ratio']:.0f}× as fast ({f['d_nlcx_ms']:.1f} ms)",
                     "≥ 100×"))  # fmt: skip
    if "e_make_run_s" in f:
        rows.append(("e", "`make run` in a fresh clone, pip's cache off", f"{f['e_make_run_s']:.0f} s", "≤ 90 s"))
    if "gpu_sweep_s" in f:
        rows += [
            ("gpu", f"`nlcx sweep --device cuda` of 1 000 000 variants of (b)'s loop on one {f['gpu_name']}, its "
             "kernels kept from an earlier process: plan, simulate, measure, write the metrics; then the report",
             f"{f['gpu_sweep_s']:.1f} s; "
             f"{f['gpu_report_s']:.1f} s", "≤ 10 s"),
            ("gpu", "nlcx's GPU kernel over a hand-written CUDA kernel of the same loop, 1 000 000 variants "
             "(`benchmarks/gpu.py`)", f"{f['gpu_kernel_ratio']:.2f}×", "≤ 2×"),
        ]  # fmt: skip
    if "f_wall_s" in f:
        rows += [
            ("f", "`nlcx sweep` of 1 000 000 x-pendulum variants over 0.1 s, `--jobs 2`, report on: wall time, "
             "peak memory", f"{f['f_wall_s']:.1f} s, {f['f_peak_mb']:.0f} MB", "≤ 30 s, ≤ 2 GB"),
            ("f", "that sweep's CPU time a variant outside the kernel and the report",
             f"{f['f_outside_us']:.1f} µs", "≤ 10 µs"),
        ]  # fmt: skip
    if "i_ratio" in f:
        rows.append(("i", "(b)'s sweep with an LQR law in plain Python (`@nlcx.controller`) in place of the PID: "
                     "wall time, and over (b)'s PID sweep in the same run", f"{f['i_law_s']:.1f} s, "
                     f"{f['i_ratio']:.2f}×", "≤ 1.3×"))  # fmt: skip
    if "h_wall_s" in f:
        rows.append(("h", "`nlcx identify benchmarks/identify_subset.yaml --jobs 2`: eight hypotheses of the "
                     "identification study, GA 30 × 15 then 18 × 10", f"{f['h_wall_s']:.1f} s", "–"))  # fmt: skip
    return rows


def speed_table(figures: dict[str, Any], kept: Sequence[str] = ()) -> str:
    """The README's speed table: a row per figure of ``figures``, then the ``kept`` rows (lines
    of the table before, for benchmarks this run did not measure), in the benchmarks' order."""
    lines = [f"| ({bench}) | {what} | {value} | {target} |" for bench, what, value, target in table_rows(figures)]
    lines = sorted([*lines, *kept], key=lambda line: line[:5])
    machine_text = f" on {figures['machine']}" if figures.get("machine") else ""
    if "machine" not in figures and "previous_machine" in figures:  # only GPU rows measured: the CPU rows' machine
        machine_text = f" on {figures['previous_machine']}"
    return (
        f"Measured by `make bench`{machine_text} (`benchmarks/latest.txt` holds the whole output; "
        "docs/performance.md describes each benchmark).\n\n"
        "| | benchmark | measured | target |\n|---|---|---|---|\n" + "\n".join(lines) + "\n"
    )


def write_speed_table(figures: dict[str, Any], readme: Path = README) -> bool:
    """Rewrite the table between the markers of ``readme``, keeping the rows of benchmarks that
    ``figures`` lacks. False (and nothing written) when the file has no markers."""
    text = readme.read_text(encoding="utf-8")
    start, end = text.find(TABLE_START), text.find(TABLE_END)
    if start < 0 or end < start:
        return False
    measured = {bench for bench, *_ in table_rows(figures)}
    body = text[start + len(TABLE_START) : end]
    rows = (re.match(r"^\| \(([a-i]|gpu)\) \|", line) for line in body.splitlines())
    kept = [row.string for row in rows if row and row.group(1) not in measured]
    before = re.search(r"Measured by `make bench` on (.*?) \(`benchmarks", body)
    if before and "machine" not in figures:
        figures = {**figures, "previous_machine": before.group(1)}
    table = speed_table(figures, kept)
    new = f"{text[: start + len(TABLE_START)]}\n{table}{text[end:]}"
    if new != text:
        readme.write_text(new, encoding="utf-8")
    return True


def machine() -> str:
    """The machine line of the output: processor, cores, Python."""
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def main() -> None:
    parser = argparse.ArgumentParser(description="nlcx speed benchmarks (latest output: benchmarks/latest.txt)")
    parser.add_argument(
        "--only", default="a,d,c,b,f,h,i", help="benchmarks to run, comma-separated (default a,d,c,b,f,h,i)"
    )
    parser.add_argument("--fresh-clone", action="store_true", help="also time make run in a fresh clone (downloads)")
    parser.add_argument(
        "--table-from", type=Path, help="only rewrite README.md's speed table from this saved output (latest.txt)"
    )
    args = parser.parse_args()
    if args.table_from is not None:
        if not write_speed_table(figures_from_text(args.table_from.read_text(encoding="utf-8"))):
            sys.exit(f"README.md has no {TABLE_START} ... {TABLE_END} markers")
        return
    chosen = set(args.only.split(","))
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    os.chdir(ROOT)
    print(f"nlcx benchmarks, {time.strftime('%Y-%m-%d')}, {machine()}")
    a = b = c = d = e = f = h = i = None
    if "a" in chosen:
        a = bench_a()
        print_a(a)
    if "d" in chosen:
        d = bench_d()
        print(
            f"(d) proposed controller of (a): nlcx {d['nlcx_s'] * 1e3:.1f} ms; "
            f"scipy solve_ivp RK45 {d['scipy_solve_ivp_s']:.2f} s "
            f"(x{d['ratio_scipy']:.0f}, {d['rhs_evals_scipy']} RHS evaluations); python-control "
            f"input_output_response {d['python_control_s']:.2f} s (x{d['ratio_python_control']:.0f}) "
            "[goal >= 100x python-control]"
        )
        print(
            f"    max |position/angle| difference vs scipy {d['max_dev_vs_scipy']:.2e}, vs python-control "
            f"{d['max_dev_vs_python_control']:.2e} (ZOH-sampled vs continuous PID)"
        )
    if "c" in chosen:
        c = bench_c()
        print(
            f"(c) nlcx reproduce (chapters 2-5, calibration excluded): {c['wall_s']:.1f} s [target <= 120], "
            f"peak {c['peak_memory_mb']:.0f} MB [target <= 2048] (Rss summed; Pss {c['peak_pss_mb']:.0f} MB; "
            f"sampled in a run of its own, {c['sampled_wall_s']:.1f} s); "
            f"{c['summary']}"
        )
    if "b" in chosen:
        b = bench_b(repeats=3)
        print_b(b)
    if "f" in chosen:
        f = bench_f()
        print_f(f)
    if "h" in chosen:
        h = bench_h()
        print(
            f"(h) nlcx identify benchmarks/identify_subset.yaml --jobs 2 ({h['fitted']} fits): {h['wall_s']:.1f} s "
            f"wall (best of {', '.join(f'{w:.1f}' for w in h['walls'])}) | {h['summary']}"
        )
    if args.fresh_clone:
        e = bench_fresh_clone()
        print(
            f"(e) make run in a fresh clone, pip's cache off (install, warm-up compile, main job): "
            f"{e['make_run_s']:.0f} s [target <= 90]; the next nlcx run {e['next_run_s']:.1f} s"
        )
    if "i" in chosen:
        i = bench_i()
        print_i(i)
    if write_speed_table(figures_measured(a, b, c, d, e, f, h, i)):
        print("README.md speed table rewritten", file=sys.stderr)


if __name__ == "__main__":
    main()

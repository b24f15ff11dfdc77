"""nlcx on one GPU against a hand-written CUDA kernel of the same loop (needs a CUDA GPU and numba-cuda).

    python benchmarks/gpu.py | tee benchmarks/gpu_latest.txt        (or: make bench-gpu)

It also writes its 10^6-variant figures into the speed table of README.md (the ``(gpu)`` rows).

Benchmark (b)'s loop (the x pendulum under the error-AGS PID of configs/x_error_ags.yaml, M, m
and l uniform within +-20 %, classic RK4 at 1 ms over 20 s, float64) at 10^4, 10^5 and 10^6
variants:

- reference: :func:`reference_kernel`, written by hand for this loop only: one thread a
  variant, the plant (the mass matrix solved as nlcx's generated code does), the two PID
  loops and the schedules in local variables, libdevice's sin, cos and exp, overshoot and
  settling time of x computed on the fly;
- kernel: nlcx's closed-loop kernel (:func:`nlcx.kernel.cuda_loop.launch`) on the same
  variants, nothing recorded;
- simulate + measure: nlcx's GPU ensemble (:func:`nlcx.engine.gpu.simulate_measure`):
  packing, the kernel keeping x, theta and F, every metric on the GPU, the values copied back;
- end to end: ``nlcx sweep --device cuda`` of the sweep of benchmark (b) with that many
  variants (plan, simulate, measure, write the metrics; then the report, timed apart).

The reference and the kernel are each the best of two after a warm-up (the kernel's compilation
is timed apart); simulate + measure is one call, whose first, at the smallest size, also loads
or compiles the metric kernels; end to end is one process. The statuses of the reference and of
nlcx are compared variant by variant.
"""

from __future__ import annotations

import json
import math
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from run import sweep_config  # noqa: E402

SIZES = (10_000, 100_000, 1_000_000)


def reference_kernel(cuda):
    """The hand-written CUDA kernel of (b)'s loop (see the module docstring)."""

    @cuda.jit(device=True)
    def ags(s, a0, a1, a2, a3, a4, a5, r_p, r_i, r_d):  # pragma: no cover - device
        e_p = math.exp(-r_p * s)
        e_i = e_p if r_i == r_p else math.exp(-r_i * s)
        e_d = e_p if r_d == r_p else (e_i if r_d == r_i else math.exp(-r_d * s))
        return a1 - (a1 - a0) * e_p, a2 - (a2 - a3) * e_i, a5 - (a5 - a4) * e_d

    @cuda.jit(device=True)
    def rhs(M, m, l, g, th, thd, F):  # pragma: no cover - device
        s, c = math.sin(th), math.cos(th)
        w0 = l * m
        w1 = w0 * s
        r0 = 1.0 / (M + m)
        L10 = w0 * c * r0
        b0 = F + thd * thd * w1
        a1 = (g * w1 - L10 * b0) / (l * l * m - L10 * L10 * (M + m))
        return b0 * r0 - L10 * a1, a1

    @cuda.jit
    def kernel(p, gains, dt, n_steps, bound, status, overshoot, settling):  # pragma: no cover - device
        b = cuda.grid(1)
        if b >= p.shape[0]:
            return
        M, m, l, g = p[b, 0], p[b, 1], p[b, 2], p[b, 3]
        x, xd, th, thd = 0.0, 0.0, 0.0, 0.0
        i_th, i_x, e_th_prev, e_x_prev = 0.0, 0.0, 0.0, 0.0
        peak, last_out = -math.inf, 0.0
        status[b] = 0
        for k in range(n_steps + 1):
            e_th, e_x = -th, 1.0 - x
            if k == 0:
                e_th_prev, e_x_prev = e_th, e_x
            kp, ki, kd = ags(abs(e_th), gains[0], gains[1], gains[2], gains[3], gains[4], gains[5], gains[6],
                             gains[7], gains[8])  # fmt: skip
            i_th += e_th * dt
            F = -(kp * e_th + i_th * ki + kd * (e_th - e_th_prev) / dt)
            kp, ki, kd = ags(abs(e_x), gains[9], gains[10], gains[11], gains[12], gains[13], gains[14], gains[15],
                             gains[16], gains[17])  # fmt: skip
            i_x += e_x * dt
            F += kp * e_x + i_x * ki + kd * (e_x - e_x_prev) / dt
            e_th_prev, e_x_prev = e_th, e_x
            peak = max(peak, x - 1.0)
            if abs(x - 1.0) > 0.02:
                last_out = (k + 1) * dt
            if k == n_steps:
                break
            a1, t1 = rhs(M, m, l, g, th, thd, F)
            a2, t2 = rhs(M, m, l, g, th + 0.5 * dt * thd, thd + 0.5 * dt * t1, F)
            a3, t3 = rhs(M, m, l, g, th + 0.5 * dt * (thd + 0.5 * dt * t1), thd + 0.5 * dt * t2, F)
            a4, t4 = rhs(M, m, l, g, th + dt * (thd + 0.5 * dt * t2), thd + dt * t3, F)
            v2, v3, v4 = xd + 0.5 * dt * a1, xd + 0.5 * dt * a2, xd + dt * a3
            w2, w3, w4 = thd + 0.5 * dt * t1, thd + 0.5 * dt * t2, thd + dt * t3
            x, xd, th, thd = (
                x + dt / 6.0 * (xd + 2.0 * (v2 + v3) + v4), xd + dt / 6.0 * (a1 + 2.0 * (a2 + a3) + a4),
                th + dt / 6.0 * (thd + 2.0 * (w2 + w3) + w4), thd + dt / 6.0 * (t1 + 2.0 * (t2 + t3) + t4),
            )  # fmt: skip
            if not (abs(th) <= bound and math.isfinite(x) and math.isfinite(xd) and math.isfinite(thd)):
                status[b] = 1
                return
        overshoot[b] = 100.0 * max(peak, 0.0)
        settling[b] = last_out

    return kernel


def _best(fn, cuda, repeats: int = 2) -> float:
    times = []
    for _ in range(repeats):
        cuda.synchronize()
        start = time.perf_counter()
        fn()
        cuda.synchronize()
        times.append(time.perf_counter() - start)
    return min(times)


def _variants(n: int):
    """The first ``n`` variants of benchmark (b)'s sweep as the columnar path packs them: the
    template, the packing's slots and the columns."""
    from nlcx import sweeps
    from nlcx.sweeps import columnar, planning

    work = Path(tempfile.mkdtemp())
    path = work / "sweep.yaml"
    raw = sweep_config(n)
    raw["simulation"] = {**raw["simulation"], "device": "cuda"}
    path.write_text(yaml.safe_dump(raw))
    base_raw, spec, _ = sweeps.load(path)
    plan = planning.expand_columns(spec, base_raw)
    found = columnar.packing(base_raw, spec, plan)
    template = columnar._Probe(base_raw).template(plan.values(0), int(plan.seeds[0]))
    return template, found.slots, plan.columns, path


def _kernel_arguments(template, slots, columns, n):
    from nlcx.engine.ensembles import _call_arguments, ensemble_calls

    ((pattern, step),) = ensemble_calls(template.items, n)
    return _call_arguments(template, pattern, step, n, slots, columns)


def measure(n: int, cuda, ref_kernel) -> dict:
    from nlcx.engine.gpu import simulate_measure
    from nlcx.engine.prepared import TABLEAUS
    from nlcx.kernel import cuda_loop
    from nlcx.kernel.structures import Integration, method_of

    template, slots, columns, path = _variants(n)
    plant, controller, elements, forces = _kernel_arguments(template, slots, columns, n)
    grid = template.prepared.grid
    tab = TABLEAUS["rk4"]
    integration = Integration(method=method_of("rk4"), rk_a=tab.a, rk_b=tab.b, dt=grid.dt)
    none = np.zeros((0, 2), dtype=np.int64)
    n_log = len(template.items[0].controller.log_names)
    outcome = {}

    def ours() -> None:
        outcome["done"] = cuda_loop.launch(integration, plant, controller, elements, forces, 1, n_log, grid.t.size,
                                           none, False)  # fmt: skip

    cfg = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())["controllers"]["proposed"]["loops"]
    gains = []
    for loop in ("theta", "x"):
        s = cfg[loop]["schedule"]
        gains += [s["kp"]["min"], s["kp"]["max"], s["ki"]["min"], s["ki"]["max"], s["kd"]["min"], s["kd"]["max"],
                  s["rate"]["kp"], s["rate"]["ki"], s["rate"]["kd"]]  # fmt: skip
    p_dev, g_dev = cuda.to_device(np.ascontiguousarray(plant.p)), cuda.to_device(np.array(gains, dtype=float))
    r_status, r_over, r_settle = (cuda.device_array(n) for _ in range(3))
    bound = float(plant.bounds.reshape(-1, plant.bounds.shape[-1])[0, 2])

    def reference() -> None:
        ref_kernel[(n + 127) // 128, 128](p_dev, g_dev, grid.dt, grid.n_steps, bound, r_status, r_over, r_settle)

    start = time.perf_counter()
    ours()
    cuda.synchronize()
    compile_s = time.perf_counter() - start
    reference()
    row = {"n": n, "compile_s": compile_s, "reference_s": _best(reference, cuda), "kernel_s": _best(ours, cuda)}
    ours()
    same = np.array_equal(outcome["done"].status.copy_to_host() != 0, r_status.copy_to_host() != 0)
    row["statuses_equal"] = bool(same)
    row["simulate_measure_s"] = _best(lambda: simulate_measure(template, slots, columns, n), cuda, repeats=1)
    out = path.parent / "out"
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "nlcx.cli", "sweep", str(path), "--out", str(out), "--force"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    row["end_to_end_s"] = time.perf_counter() - start
    report = [line for line in done.stdout.splitlines() if line.startswith("report ")]
    row["report_s"] = float(report[0].rsplit("(", 1)[1].split(" ")[0]) if report else math.nan
    manifest = json.loads((out / "manifest.json").read_text())
    row["sweep_timings"] = manifest.get("timings_s", {})
    row["statuses"] = manifest.get("status")
    return row


def kept_kernels(n: int = 10_000) -> tuple[float, float]:
    """Wall times of ``nlcx sweep --device cuda`` of ``n`` variants (report off) in a process that
    compiles its GPU kernels (none kept on disk) and in one that loads them (kept by the first)."""
    import shutil

    from nlcx.kernel.device import KERNEL_DIR

    work = Path(tempfile.mkdtemp())
    raw = sweep_config(n)
    raw["simulation"] = {**raw["simulation"], "device": "cuda"}
    (work / "sweep.yaml").write_text(yaml.safe_dump(raw))
    shutil.rmtree(KERNEL_DIR, ignore_errors=True)
    times = []
    for k in range(2):
        command = [sys.executable, "-m", "nlcx.cli", "sweep", str(work / "sweep.yaml"), "--out", str(work / f"o{k}")]
        start = time.perf_counter()
        subprocess.run([*command, "--force", "--no-report"], capture_output=True, text=True, check=True)
        times.append(time.perf_counter() - start)
    return times[0], times[1]


def figures_from_text(text: str) -> dict[str, object]:
    """The README's (gpu) figures from a saved output of this script (its 10^6-variant line)."""
    import re

    name = re.search(r"^nlcx GPU benchmark on ([^;]+);", text, flags=re.MULTILINE)
    line = re.search(
        r"^\(gpu\) 1,000,000 variants: reference ([\d.]+) s, nlcx kernel ([\d.]+) s .*? end to end ([\d.]+) s "
        r"\(report ([\d.]+) s\)",
        text,
        flags=re.MULTILINE,
    )
    if name is None or line is None:
        return {}
    reference, kernel, end_to_end, report = (float(v) for v in line.groups())
    return {
        "gpu_name": name.group(1),
        "gpu_sweep_s": round(end_to_end - report, 1),
        "gpu_report_s": round(report, 1),
        "gpu_kernel_ratio": round(kernel / reference, 2),
    }


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--sizes", default=",".join(str(n) for n in SIZES), help="Numbers of variants, comma-separated."
    )
    parser.add_argument("--table-from", type=Path, help="only rewrite README.md's (gpu) rows from a saved output")
    args = parser.parse_args()
    if args.table_from is not None:
        from run import write_speed_table

        write_speed_table(figures_from_text(args.table_from.read_text(encoding="utf-8")))
        return
    sizes = [int(n) for n in args.sizes.split(",")]
    from nlcx import compiled_cache

    compiled_cache.ready()
    from nlcx.kernel.device import cuda, device_name

    gpu = cuda()
    print(f"nlcx GPU benchmark on {device_name()}; {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}", flush=True)  # fmt: skip
    ref_kernel = reference_kernel(gpu)
    table: dict[str, object] = {}
    for n in sizes:
        r = measure(n, gpu, ref_kernel)
        if n == 1_000_000:
            table = {
                "gpu_name": device_name(),
                "gpu_sweep_s": round(r["end_to_end_s"] - r["report_s"], 1),
                "gpu_report_s": round(r["report_s"], 1),
                "gpu_kernel_ratio": round(r["kernel_s"] / r["reference_s"], 2),
            }
        steps = n * 20_000
        print(
            f"(gpu) {n:>9,} variants: reference {r['reference_s']:.3f} s, nlcx kernel {r['kernel_s']:.3f} s "
            f"(x{r['kernel_s'] / r['reference_s']:.2f}; {steps / r['kernel_s']:.3g} variant-steps/s), "
            f"simulate+measure {r['simulate_measure_s']:.2f} s, end to end {r['end_to_end_s']:.1f} s "
            f"(report {r['report_s']:.1f} s); statuses equal to the reference: {r['statuses_equal']}; "
            f"{r['statuses']}; first launch (compiling) {r['compile_s']:.1f} s",
            flush=True,
        )
        print(f"      sweep timings: {json.dumps({k: round(v, 2) for k, v in r['sweep_timings'].items()})}", flush=True)
    cold, warm = kept_kernels()
    print(
        f"(gpu) `nlcx sweep --device cuda` of 10,000 variants, report off: {cold:.1f} s compiling its GPU kernels, "
        f"{warm:.1f} s loading them (kept on disk by the first)",
        flush=True,
    )
    if table:
        from run import write_speed_table

        write_speed_table(table)


if __name__ == "__main__":
    main()

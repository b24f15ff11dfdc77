"""Benchmark (g): how a sweep scales with its workers and its size.

For each (variants, jobs) asked for, benchmark (b)'s sweep (the x pendulum under error-AGS PID,
M, m, l uniform within +-20 %, 20 s at 1 ms) runs as users run it, ``nlcx sweep --jobs J``
with its report, in a fresh output directory, beside the hand-written limit reference
(benchmarks/reference.py) of the same variants on the same J processes, alternated. It prints
the wall times, their ratio, the report's share, and the parent's serial time (planning
before the pool and assembling after it, from the sweep's manifest.json) per variant.

    python benchmarks/scaling.py --runs 10000:2,40000:2          # the 2-core figures
    python benchmarks/scaling.py --runs 4000:1,4000:16,40000:16  # a 16-core machine
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

import run as bench


def one(n: int, jobs: int, repeats: int) -> dict[str, float]:
    """nlcx sweep and the limit reference of ``n`` variants on ``jobs`` processes, best of ``repeats``."""
    raw = bench.sweep_config(n)
    work = bench.scratch()
    path = work / "sweep.yaml"
    path.write_text(yaml.safe_dump(raw))
    walls, limits, reports, serial, outside = [], [], [], [], []
    for repeat in range(repeats):
        out = work / f"out{repeat}"
        wall, text = bench.run_timed(
            [*bench.NLCX, "sweep", str(path), "--jobs", str(jobs), "--out", str(out)], bench.ROOT
        )
        walls.append(wall)
        reports.append(bench.report_seconds(text))
        timings = json.loads((out / "manifest.json").read_text())["timings_s"]
        serial.append(timings["plan"] + timings["assemble"])
        outside.append(wall - timings["batches"])  # imports, planning, assembling, the report
        limits.append(bench.limit_reference(raw, jobs=jobs)["wall_s"])
    k = walls.index(min(walls))
    return {"variants": n, "jobs": jobs, "wall_s": walls[k], "limit_s": min(limits), "ratio": walls[k] / min(limits),
            "report_s": reports[k], "serial_s": serial[k], "outside_s": outside[k]}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="10000:2,40000:2", help="VARIANTS:JOBS pairs, comma-separated")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    warm = bench.sweep_config(200)  # compile (or load) the kernels once, outside the timings
    path = bench.scratch() / "warm.yaml"
    path.write_text(yaml.safe_dump(warm))
    bench.run_timed([*bench.NLCX, "sweep", str(path), "--jobs", "2", "--out", str(path.parent / "out")], bench.ROOT)
    print(f"(g) sweep scaling, {bench.machine()}")
    for pair in args.runs.split(","):
        n, jobs = (int(v) for v in pair.split(":"))
        r = one(n, jobs, args.repeats)
        print(
            f"    {r['variants']:>7} variants, --jobs {r['jobs']:>2}: nlcx sweep (report on) {r['wall_s']:.2f} s, "
            f"limit reference {r['limit_s']:.2f} s, ratio {r['ratio']:.2f} [target <= 1.3]; "
            f"report {r['report_s']:.2f} s "
            f"({100 * r['report_s'] / r['wall_s']:.1f} %); parent serial {r['serial_s']:.2f} s "
            f"= {1e6 * r['serial_s'] / r['variants']:.1f} us a variant [target <= 0.5 s + 1 us a variant]; "
            f"outside the pool in all (start, imports, the report too) {r['outside_s']:.2f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()

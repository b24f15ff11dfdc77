"""Where a sweep worker's time goes: benchmark (b)'s batches run in this process under
cProfile, the time split by stage. Run from the repository root:

    python benchmarks/profile_sweep.py [BATCHES]

Stages: kernel (the compiled closed loop), metrics (measuring the runs), config (resolving,
validating and preparing each variant), writing (part files) and the rest of a batch.
The process-level part of a sweep (start-up, imports, pool, assembling metrics.csv) is the
difference between benchmark (b)'s wall time and its workers' batch times.
"""

from __future__ import annotations

import cProfile
import pstats
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

#: Stage -> the functions whose cumulative time it is (by module path and name).
STAGES = {
    "kernel": ("kernel/integrator.py", "simulate"),
    "metrics": ("engine/measure.py", "measure_experiments"),
    "config: resolve": ("sweeps/planning.py", "resolve"),
    "config: validate": ("config/building.py", "build"),
    "config: prepare": ("engine/pipeline.py", "prepare"),
    "writing": ("report.py", "write_csv"),
}


def main() -> None:
    from run import planned_batches

    from nlcx import sweeps as sweep

    batches = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    batch = planned_batches(batches + 1)
    sweep.run_batch(batch[0])  # compiled code loaded, caches warm
    profile = cProfile.Profile()
    start = time.perf_counter()
    profile.enable()
    for b in batch[1:]:
        sweep.run_batch(b)
    profile.disable()
    wall = time.perf_counter() - start
    stats = pstats.Stats(profile).stats
    print(f"{batches} batches of 100 variants in one process: {wall:.2f} s ({1e3 * wall / batches:.0f} ms a batch)")
    accounted = 0.0
    for stage, (file, name) in STAGES.items():
        seconds = sum(v[3] for (f, _, n), v in stats.items() if f.endswith(file) and n == name)
        accounted += seconds
        print(f"  {stage:18s} {seconds:6.2f} s  {100 * seconds / wall:5.1f} %")
    rest = wall - accounted
    print(f"  {'rest':18s} {rest:6.2f} s  {100 * rest / wall:5.1f} %  (the profiler's overhead included)")


if __name__ == "__main__":
    main()

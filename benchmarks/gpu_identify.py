"""`nlcx identify --device cuda` against the same study on two CPU cores of the same machine.

    python benchmarks/gpu_identify.py                                   (the eight-hypothesis subset)
    python benchmarks/gpu_identify.py --spec configs/identify/pendulum_all.yaml

Runs the study three times, each into a fresh output directory: on the GPU twice (the first
compiles or loads the GPU kernels, the second finds them kept on disk), then with ``--jobs 2``
pinned to two cores (``taskset -c 0,1``). Prints each wall time, the ratio of the two-core run
to the GPU's second, and whether the three rank the same hypothesis first with the same fitted
values. ``--device cpu`` runs the first two on the CPU instead (a check of this script without a
GPU).
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import sys
import tempfile
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from run import NLCX, run_timed  # noqa: E402


def first_ranked(out: Path) -> tuple[str, str]:
    """The hypothesis ranked first and its fitted values (JSON), from ranking.csv."""
    best = pd.read_csv(out / "ranking.csv").iloc[0]
    return str(best.hypothesis), str(best["values"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spec", type=Path, default=ROOT / "benchmarks" / "identify_subset.yaml")
    parser.add_argument("--device", default="cuda", choices=("cuda", "cpu"), help="where the first two runs go")
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="nlcx-gpu-identify-"))
    pinned = ["taskset", "-c", "0,1"] if shutil.which("taskset") else []
    runs = {
        "device, first": [*NLCX, "identify", str(args.spec), "--device", args.device],
        "device, second": [*NLCX, "identify", str(args.spec), "--device", args.device],
        "2 cores": [*pinned, *NLCX, "identify", str(args.spec), "--jobs", "2"],
    }
    print(f"nlcx identify {args.spec.name}: --device {args.device} against --jobs 2 on two cores; "
          f"{platform.processor() or platform.machine()}, Python {platform.python_version()}", flush=True)  # fmt: skip
    walls, ranked, fitted = {}, {}, {}
    for k, (label, cmd) in enumerate(runs.items()):
        out = scratch / f"run{k}"
        walls[label], _ = run_timed([*cmd, "--out", str(out)], ROOT)
        ranked[label] = first_ranked(out)
        fitted[label] = json.loads((out / "study.json").read_text())["fitted_now"]
        print(f"  {label}: {walls[label]:.1f} s, {fitted[label]} fits, rank 1 {ranked[label][0]}", flush=True)
    same = len(set(ranked.values())) == 1
    ratio = walls["2 cores"] / walls["device, second"]
    print(f"two cores / device (second run): x{ratio:.2f}; the same rank-1 hypothesis and values: {same}", flush=True)
    shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()

"""What each of nlcx's performance mechanisms buys: every benchmark target with and without it.

    python benchmarks/ablation.py | tee benchmarks/ablation.jsonl
    python benchmarks/ablation.py --old REV       (this tree against git revision REV instead)

A mechanism is switched off by replacing one name in the module that holds it (``WITHOUT``),
in a process of its own, when that module is first imported, so both arms import the same
modules in the same order. Both arms of a pair run the same command, one right after the
other, their order alternating; each target is the median of its pairs. The outputs of the
two arms are compared byte for byte: a mechanism changes speed, never a result.

Targets (benchmarks/run.py): (a) the simulation of configs/xyz_error_ags.yaml after warm-up and
``nlcx run`` of it end to end; (b) the 10 000-variant sweep, ``--jobs 2``; (c) ``nlcx
reproduce``, ``--jobs 2``. ``python benchmarks/ablation.py exec MECHANISM -- ARGS`` runs
``nlcx ARGS`` with MECHANISM switched off (``none``: all on).
"""

from __future__ import annotations

import argparse
import gc
import importlib.abc
import importlib.machinery
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))


def _no_painter(module: ModuleType) -> None:
    module._painter = lambda raw: None  # figures drawn in a thread of the run's own process


def _no_mallopt(module: ModuleType) -> None:
    module.reuse_freed_memory = lambda: False  # glibc's default thresholds


def _no_pandas_free_csv(module: ModuleType) -> None:
    import pandas as pd

    write_csv = module.write_csv
    module.write_columns = lambda path, columns: write_csv(path, pd.DataFrame(dict(columns)))


def _no_built_controllers(module: ModuleType) -> None:
    module._BUILT.size = 0  # every variant builds its own PID


def _no_reference_cache(module: ModuleType) -> None:
    module.REFERENCES.size = 0  # every variant computes its own reference arrays


def _no_structure_pid(module: ModuleType) -> None:
    general = module.pid_step
    module.step_for = lambda structure: general  # the general step for every PID


def _no_freezing(module: ModuleType) -> None:
    gc.freeze = lambda: None  # nothing frozen: every collection scans the whole heap


#: mechanism -> (what it is, the module holding it, how it is switched off)
WITHOUT: dict[str, tuple[str, str, Callable[[ModuleType], None]]] = {
    "painter": ("painter process (nlcx run's figure drawn in a second process)", "nlcx.cli.experiments", _no_painter),
    "mallopt": ("mallopt (glibc keeps freed blocks up to 32 MB)", "nlcx.runtime", _no_mallopt),
    "collector_freezing": ("collector freezing (gc.freeze after imports, in workers, at exit)", "nlcx", _no_freezing),
    "pandas_free_csv": ("pandas-free CSV path (metrics and time series to Arrow)", "nlcx.report", _no_pandas_free_csv),
    "build_cache_pid": ("build cache: PIDs shared by variants", "nlcx.controllers.pid", _no_built_controllers),
    "build_cache_reference": (
        "build cache: reference arrays shared by variants",
        "nlcx.engine.prepared",
        _no_reference_cache,
    ),
    "structure_pid": ("per-structure PID step", "nlcx.controllers.pid", _no_structure_pid),
}


class _SwitchOff(importlib.abc.MetaPathFinder):
    """Applies ``patch`` to module ``name`` right after it is first executed."""

    def __init__(self, name: str, patch: Callable[[ModuleType], None]) -> None:
        self.name, self.patch = name, patch

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> Any:
        if fullname != self.name:
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None:
            return spec
        loader, patch = spec.loader, self.patch

        class Patched(importlib.abc.Loader):
            def create_module(self, spec: Any) -> Any:
                return loader.create_module(spec)

            def exec_module(self, module: ModuleType) -> None:
                loader.exec_module(module)
                patch(module)

        spec.loader = Patched()
        return spec


def switch_off(mechanism: str) -> None:
    """Switch ``mechanism`` off in this process (before nlcx is imported)."""
    if mechanism == "none":
        return
    _, module, patch = WITHOUT[mechanism]
    if module in sys.modules:
        patch(sys.modules[module])
    else:
        sys.meta_path.insert(0, _SwitchOff(module, patch))


def _exec(mechanism: str, args: list[str]) -> None:
    switch_off(mechanism)
    from nlcx.cli import main

    sys.argv = ["nlcx", *args]
    main()


_SIMULATE = """
import sys, time
sys.path.insert(0, {tree!r})
sys.path.insert(0, {bench!r})
import ablation
ablation.switch_off({mechanism!r})
from nlcx import config, engine
try:
    from nlcx import compiled_cache
    compiled_cache.ready()
except (ImportError, AttributeError):  # a tree whose import checks the cache
    pass
exp = config.load({config!r})
prepared = engine.prepare(exp)
engine.evaluate([prepared], measure=False)
times = []
for _ in range(7):
    start = time.perf_counter()
    engine.evaluate([prepared], measure=False)
    times.append(time.perf_counter() - start)
print(min(times))
"""


@dataclass(frozen=True)
class Arm:
    """One side of a pair: the source tree nlcx is imported from and the mechanism switched off."""

    label: str
    tree: Path = ROOT
    mechanism: str = "none"

    def nlcx(self, args: Sequence[str]) -> list[str]:
        """The command running ``nlcx ARGS`` on this arm."""
        return [sys.executable, str(Path(__file__).resolve()), "exec", self.mechanism, "--", *args]

    def run(self, args: Sequence[str]) -> float:
        """Wall time of ``nlcx ARGS`` on this arm (its tree first on the path, and the working directory)."""
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join(filter(None, [str(self.tree), os.environ.get("PYTHONPATH")])),
        }
        start = time.perf_counter()
        subprocess.run(self.nlcx(args), cwd=self.tree, env=env, check=True, capture_output=True)
        return time.perf_counter() - start

    def simulate_s(self) -> float:
        """The best of 7 simulations of configs/xyz_error_ags.yaml after warm-up, in one process."""
        code = _SIMULATE.format(
            tree=str(self.tree),
            bench=str(ROOT / "benchmarks"),
            mechanism=self.mechanism,
            config=str(self.tree / "configs" / "xyz_error_ags.yaml"),
        )
        proc = subprocess.run([sys.executable, "-c", code], cwd=self.tree, check=True, capture_output=True, text=True)
        return float(proc.stdout.split()[-1])


def target_args(work: Path, variants: int = 10_000) -> dict[str, tuple[Callable[[Path], list[str]], tuple[str, ...]]]:
    """target -> (the nlcx arguments writing to an output directory, the files compared)."""
    from run import sweep_config

    sweep = work / "bench_b.yaml"
    sweep.write_text(yaml.safe_dump(sweep_config(variants)))
    return {
        "a_run": (
            lambda out: ["run", "configs/xyz_error_ags.yaml", "--out", str(out), "-q"],
            ("metrics.csv", "timeseries.csv", "figure.png"),
        ),
        "b_sweep": (
            lambda out: ["sweep", str(sweep), "--jobs", "2", "--out", str(out), "--no-report"],
            ("metrics.csv",),
        ),
        "c_reproduce": (lambda out: ["reproduce", "--jobs", "2", "--out", str(out)], ("claims.csv",)),
    }


def _same(a: Path, b: Path, files: Sequence[str]) -> bool:
    return all((a / f).read_bytes() == (b / f).read_bytes() for f in files)


def warm(trees: Sequence[Path], targets: Sequence[str], variants: int = 10_000) -> None:
    """Run each target once on each tree: numba's cache then holds every kernel they compile."""
    with tempfile.TemporaryDirectory(prefix="nlcx-warm-") as tmp:
        commands = target_args(Path(tmp), variants)
        for k, tree in enumerate(trees):
            for target in targets:
                if target in commands:
                    Arm(f"warm{k}", tree).run(commands[target][0](Path(tmp) / f"{k}-{target}"))


def _pair(reference: Arm, other: Arm, target: str, n: int, work: Path, commands: dict[str, Any]) -> dict[str, Any]:
    """``n`` interleaved runs of ``target`` on both arms, each into a new directory (a sweep
    resumes from a directory it finds); their medians and whether the arms wrote the same bytes."""
    times: dict[str, list[float]] = {reference.label: [], other.label: []}
    same = True
    for k in range(n):
        for arm in (reference, other) if k % 2 == 0 else (other, reference):
            if target == "a_simulate":
                times[arm.label].append(arm.simulate_s())
            else:
                out = Path(tempfile.mkdtemp(dir=work)) / "out"
                times[arm.label].append(arm.run(commands[target][0](out)))
                if arm is reference:
                    reference_out = out
                else:
                    other_out = out
        if target != "a_simulate":
            same = same and _same(reference_out, other_out, commands[target][1])
            for out in (reference_out, other_out):
                shutil.rmtree(out.parent)
    row = {
        "pair": f"{reference.label} vs {other.label}",
        "target": target,
        "reference_s": statistics.median(times[reference.label]),
        "other_s": statistics.median(times[other.label]),
        "pairs": n,
        "outputs_identical": same if target != "a_simulate" else None,
        "times": times,
    }
    row["other_slower_by"] = row["other_s"] / row["reference_s"] - 1.0
    return row


def measure(pairs: Sequence[tuple[Arm, Arm]], targets: dict[str, int], variants: int = 10_000) -> list[dict[str, Any]]:
    """For each pair (reference, other) and target: :func:`_pair` (numba's cache warm: :func:`warm`)."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="nlcx-ablation-") as tmp:
        commands = target_args(Path(tmp), variants)
        for reference, other in pairs:
            for target, n in targets.items():
                rows.append(_pair(reference, other, target, n, Path(tmp), commands))
                print(json.dumps(rows[-1]), flush=True)
    return rows


def _worktree(rev: str, where: Path) -> Path:
    tree = where / "old"
    subprocess.run(["git", "worktree", "add", "--detach", str(tree), rev], cwd=ROOT, check=True, capture_output=True)
    return tree


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mechanisms", nargs="*", default=list(WITHOUT), help="those to switch off, one at a time")
    parser.add_argument("--old", metavar="REV", help="instead: this tree against git revision REV, all mechanisms on")
    parser.add_argument("--old-tree", metavar="DIR", type=Path, help="instead: this tree against the sources in DIR")
    parser.add_argument("--no-warm", action="store_true", help="numba's cache is warm already: no warm-up runs")
    parser.add_argument("--warm-only", action="store_true", help="only the warm-up runs")
    parser.add_argument("--variants", type=int, default=10_000, help="the sweep's variants (benchmark (b): 10 000)")
    parser.add_argument("--pairs", default="a_simulate=5,a_run=5,b_sweep=3,c_reproduce=1",
                        help="target=pairs,... (0 or absent: not measured)")  # fmt: skip
    args = parser.parse_args()
    targets = {k: int(v) for k, v in (item.split("=") for item in args.pairs.split(",")) if int(v)}
    if args.old:
        with tempfile.TemporaryDirectory(prefix="nlcx-old-") as tmp:
            tree = _worktree(args.old, Path(tmp))
            try:
                if not args.no_warm:
                    warm([tree, ROOT], list(targets), args.variants)
                print(f"# nlcx: this tree against {args.old}, pairs {targets}", flush=True)
                measure([(Arm(args.old, tree), Arm("this tree"))], targets, args.variants)
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
        return
    trees = [args.old_tree.resolve(), ROOT] if args.old_tree else [ROOT]
    if not args.no_warm:
        warm(trees, list(targets), args.variants)
    if args.warm_only:
        return
    if args.old_tree:
        print(f"# nlcx: this tree against {args.old_tree.name}, pairs {targets}", flush=True)
        measure([(Arm(args.old_tree.name, trees[0]), Arm("this tree"))], targets, args.variants)
        return
    print(f"# nlcx ablation: {len(args.mechanisms)} mechanisms, pairs {targets}", flush=True)
    pairs = [(Arm("all on"), Arm(f"without {m}", mechanism=m)) for m in args.mechanisms]
    measure(pairs, targets, args.variants)


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "exec":
        rest = sys.argv[3:]
        _exec(sys.argv[2], rest[1:] if rest[:1] == ["--"] else rest)
    else:
        main()

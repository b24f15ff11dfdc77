"""Every process-wide effect of nlcx lives in nlcx.runtime, and only a command and its workers get
it: importing nlcx, ``nlcx.run`` and a serial ``nlcx.sweep`` leave the caller's environment
variables, its collector and numba's classes as they were.

The checks that read a whole process run in a fresh Python process, so that what the test
session set does not count.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from importlib.metadata import version
from pathlib import Path

import pytest

from nlcx import runtime

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "nlcx"
CONFIG = ROOT / "configs" / "x_error_ags.yaml"
SWEEP = ROOT / "configs" / "sweeps" / "robustness.yaml"

#: Prints, as JSON, the process-wide state before and after ``{workload}``.
PROBE = """
import gc, json, os
from numba.core.caching import IndexDataCacheFile
def state():
    return {{
        "environ": dict(os.environ),
        "collector on": gc.isenabled(),
        "frozen": gc.get_freeze_count(),
        "numba cache methods": {{n: getattr(IndexDataCacheFile, n).__qualname__ + repr(getattr(
            getattr(IndexDataCacheFile, n), "serialized", False)) for n in ("save", "load", "flush")}},
        "numba cache method ids": [id(getattr(IndexDataCacheFile, n)) for n in ("save", "load", "flush")],
    }}
before = state()
{workload}
from nlcx import runtime
print(json.dumps([before, state(), runtime.reuse_freed_memory.cache_info().misses]))
"""


def _probe(workload: str, tmp_path: Path) -> tuple[dict, dict, int]:
    done = subprocess.run(
        [sys.executable, "-c", PROBE.format(workload=workload)], cwd=tmp_path, capture_output=True, text=True,
        timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    before, after, mallopt_calls = json.loads(done.stdout.splitlines()[-1])
    return before, after, mallopt_calls


LIBRARY = f"""
import nlcx
result = nlcx.run({str(CONFIG)!r}, ["simulation.t_end=1"])
swept = nlcx.sweep({str(SWEEP)!r}, ["sweep.random.n=1", "simulation.t_end=1"], executor="serial")
assert len(swept.variants) == 3 and result.controllers == ["conventional", "proposed"]
"""


def test_the_library_leaves_environment_collector_and_numba_as_they_were(tmp_path: Path) -> None:
    before, after, mallopt_calls = _probe(LIBRARY, tmp_path)
    assert {k: (before[k], after[k]) for k in before if before[k] != after[k]} == {}
    assert mallopt_calls == 0  # mallopt belongs to commands and workers


def test_a_process_sweep_from_the_library_leaves_the_caller_as_it_was(tmp_path: Path) -> None:
    workload = f"""
import nlcx
swept = nlcx.sweep({str(SWEEP)!r}, ["sweep.random.n=2", "simulation.t_end=1"], executor="process", jobs=2)
assert len(swept.variants) == 6
"""
    before, after, mallopt_calls = _probe(workload, tmp_path)
    assert {k: (before[k], after[k]) for k in before if before[k] != after[k]} == {}
    assert mallopt_calls == 0


def test_the_probe_sees_each_change(tmp_path: Path) -> None:
    planted = """
import gc, os
from nlcx import _numba_compat, runtime
os.environ["NLCX_PROBE_PLANTED"] = "1"
gc.freeze()
_numba_compat.serialize_cache_access()
runtime.reuse_freed_memory()
"""
    before, after, mallopt_calls = _probe(planted, tmp_path)
    changed = {k for k in before if before[k] != after[k]}
    assert changed == {"environ", "frozen", "numba cache methods", "numba cache method ids"}
    assert mallopt_calls == 1


COMMAND = """
from nlcx.cli import _app, main
from nlcx import runtime
import sys
@_app.app.command("probe")
def probe() -> None:
    from numba.core.caching import IndexDataCacheFile
    print(json.dumps({"serialized": getattr(IndexDataCacheFile.save, "serialized", False),
                      "role": runtime.role(), "MPLBACKEND": os.environ.get("MPLBACKEND")}))
sys.argv = ["nlcx", "probe"]
try:
    main()
except SystemExit as exit:
    assert not exit.code, exit.code
"""


def test_a_command_enters_the_runtime_and_leaves_it_when_it_ends(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-c", PROBE.format(workload=COMMAND)], cwd=tmp_path, capture_output=True, text=True,
        timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    during = json.loads(done.stdout.splitlines()[0])
    before, after, mallopt_calls = json.loads(done.stdout.splitlines()[-1])
    assert during == {"serialized": True, "role": "command", "MPLBACKEND": "Agg"}
    assert mallopt_calls == 1
    assert before["numba cache method ids"] == after["numba cache method ids"]
    assert before["environ"] == after["environ"] and after["frozen"] == 0


def _worker_state() -> dict[str, object]:
    from numba.core.caching import IndexDataCacheFile

    return {
        "role": runtime.role(),
        "threads": {name: os.environ.get(name) for name in runtime.THREAD_VARIABLES},
        "serialized": getattr(IndexDataCacheFile.save, "serialized", False),
        "mallopt": runtime.reuse_freed_memory.cache_info().misses,
    }


@pytest.mark.parametrize("executor", ["process", "dask"])
def test_a_sweeps_workers_enter_the_runtime_and_the_caller_does_not(executor: str) -> None:
    from nlcx.sweeps.runner import make_executor

    environ = dict(os.environ)
    pool, close = make_executor(executor, 1, None)
    try:
        assert pool is not None
        state = pool.submit(_worker_state).result(timeout=300)
    finally:
        close()
    assert state["role"] == "worker" and state["serialized"] is True and state["mallopt"] == 1
    assert state["threads"] == runtime.thread_variables() and runtime.role() == "library"
    if executor == "process":  # Dask's nannies set distributed's pre-spawn-environ in the caller themselves
        assert dict(os.environ) == environ


def test_every_pool_of_nlcx_starts_its_workers_in_the_runtime() -> None:
    """Each ProcessPoolExecutor nlcx makes names runtime.worker as its initialiser."""
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) == (
                "ProcessPoolExecutor"
            ):
                initializer = {k.arg: ast.unparse(k.value) for k in node.keywords}.get("initializer")
                if initializer != "runtime.worker":
                    missing.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert missing == []
    with ProcessPoolExecutor(max_workers=1, initializer=runtime.worker) as pool:
        assert pool.submit(_worker_state).result(timeout=300)["role"] == "worker"


#: Calls and assignments that change the whole process, allowed in nlcx/runtime.py (and numba's
#: own classes in nlcx/_numba_compat.py) only.
PROCESS_WIDE = ("gc.freeze", "gc.unfreeze", "gc.disable", "gc.set_threshold", "os.putenv", "atexit.register")


def _process_wide(source: str) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            name = ast.unparse(node.func)
            if (
                name in PROCESS_WIDE
                or name.endswith(".mallopt")
                or (name.startswith("os.environ.") and (node.func.attr in ("update", "setdefault", "pop", "clear")))
            ):
                found.append(f"line {node.lineno}: {name}")
        elif isinstance(node, ast.Assign | ast.AugAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                text = ast.unparse(target)
                if text.startswith("os.environ[") or text.startswith(("np.", "numpy.")):
                    found.append(f"line {node.lineno}: {text} =")
    return sorted(found, key=lambda line: int(line.split(":")[0].split()[1]))


def test_process_wide_effects_live_in_the_runtime_only() -> None:
    allowed = {PACKAGE / "runtime.py"}
    offenders = {
        str(path.relative_to(ROOT)): calls
        for path in sorted(PACKAGE.rglob("*.py"))
        if path not in allowed and (calls := _process_wide(path.read_text(encoding="utf-8")))
    }
    assert offenders == {}


def test_the_source_rule_finds_each_process_wide_effect() -> None:
    planted = (
        "import gc, os, ctypes, numpy as np\n"
        "gc.freeze()\n"
        "os.environ['OMP_NUM_THREADS'] = '1'\n"
        "os.environ.update({'A': '1'})\n"
        "ctypes.CDLL(None).mallopt(-3, 1)\n"
        "np.row_stack = np.vstack\n"
        "os.environ.get('A')\n"
    )
    assert [line.split(":")[0] for line in _process_wide(planted)] == ["line 2", "line 3", "line 4", "line 5", "line 6"]


def test_numbas_private_api_is_reached_from_the_compatibility_module_only() -> None:
    private = ("numba.core.caching", "numba.cuda.cudadrv", "numba.core.typing.typeof", "_nrt")
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "_numba_compat.py":
            continue
        text = path.read_text(encoding="utf-8")
        offenders += [f"{path.relative_to(ROOT)}: {name}" for name in private if name in text]
    assert offenders == []


def test_serialised_cache_access_is_given_back() -> None:
    code = """
from numba.core.caching import IndexDataCacheFile
from nlcx import _numba_compat
own = [getattr(IndexDataCacheFile, n) for n in ("save", "load", "flush")]
done = _numba_compat.serialize_cache_access()
assert done == ("save", "load", "flush") and IndexDataCacheFile.save.serialized
assert _numba_compat.serialize_cache_access() == ()
_numba_compat.restore_cache_access(done)
assert [getattr(IndexDataCacheFile, n) for n in ("save", "load", "flush")] == own
print("ok")
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_freed_memory_is_kept_for_reuse_on_glibc() -> None:
    """A command or a worker asks glibc to keep freed blocks of up to 32 MB in its heap (the rows
    a batch measures); elsewhere nothing is changed and it says so."""
    code = "from nlcx import runtime; print(runtime.reuse_freed_memory())"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    try:
        glibc = bool(os.confstr("CS_GNU_LIBC_VERSION"))
    except (ValueError, OSError):
        glibc = False
    assert done.returncode == 0 and done.stdout.strip() == str(glibc), done.stderr


def _decoy_checkout(root: Path) -> Path:
    """A directory holding a package named nlcx that says so when imported, as a checkout of
    another nlcx would."""
    (root / "nlcx" / "cli").mkdir(parents=True)
    (root / "nlcx" / "__init__.py").write_text("")
    (root / "nlcx" / "cli" / "__init__.py").write_text("")
    (root / "nlcx" / "cli" / "__main__.py").write_text("print('the decoy nlcx')\n")
    return root


def test_a_child_module_imports_the_nlcx_its_parent_imported(tmp_path: Path) -> None:
    """The compile helper and the painter, started in a directory holding another nlcx, run this
    process's nlcx; `python -m` would have run the other."""
    cwd = _decoy_checkout(tmp_path)
    child = subprocess.run(runtime.module_command("nlcx.cli", "--version"), cwd=cwd, capture_output=True, text=True)
    assert child.returncode == 0, child.stderr
    assert child.stdout.strip() == f"nlcx {version('nlcx')}"
    plain = subprocess.run([sys.executable, "-m", "nlcx.cli", "--version"], cwd=cwd, capture_output=True, text=True)
    assert plain.stdout.strip() == "the decoy nlcx"  # what module_command is there to avoid


def test_sigterm_ends_a_command_as_ctrl_c_does_and_stops_its_workers(tmp_path: Path) -> None:
    """SIGTERM in a command raises Terminated (a KeyboardInterrupt) in its main thread, after
    stopping its pool's workers, which keep SIGTERM's default action: the pool does not finish
    its minute-long task before the command ends. Outside a command SIGTERM is left alone."""
    code = """
import os, signal, sys, time
from concurrent.futures import ProcessPoolExecutor
from nlcx import runtime
assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
start = time.perf_counter()
try:
    with runtime.command(), ProcessPoolExecutor(max_workers=1, initializer=runtime.worker) as pool:
        assert pool.submit(signal.getsignal, signal.SIGTERM).result(timeout=120) is signal.SIG_DFL
        pool.submit(time.sleep, 60)
        time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(60)
except runtime.Terminated:
    print("terminated", round(time.perf_counter() - start))
assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    word, seconds = done.stdout.split()
    assert word == "terminated" and int(seconds) < 30  # not the minute its worker's task would take

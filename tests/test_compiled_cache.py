"""numba's disk cache is dropped when any source file of the package changes (checked when a
command or the Python API first needs compiled code, not on ``import nlcx``), processes share
it one function's files at a time, and a cold run compiles on two cores."""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from nlcx import _numba_compat, compiled_cache

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "x_error_ags.yaml"


def _package(tmp_path: Path) -> Path:
    root = tmp_path / "pkg"
    (root / "sub" / "__pycache__").mkdir(parents=True)
    (root / "a.py").write_text("x = 1\n")
    (root / "sub" / "b.py").write_text("y = 2\n")
    return root


def test_a_changed_callee_module_drops_every_cached_function(tmp_path: Path) -> None:
    root = _package(tmp_path)
    assert compiled_cache.ensure_consistent(root)  # first run: stamped
    cached = [root / "sub" / "__pycache__" / "b.f-1.py311.nbi", root / "sub" / "__pycache__" / "b.f-1.py311.1.nbc"]
    for path in cached:
        path.write_bytes(b"machine code")
    assert not compiled_cache.ensure_consistent(root)  # nothing changed: the cache stays
    assert all(p.exists() for p in cached)
    (root / "a.py").write_text("x = 3\n")  # another module than the cached function's
    assert compiled_cache.ensure_consistent(root)
    assert not any(p.exists() for p in cached)
    assert (root / "__pycache__" / compiled_cache.STAMP.name).read_text().strip() == compiled_cache.source_digest(root)


def test_a_changed_dependency_drops_the_cache_that_inlines_it(tmp_path: Path) -> None:
    """benchmarks/reference.py inlines nlcx's functions: its stamp covers nlcx's source too."""
    root, dependency = _package(tmp_path), tmp_path / "dep"
    dependency.mkdir()
    (dependency / "c.py").write_text("z = 1\n")
    assert compiled_cache.ensure_consistent(root, depends=(dependency,))
    cached = root / "sub" / "__pycache__" / "b.f-1.py311.nbi"
    cached.write_bytes(b"machine code")
    assert not compiled_cache.ensure_consistent(root, depends=(dependency,))
    assert cached.exists()
    (dependency / "c.py").write_text("z = 2\n")
    assert compiled_cache.ensure_consistent(root, depends=(dependency,))
    assert not cached.exists()


def _python(site: Path, code: str) -> str:
    """What ``code`` prints, run by a Python whose ``nlcx`` is the copy in ``site``."""
    env = {**os.environ, "PYTHONPATH": str(site)}
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=site, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_package_cache_is_checked_when_compiled_code_is_first_needed_not_on_import(tmp_path: Path) -> None:
    """On a copy of the package: importing nlcx (and its command line) leaves numba's cache and
    the stamp alone; ``ready()`` drops a cache it cannot vouch for, keeps it while the source
    is unchanged, and drops it after any module changed."""
    site = tmp_path / "site"
    package = site / "nlcx"
    shutil.copytree(compiled_cache.PACKAGE, package, ignore=shutil.ignore_patterns("__pycache__"))
    stamp = package / "__pycache__" / compiled_cache.STAMP.name
    cached = [package / "kernel" / "__pycache__" / name for name in ("abi.f-1.py311.nbi", "abi.f-1.py311.1.nbc")]

    def plant_cache() -> None:
        cached[0].parent.mkdir(exist_ok=True)
        for path in cached:
            path.write_bytes(b"machine code")

    ready = "from nlcx import compiled_cache; compiled_cache.ready()"
    plant_cache()
    assert _python(site, "import nlcx, nlcx.cli; print(nlcx.__file__)").strip() == str(package / "__init__.py")
    assert all(p.exists() for p in cached) and not stamp.exists()  # the import read and removed nothing
    _python(site, ready)
    assert stamp.exists() and not any(p.exists() for p in cached)  # not stamped before: dropped
    plant_cache()
    _python(site, ready)
    assert all(p.exists() for p in cached)  # the source is unchanged: kept
    layout = package / "layout.py"  # another module than the cached function's
    layout.write_text(layout.read_text() + "# changed\n")
    _python(site, ready)
    assert not any(p.exists() for p in cached)


def _compiled_modules() -> set[str]:
    """The nlcx modules that declare compiled functions (a decorator named njit or hot_njit), read
    from the source: importing one may load its functions from numba's cache."""
    found = set()
    for path in compiled_cache.PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef) and any(
                "njit" in ast.unparse(d.func if isinstance(d, ast.Call) else d) for d in node.decorator_list
            ):
                parts = path.relative_to(compiled_cache.PACKAGE.parent).with_suffix("").parts
                found.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
                break
    return found


#: Records each call of compiled_cache.ready with the modules of compiled functions imported by then.
_SPY = """
import json, sys
from nlcx import compiled_cache
compiled = {compiled!r}
calls = []
original = compiled_cache.ready
def spy():
    calls.append(sorted(m for m in compiled if m in sys.modules))
    original()
compiled_cache.ready = spy
"""


def test_the_api_and_the_command_line_check_the_cache_before_loading_compiled_code(tmp_path: Path) -> None:
    compiled = _compiled_modules()
    assert {"nlcx.kernel.abi", "nlcx.kernel.integrator", "nlcx.controllers.pid_step"} <= compiled
    spy = _SPY.format(compiled=sorted(compiled))
    api = (
        "import nlcx\n"
        "nlcx.__version__, nlcx.ConfigError\n"
        "on_import = list(calls)\n"
        f"nlcx.run({str(CONFIG)!r}, ['simulation.t_end=1'])\n"
        "print(json.dumps([on_import, calls, 'nlcx.kernel.integrator' in sys.modules]))\n"
    )
    cli = (
        "from nlcx.cli import main\n"
        f"sys.argv = ['nlcx', 'run', {str(CONFIG)!r}, 'simulation.t_end=1', '--out', {str(tmp_path / 'run')!r},"
        " '--no-report', '-q']\n"
        "try:\n    main()\nexcept SystemExit as exit:\n    assert not exit.code, exit.code\n"
        "print(json.dumps([calls, 'nlcx.kernel.integrator' in sys.modules]))\n"
    )
    on_import, calls, simulated = _spied(spy + api)
    assert on_import == []  # import nlcx (and names that load nothing compiled) did not call it
    assert calls[:1] == [[]] and simulated  # nlcx.run called it before any compiled function's module was imported
    calls, simulated = _spied(spy + cli)
    assert calls[:1] == [[]] and simulated  # as did nlcx run


def test_commands_that_load_no_compiled_code_leave_numba_alone(tmp_path: Path) -> None:
    """nlcx.cli._app.FILE_COMMANDS skip the check (it imports numba): true only while they load
    no compiled code, which this test holds them to."""
    from nlcx.cli._app import FILE_COMMANDS

    table = tmp_path / "metrics.csv"
    table.write_text("controller,signal,metric,value\nproposed,x,overshoot,1.5\n")
    assert sorted(FILE_COMMANDS) == ["diff"]  # each is run below
    code = _SPY.format(compiled=sorted(_compiled_modules())) + (
        "from nlcx.cli import main\n"
        f"sys.argv = ['nlcx', 'diff', {str(table)!r}, {str(table)!r}]\n"
        "try:\n    main()\nexcept SystemExit as exit:\n    assert not exit.code, exit.code\n"
        "print(json.dumps([calls, sorted(m for m in ('numba', 'matplotlib') if m in sys.modules)]))\n"
    )
    assert _spied(code) == [[], []]


def _spied(code: str) -> Any:
    """The JSON that ``code`` prints last."""
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def _compiled_now() -> None:
    """A function numba has not seen before (a fresh closure, no disk cache), compiled."""
    from numba import njit

    offset = time.monotonic()
    njit(lambda x: x + offset)(1.0)


def test_the_helper_starts_only_when_numba_compiles_in_the_watched_step(tmp_path: Path) -> None:
    marker = tmp_path / "started"
    command = [sys.executable, "-c", f"open({str(marker)!r}, 'w').close()"]
    quick = compiled_cache.CompileHelper(command)
    with quick.watching():
        time.sleep(0.2)  # slow, but nothing compiled
    quick.close()
    assert quick.process is None and not marker.exists()
    slow = compiled_cache.CompileHelper(command)
    with slow.watching():
        _compiled_now()
        _compiled_now()  # a second compilation starts nothing more
    slow.close()
    assert slow.process is not None and slow.process.returncode == 0 and marker.exists()


def test_measuring_waits_for_a_running_helper_and_for_nothing_else(tmp_path: Path) -> None:
    """wait_for_helpers (called before the metric functions are first used) returns once the
    helpers this process started have finished, and at once when there are none."""
    marker = tmp_path / "done"
    command = [sys.executable, "-c", f"import time; time.sleep(0.5); open({str(marker)!r}, 'w').close()"]
    compiled_cache.wait_for_helpers()  # none started: returns at once
    helper = compiled_cache.CompileHelper(command)
    with helper.watching():
        _compiled_now()
    assert helper.process is not None
    compiled_cache.wait_for_helpers()
    assert marker.exists() and helper.process.returncode == 0
    helper.close()  # the command's own close afterwards: nothing left to wait for


def test_the_compiling_notice_is_given_once_when_numba_compiles_and_never_on_a_cached_load(tmp_path: Path) -> None:
    marker = tmp_path / "started"
    command = [sys.executable, "-c", f"open({str(marker)!r}, 'w').close()"]
    notices: list[str] = []
    quick = compiled_cache.CompileHelper(command, notice=lambda: notices.append("quick"))
    with quick.watching():
        time.sleep(0.2)
    quick.close()
    assert notices == []
    slow = compiled_cache.CompileHelper(command, notice=lambda: notices.append("slow"))
    with slow.watching():
        _compiled_now()
        _compiled_now()
    slow.close()
    assert notices == ["slow"]
    line = compiled_cache.COMPILING
    assert "\n" not in line and "numba" in line and "once per install" in line and " s " in line


def _wait_for(condition: Any, timeout: float = 120.0) -> None:
    """Poll ``condition()`` until it holds; fail after ``timeout`` seconds (a hung process)."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"still waiting for {condition}"
        time.sleep(0.01)


def _cache_index(cache: Path) -> set[str]:
    """The compiled functions numba's cache under ``cache`` holds an index for."""
    return {p.name.split("-")[0] for p in cache.rglob("*.nbi")}


@pytest.mark.slow
def test_prewarm_compiles_what_a_run_needs_except_the_kernel_and_the_plant(tmp_path: Path) -> None:
    """`nlcx prewarm` (what `nlcx run` starts beside itself on an empty cache) fills the cache
    with the run's controller and metric functions, but not the kernel nor the plant's
    right-hand side (the run compiles those); a run on that cache then compiles them, and its
    files equal those of a run on the warm cache."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    overrides = ["simulation.t_end=2"]
    nlcx = [sys.executable, "-m", "nlcx.cli"]
    done = subprocess.run([*nlcx, "prewarm", str(CONFIG), *overrides], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    index = _cache_index(tmp_path / "cache")
    assert {"pid_step.pid_step", "schedules.error_ags_gains", "batch.measure_rows", "sums.pairwise_sums"} <= index
    assert not any(name.startswith(("integrator.", "pendulums.")) for name in index)
    for out, run_env in ((tmp_path / "cold", env), (tmp_path / "warm", None)):
        run = [*nlcx, "run", str(CONFIG), *overrides, "--out", str(out), "--no-report", "-q"]
        done = subprocess.run(run, env=run_env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    assert {"integrator.simulate", "pendulums.x_derived_rhs"} <= _cache_index(tmp_path / "cache")
    for name in ("metrics.csv", "timeseries.csv"):
        assert (tmp_path / "cold" / name).read_bytes() == (tmp_path / "warm" / name).read_bytes()


FUNCTION = """
from numba import njit


@njit(cache=True)
def f(a):
    return a * 2 + 1
"""


def _in_child(tmp_path: Path, code: str) -> subprocess.Popen[str]:
    """A Python process that runs ``code`` beside the module ``cached_f`` (in ``tmp_path``),
    with nlcx's cache access serialized (as every nlcx process once ready to load compiled code)."""
    script = (
        f"import sys; sys.path.insert(0, {str(tmp_path)!r})\n"
        "from nlcx import _numba_compat; _numba_compat.serialize_cache_access()\n"
        f"import cached_f\n{code}"
    )
    return subprocess.Popen(
        [sys.executable, "-c", script],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def test_cache_access_is_serialized_once() -> None:
    from numba.core.caching import IndexDataCacheFile

    _numba_compat.serialize_cache_access()
    before = {name: getattr(IndexDataCacheFile, name) for name in ("save", "load", "flush")}
    _numba_compat.serialize_cache_access()
    assert all(getattr(IndexDataCacheFile, name) is op and op.serialized for name, op in before.items())


def _first_line(process: subprocess.Popen[str], timeout: float) -> str:
    """The first line ``process`` prints, or "" if it prints none within ``timeout`` seconds."""
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.append(process.stdout.readline()), daemon=True)  # type: ignore[union-attr]
    reader.start()
    reader.join(timeout)
    return lines[0].strip() if lines else ""


def test_numbas_cache_access_waits_for_the_functions_lock(tmp_path: Path) -> None:
    """A process that looks a compiled function up in numba's cache (and then compiles and saves
    it) waits while another holds the lock beside the function's index (here this test), then
    goes on; a third process loads the saved code. The saver says when it found the lock taken
    (filelock tries again until it is free), and only then is the lock released."""
    from filelock import FileLock

    (tmp_path / "cached_f.py").write_text(FUNCTION)
    sys.path.insert(0, str(tmp_path))
    try:
        import cached_f
    finally:
        sys.path.remove(str(tmp_path))
    index = Path(cached_f.f._cache._cache_file._index_path)
    lock = FileLock(f"{index}.lock")
    lock.acquire()
    saver = _in_child(
        tmp_path,
        "from filelock import FileLock\n"
        "attempt, taken = FileLock._acquire, []\n"
        "def announced(self):\n"
        "    attempt(self)\n"
        "    if not self.is_locked and self.lock_file.endswith('.nbi.lock') and not taken:\n"
        "        print('lock taken', flush=True)\n"
        "        taken.append(self.lock_file)\n"
        "FileLock._acquire = announced\n"
        "print(cached_f.f(20), flush=True)\n",
    )
    try:
        assert _first_line(saver, 120) == "lock taken"
        assert saver.poll() is None and not index.exists()  # held at the lock, nothing saved
    finally:
        lock.release()
    out, err = saver.communicate(timeout=60)
    assert saver.returncode == 0, err
    assert out.strip() == "41" and index.exists()
    loader = _in_child(tmp_path, "print(cached_f.f(20), cached_f.f.stats.cache_hits)\n")
    out, err = loader.communicate(timeout=60)
    assert loader.returncode == 0, err
    assert out.split()[0] == "41" and ": 1" in out  # loaded, not compiled


def test_processes_saving_overloads_of_one_function_at_once_keep_each_its_code(tmp_path: Path) -> None:
    """Four processes compile a different overload of one function at the same moment into one
    cache; a fifth loads all four from it, and each computes with its own types. Each saver says
    when it is ready to call the function and waits for the word go, which all get at once."""
    (tmp_path / "cached_f.py").write_text(FUNCTION)
    arguments = ["7", "2.5", "(1+2j)", "np.float32(1.5)"]
    savers = [
        _in_child(tmp_path, f"import numpy as np\nprint('ready', flush=True)\nsys.stdin.readline()\ncached_f.f({a})\n")
        for a in arguments
    ]
    assert [_first_line(saver, 120) for saver in savers] == ["ready"] * len(savers)
    for saver in savers:
        saver.stdin.write("go\n")  # type: ignore[union-attr]
        saver.stdin.flush()  # type: ignore[union-attr]
    for saver in savers:
        _, err = saver.communicate(timeout=120)
        assert saver.returncode == 0, err
    loader = _in_child(
        tmp_path,
        "import numpy as np\n"
        f"values = [{', '.join(f'cached_f.f({a})' for a in arguments)}]\n"
        "print([repr(v) for v in values], dict(cached_f.f.stats.cache_hits))\n",
    )
    out, err = loader.communicate(timeout=60)
    assert loader.returncode == 0, err
    assert out.startswith("['15', '6.0', '(3+4j)', '4.0']")
    assert out.count(": 1") == 4  # every overload loaded from the cache, none compiled again

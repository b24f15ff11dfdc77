"""numba's disk cache is dropped when any source file of the package changes, and a cold run
compiles on two cores."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

from nlcx import compiled_cache

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "x_error_ags.yaml"


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


def test_the_package_is_stamped_with_its_current_source() -> None:
    stamp = compiled_cache.STAMP
    assert stamp.read_text().strip() == compiled_cache.source_digest()


def test_the_helper_starts_only_when_the_watched_step_is_slow(tmp_path: Path) -> None:
    marker = tmp_path / "started"
    command = [sys.executable, "-c", f"open({str(marker)!r}, 'w').close()"]
    quick = compiled_cache.CompileHelper(command, after=5.0)
    with quick.watching():
        pass
    quick.close()
    assert quick.process is None and not marker.exists()
    slow = compiled_cache.CompileHelper(command, after=0.05)
    with slow.watching():
        time.sleep(0.5)
    slow.close()
    assert slow.process is not None and slow.process.returncode == 0 and marker.exists()


def _cache_index(cache: Path) -> set[str]:
    """The compiled functions numba's cache under ``cache`` holds an index for."""
    return {p.name.split("-")[0] for p in cache.rglob("*.nbi")}


def test_prewarm_compiles_what_a_run_needs_except_the_kernel(tmp_path: Path) -> None:
    """`nlcx prewarm` (what `nlcx run` starts beside itself on an empty cache) fills the cache
    with the run's plugin and metric functions, but not the kernel; a run on that cache then
    compiles the kernel alone, and its files equal those of a run on the warm cache."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    overrides = ["simulation.t_end=2"]
    nlcx = [sys.executable, "-m", "nlcx.cli"]
    done = subprocess.run([*nlcx, "prewarm", str(CONFIG), *overrides], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    index = _cache_index(tmp_path / "cache")
    assert {"pid.pid_step", "pendulums.x_derived_rhs", "metrics._error_terms", "metrics._first_crossing"} <= index
    assert not any(name.startswith("integrator.") for name in index)
    for out, run_env in ((tmp_path / "cold", env), (tmp_path / "warm", None)):
        run = [*nlcx, "run", str(CONFIG), *overrides, "--out", str(out), "--no-report", "-q"]
        done = subprocess.run(run, env=run_env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    assert "integrator.simulate" in _cache_index(tmp_path / "cache")
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
    with nlcx's cache access serialized (as every nlcx process after importing its kernel ABI)."""
    script = f"import sys; sys.path.insert(0, {str(tmp_path)!r})\nimport nlcx.kernel.abi\nimport cached_f\n{code}"
    return subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_cache_access_is_serialized_once() -> None:
    from numba.core.caching import IndexDataCacheFile

    import nlcx.kernel.abi  # noqa: F401  (serializes on import)

    before = {name: getattr(IndexDataCacheFile, name) for name in ("save", "load", "flush")}
    compiled_cache.serialize_cache_access()
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
    goes on; a third process loads the saved code."""
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
        "from numba.core.caching import IndexDataCacheFile\n"
        "load = IndexDataCacheFile.load\n"
        "def announced(self, key):\n"
        "    print('looking up', flush=True)\n"
        "    return load(self, key)\n"
        "IndexDataCacheFile.load = announced\n"
        "print(cached_f.f(20), flush=True)\n",
    )
    try:
        assert _first_line(saver, 60) == "looking up"
        time.sleep(1.0)
        assert saver.poll() is None and not index.exists()  # held at the lock
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
    cache; a fifth loads all four from it, and each computes with its own types."""
    (tmp_path / "cached_f.py").write_text(FUNCTION)
    start = time.time() + 3.0
    arguments = ["7", "2.5", "(1+2j)", "np.float32(1.5)"]
    savers = [
        _in_child(tmp_path, f"import time, numpy as np\ntime.sleep(max(0.0, {start} - time.time()))\ncached_f.f({a})\n")
        for a in arguments
    ]
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

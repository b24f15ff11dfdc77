"""Keep numba's disk cache consistent with the package's source, and fill it on two cores.

numba's ``cache=True`` keys each compiled function on its own module's source file only. A
function that calls another module's compiled function directly (the PID calls the built-in
gain schedules, the integrator calls the friction physics) keeps its cached machine code,
with the *old* callee inlined, after only the callee's module changed. nlcx therefore
stamps the cache with a hash of every source file of the package; when the stamp differs,
the package's cache files (``*.nbi``, ``*.nbc`` in its ``__pycache__`` folders) are removed
before anything is compiled or loaded, and numba rebuilds them. :func:`ready` does this once
per process, before the first module with compiled functions is imported: the command line
calls it before a command runs, the Python API (:mod:`nlcx.api`) before it builds or
simulates an experiment. Importing ``nlcx`` reads and removes nothing.

Rebuilding takes a while: the kernel alone compiles for seconds, in the process that needs it.
:class:`CompileHelper` lets ``nlcx run`` compile the rest of what the run needs (its plugins'
functions, the metric functions) in a second process meanwhile, and the run waits for it
before it measures (:func:`wait_for_helpers`) rather than compile the same functions a second
time. Processes that share the cache (that helper, a sweep's or a reproduction's workers) read
and write a function's cache files one at a time
(:func:`nlcx._numba_compat.serialize_cache_access`).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

from nlcx._numba_compat import check_version

PACKAGE = Path(__file__).resolve().parent
STAMP = PACKAGE / "__pycache__" / "numba-source.sha256"


def files_digest(root: Path, pattern: str, skip: tuple[str, ...] = (), prefix: bytes = b"") -> str:
    """SHA-256 over ``prefix``, then the relative path (``/``-separated) and bytes of every file
    under ``root`` whose name matches ``pattern``, in sorted order, but those whose relative
    path is in ``skip``."""
    digest = hashlib.sha256(prefix)
    for path in sorted(root.rglob(pattern)):
        name = path.relative_to(root).as_posix()
        if name not in skip:
            digest.update(name.encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def source_digest(root: Path = PACKAGE) -> str:
    """SHA-256 over the relative path and bytes of every ``.py`` file of the package."""
    return files_digest(root, "*.py")


def cache_files(root: Path = PACKAGE) -> list[Path]:
    """numba's index and data files in the package's ``__pycache__`` folders, and the GPU
    kernels kept there (:func:`nlcx.kernel.device.kept`)."""
    patterns = ("*.nbi", "*.nbc", "cuda-kernels/*.kernel")
    return [p for pattern in patterns for p in root.rglob(f"__pycache__/{pattern}")]


def ensure_consistent(root: Path = PACKAGE, stamp: Path | None = None, depends: tuple[Path, ...] = ()) -> bool:
    """Remove the package's numba cache if the source changed since it was stamped; True if
    it was removed. ``depends``: other packages whose compiled functions ``root``'s functions call
    (and inline), their source hashed into the stamp too (benchmarks/reference.py inlines nlcx's).
    A read-only install (no writable ``__pycache__``) is left alone."""
    stamp = stamp or root / "__pycache__" / STAMP.name
    current = "".join(source_digest(path) for path in (root, *depends))
    try:
        if stamp.is_file() and stamp.read_text(encoding="ascii").strip() == current:
            return False
        for path in cache_files(root):
            path.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(current + "\n", encoding="ascii")
        tmp.replace(stamp)
    except OSError:
        return False
    return True


@functools.cache
def ready() -> None:
    """Prepare this process to load the package's compiled functions (once; the processes it
    forks inherit it): say in one line if numba's version is untested
    (:func:`nlcx._numba_compat.check_version`) and drop the package's numba cache if the source
    changed since it was stamped (:func:`ensure_consistent`). The reads and writes of the cache
    files are serialised between processes by whoever runs nlcx (:mod:`nlcx.runtime`).

    Call it before importing a module that declares compiled functions: a function compiled
    for an explicit signature is loaded from the cache when its module is imported."""
    check_version()
    ensure_consistent()


#: What ``nlcx run`` prints on stderr when it finds numba's cache empty or stale (:class:`CompileHelper`).
COMPILING = (
    "compiling nlcx's simulation kernel and this run's functions into numba's disk cache: once per install "
    "(and after nlcx's source changes), about 10 s on 2 idle cores; later runs load them in under a second"
)


class CompileHelper:
    """A command run in a second process, started only if numba compiles during a step of this
    one (a miss of its disk cache: :func:`nlcx._numba_compat.on_first_compile`): ``nlcx run``
    watches loading the kernel, which is quick from numba's cache and takes seconds when it
    compiles, and then starts ``nlcx prewarm`` with the run's config (:func:`nlcx.engine.prewarm`).
    Both processes write numba's cache, one function's files at a time
    (:func:`nlcx._numba_compat.serialize_cache_access`), so either may finish first.

    ``notice``, if given, is called when the command starts (the moment this process knows
    that it compiles): ``nlcx run`` says there in one line what the wait is (:data:`COMPILING`)."""

    def __init__(self, command: list[str], notice: Callable[[], None] | None = None) -> None:
        self.command = command
        self.notice = notice
        self.process: subprocess.Popen[bytes] | None = None

    def _start(self) -> None:
        if self.notice is not None:
            self.notice()
        self.process = subprocess.Popen(
            self.command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        _RUNNING.append(self)

    @contextlib.contextmanager
    def watching(self) -> Iterator[None]:
        """Start the command (once) when numba compiles within the block."""
        from nlcx._numba_compat import on_first_compile

        with on_first_compile(self._start):
            yield

    def close(self, timeout: float = 120.0) -> None:
        """Wait for the command if it was started (killed after ``timeout`` seconds)."""
        if self.process is None:
            return
        try:
            self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        finally:
            if self in _RUNNING:
                _RUNNING.remove(self)


#: The helpers this process started that may still run (:func:`wait_for_helpers`).
_RUNNING: list[CompileHelper] = []


def wait_for_helpers(timeout: float = 120.0) -> None:
    """Wait for every :class:`CompileHelper` this process started and has not closed (each
    killed after ``timeout`` seconds); at once if there is none.

    A process about to call functions that its helper compiles (``nlcx run`` measuring its runs
    with the metric functions) waits here: loading them from the cache once the helper is done
    is quicker than compiling them a second time beside it, on the same cores."""
    for helper in list(_RUNNING):
        helper.close(timeout)

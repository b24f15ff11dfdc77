"""Everything nlcx changes in a process, in one place: what it sets, and which processes ask for it.

Importing nlcx and calling the library (:func:`nlcx.run`, :func:`nlcx.sweep` on the serial
executor, :func:`nlcx.load_run`, ...) change nothing in the caller's process: its environment
variables, its garbage collector (enabled, nothing frozen) and numba's classes and their methods
are as they were when the call returns. Two kinds of process enter the runtime and get what
makes them faster:

- the command line, for the duration of a command (:func:`command`);
- the worker processes of a sweep, a reproduction or an identification, for their lifetime
  (:func:`worker`, their pool's initialiser).

What each sets, and why (docs/performance.md measures each mechanism that is there for speed):

========================= ============================ ==========================================
effect                    who                          what for
========================= ============================ ==========================================
numba's cache access      a command that loads         a function's cache files read and written
serialised                compiled code, a worker, a   one process at a time (correctness:
(:func:`cache_access`)    library call: each for its   :func:`nlcx._numba_compat.serialize_cache_access`)
                          own duration
one BLAS/OpenMP/numba     worker                       the workers share the cores, not each
thread                                                 worker a pool of threads
freed blocks kept         command, worker              glibc keeps blocks up to 32 MB for reuse
(``mallopt``)                                          (:func:`reuse_freed_memory`)
collector: imports        command, worker              later collections skip numba's, pandas'
frozen                                                 and matplotlib's objects
(:func:`imports_done`,
:func:`settle_heap`)
matplotlib's backend Agg  command                      every figure goes to a file
SIGTERM ends it as Ctrl-C command (a worker keeps      what it wrote is listed, its locks let go,
(:class:`Terminated`)     the default action)          as after Ctrl-C (``kill``, a scheduler)
numpy shim                a process that uses the GPU  numba-cuda before 0.31 calls
(``np.row_stack``)        (:func:`gpu_shims`)          ``np.row_stack``, which numpy 2.5 removed
no fused multiply-add     a process that uses the GPU  the GPU rounds every product and sum as the
on the GPU                (:func:`gpu_compiler`)       CPU does
========================= ============================ ==========================================
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import functools
import gc
import json
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator
from typing import Literal, TextIO

#: The thread-count variables of BLAS, OpenMP and numba: one thread in each worker.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
#: glibc's mallopt parameters (malloc.h) and the values :func:`reuse_freed_memory` sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20
_TRIM_THRESHOLD = 128 << 20

Role = Literal["library", "command", "worker"]
#: What this process is to nlcx: a library's caller (the default), a command or a worker.
_role: Role = "library"


def role() -> Role:
    """Whether this process runs nlcx as a library (the default), a command or a worker."""
    return _role


def thread_variables() -> dict[str, str]:
    """The environment of a worker process: one BLAS, OpenMP and numba thread."""
    return dict.fromkeys(THREAD_VARIABLES, "1")


@functools.cache
def reuse_freed_memory() -> bool:
    """Let this process's C allocator keep freed blocks of up to 32 MB for reuse (glibc only;
    elsewhere nothing changes). Returns whether it did.

    Measuring a batch forms rows of a few MB (outputs gathered from the records, references).
    glibc serves a block that large by mapping fresh pages and unmaps it when freed, so every
    such temporary paid a page fault and the zeroing of each of its pages; a threshold of 32 MB
    (and a trim threshold of 128 MB, above which the top of the heap is returned to the system)
    keeps them in the heap. It changes how much memory the process keeps, never a value."""
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return False
    except (ValueError, OSError):
        return False
    libc = ctypes.CDLL(None)
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD) and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))


@contextlib.contextmanager
def cache_access() -> Iterator[None]:
    """Within the block, this process reads and writes numba's cache files one function at a
    time with every other nlcx process (:func:`nlcx._numba_compat.serialize_cache_access`);
    afterwards numba's cache classes are as they were. A command enters it before it loads
    compiled code (a command that loads none, such as ``nlcx diff``, never imports numba); a
    library call for its own duration."""
    from nlcx import _numba_compat

    done = _numba_compat.serialize_cache_access()
    try:
        yield
    finally:
        _numba_compat.restore_cache_access(done)


class Terminated(KeyboardInterrupt):
    """SIGTERM received by a command (``kill``, a batch scheduler's time limit), raised in its main
    thread: like Ctrl-C's KeyboardInterrupt, it runs every ``finally`` on its way out, so a study
    resumed in place lists what it wrote (:func:`nlcx.rundir.claim_in_place`) and every lock is
    let go; the command line reports it in one line and exits with 143 (128 + SIGTERM)."""


def _terminate(signum: int, frame: object) -> None:
    """SIGTERM's handler in a command: stop the command's worker processes (a pool would otherwise
    finish every task it was given before letting the command end), then raise :class:`Terminated`."""
    import multiprocessing

    for child in multiprocessing.active_children():
        child.terminate()
    raise Terminated


@contextlib.contextmanager
def command() -> Iterator[None]:
    """What a command sets for its process, each restored (where it can be) when it ends: numba's
    note that first-class function types are experimental (the kernel's function tables) not
    shown, nlcx's own warnings (an untested numba) as one line; SIGTERM raising
    :class:`Terminated` in the main thread, so that the command ends as Ctrl-C ends it;
    matplotlib's backend Agg (``MPLBACKEND``, inherited by the processes the command starts);
    freed memory kept (:func:`reuse_freed_memory`, for the process's lifetime); and whatever the
    command froze for the collector (:func:`imports_done`) unfrozen at its end (unless something
    was frozen before)."""
    global _role
    from nlcx import _numba_compat

    before, frozen, backend = _role, gc.get_freeze_count(), os.environ.get("MPLBACKEND")
    main = threading.current_thread() is threading.main_thread()  # only the main thread sets handlers
    on_term = signal.signal(signal.SIGTERM, _terminate) if main else None
    _role = "command"
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", _numba_compat.FIRST_CLASS_FUNCTION_WARNING)
            warnings.showwarning = _one_line_warnings(warnings.showwarning)
            os.environ["MPLBACKEND"] = "Agg"
            reuse_freed_memory()
            yield
    finally:
        _role = before
        if main:
            signal.signal(signal.SIGTERM, on_term)
        _restore_variable("MPLBACKEND", backend)
        if not frozen:
            gc.unfreeze()


def worker() -> None:
    """Enter a worker process (a process pool's initialiser): one BLAS, OpenMP and numba
    thread, numba's cache access serialised, freed memory kept; the collector's heap settled
    by each batch (:func:`settle_heap`); SIGTERM's default action (a worker forked from a command
    would inherit :class:`Terminated`, and a pool that stops it must see it end)."""
    global _role
    from nlcx import _numba_compat

    _role = "worker"
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a pool stops its workers with SIGTERM: they end at once
    os.environ.update(thread_variables())
    _numba_compat.serialize_cache_access()
    reuse_freed_memory()


def imports_done() -> None:
    """A command's or a worker's imports are done (numba, pandas, matplotlib): leave what they
    built out of later collections (``gc.freeze``); a library call changes nothing."""
    if _role != "library":
        gc.freeze()


def settle_heap() -> None:
    """Collect, then freeze what survives (imported modules, loaded kernels, caches), in a
    command or a worker: its later collections then scan only the objects of the batch in hand
    instead of numba's and pandas' object graphs again and again. A library call changes nothing."""
    if _role != "library":
        gc.collect()
        gc.freeze()


@contextlib.contextmanager
def frozen_for_fork(forking: bool) -> Iterator[None]:
    """Within the block, a command's heap is frozen while it forks its workers (``forking``), so
    that their first collection skips what they inherit; whatever the block froze is unfrozen
    at its end. A library call changes nothing."""
    thawed = gc.get_freeze_count() == 0
    if forking and thawed and _role == "command":
        gc.freeze()
    try:
        yield
    finally:
        if thawed:
            gc.unfreeze()


@functools.cache
def freeze_at_exit() -> None:
    """Freeze the heap when the interpreter exits (the ``nlcx`` command's process): exit
    handlers run before its final garbage collections, which then skip the import graph of
    numba, pandas and matplotlib."""
    atexit.register(gc.freeze)


@functools.cache
def gpu_shims() -> None:
    """Give numpy, once, the function numba-cuda before 0.31 calls and numpy 2.5 removed
    (``np.row_stack``), for a process that uses the GPU or its simulator."""
    import numpy as np

    if not hasattr(np, "row_stack"):
        np.row_stack = np.vstack


@functools.cache
def gpu_compiler() -> None:
    """Compile this process's GPU code without fused multiply-add contraction, once
    (:func:`nlcx._numba_compat.cuda_without_fma`): every product and sum rounds as on the CPU."""
    from nlcx._numba_compat import cuda_without_fma

    cuda_without_fma()


#: ``python -c`` code that takes this process's import path and then runs a module as ``python -m``
#: would (:func:`module_command`).
_RUN_MODULE = (
    "import json, runpy, sys; sys.path[:] = json.loads(sys.argv.pop(1)); "
    "runpy.run_module(sys.argv.pop(1), run_name='__main__', alter_sys=True)"
)


def module_command(module: str, *args: str) -> list[str]:
    """The command that runs ``module`` (one of nlcx's, such as ``nlcx.cli``) in a child process as
    ``python -m module args`` would, importing what this process imports: the child gets this
    process's import path (``sys.path``).

    ``python -m`` puts the working directory first on the path. Started in a checkout of nlcx's
    source with nlcx installed elsewhere (``pip install .``), the child would import the checkout
    instead: another nlcx, perhaps another version, whose numba cache is another directory (a
    compile helper would fill a cache the run never reads).

    Examples
    --------
    >>> import sys
    >>> from nlcx.runtime import module_command
    >>> command = module_command("nlcx.cli", "--version")
    >>> command[0] == sys.executable, command[1], command[-2:]
    (True, '-c', ['nlcx.cli', '--version'])
    """
    return [sys.executable, "-c", _RUN_MODULE, json.dumps(sys.path), module, *args]


def _restore_variable(name: str, value: str | None) -> None:
    """Set environment variable ``name`` back to ``value`` (``None``: it was not set)."""
    if value is None:
        os.environ.pop(name, None)
    else:
        os.environ[name] = value


def _one_line_warnings(show: Callable[..., None]) -> Callable[..., None]:
    """``warnings.showwarning`` that prints a warning of nlcx's own as ``warning: <message>`` on
    stderr, and hands every other to ``show``."""
    from nlcx.terminal import echo

    def show_warning(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        if category.__module__.split(".")[0] == "nlcx":
            echo(f"warning: {message}", err=True)
        else:
            show(message, category, filename, lineno, file, line)

    return show_warning

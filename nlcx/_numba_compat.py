"""Every use of numba's private API, in one place, checked against the versions it is tested with.

nlcx relies on things numba does not document as public:

- ``_nrt=False``: a function compiled without numba's reference counting (the hot-loop rule
  of :mod:`nlcx.kernel.abi`); :func:`hot_njit` is ``numba.njit`` with it;
- ``no_cpython_wrapper=True`` and ``no_cfunc_wrapper=True``: a function compiled without the
  wrappers that let Python call it and make it a first-class function value;
  :func:`inner_njit` is ``numba.njit`` with them;
- ``numba.core.typing.typeof.typeof_impl``: how a Python object is typed when the kernel is
  called (:func:`register_typeof`);
- ``numba.core.caching.IndexDataCacheFile`` and its ``_index_path``: the disk cache's index
  file, whose reads and writes nlcx serialises between processes (:func:`serialize_cache_access`);
- the text of the warning numba gives for first-class function types
  (:data:`FIRST_CLASS_FUNCTION_WARNING`);
- numba-cuda's ``cudadrv.nvvm`` (:func:`load_nvvm`, :func:`cuda_without_fma`) and a kernel
  dispatcher's ``_cache`` (:func:`keep_compiled_kernels`).

A numba version outside :data:`TESTED` may have changed any of them: :func:`check_version`
says so in one line (:class:`UntestedNumbaWarning`). Nothing here changes numba or the
process when this module is imported; numba itself is imported on first use.
"""

from __future__ import annotations

import contextlib
import functools
import re
import types
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeGuard, TypeVar

if TYPE_CHECKING:
    # numba's classes of a compiled function and of its signature, named by nlcx.kernel.signatures
    from numba.core.caching import IndexDataCacheFile
    from numba.core.dispatcher import Dispatcher as Dispatcher
    from numba.core.types import Type
    from numba.core.typing.templates import Signature as Signature
    from numba.cuda.cudadrv.devicearray import DeviceNDArray as DeviceNDArray
    from numba.cuda.dispatcher import CUDADispatcher, _Kernel
    from numba.cuda.target import CUDATargetContext

T = TypeVar("T")

#: numba versions (major, minor) this module is tested with; pyproject pins the same range.
TESTED: tuple[tuple[int, int], ...] = tuple((0, minor) for minor in range(59, 69))

#: The message numba warns with when a compiled function takes compiled functions as values
#: (the kernel's function tables): a regular expression for :func:`warnings.filterwarnings`,
#: which matches from the message's start, where numba puts its terminal's bold codes.
FIRST_CLASS_FUNCTION_WARNING = r"(\x1b\[[0-9;]*m)*First-class function type feature is experimental"


@contextlib.contextmanager
def quiet_first_class_functions() -> Iterator[None]:
    """Within the block, numba's warning that first-class function types are experimental (the
    kernel takes its plugins as function values) is not shown; the warning filters are restored
    afterwards."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", FIRST_CLASS_FUNCTION_WARNING)
        yield


#: The operations on a function's cache files that :func:`serialize_cache_access` serialises.
_CACHE_FILE_OPERATIONS = ("save", "load", "flush")


class UntestedNumbaWarning(UserWarning):
    """The installed numba is not one of the versions in :data:`TESTED`."""


def hot_njit(*args: object, **kwargs: object) -> Any:
    """``numba.njit`` without reference counting (numba's private ``_nrt=False``): for functions
    of the kernel's hot loop that allocate nothing (:mod:`nlcx.kernel.abi`, the hot-loop rule).

    Takes what ``numba.njit`` takes, as a decorator with or without arguments."""
    from numba import njit

    private: Any = njit  # _nrt is not in numba's public signature
    return private(*args, _nrt=False, **kwargs)


def inner_njit(*args: object, **kwargs: object) -> Any:
    """``numba.njit`` without the wrappers a function needs only when Python calls it or when it
    is handed over as a first-class function value (numba's private ``no_cpython_wrapper`` and
    ``no_cfunc_wrapper``; its own ``overload`` implementations are compiled without the first):
    for a function that only compiled code calls by name, such as the kernel's parts.

    The Python wrapper converts every argument from its Python object and the result back. For
    the kernel's parts, which take and return structures of arrays
    (:mod:`nlcx.kernel.structures`), generating and compiling those wrappers is a sizeable part
    of compiling them, and no process ever runs them; the function itself compiles to the same
    machine code. Called from Python, such a function raises a TypeError (numba would call
    through the missing wrapper's null address): its dispatcher is of a subclass of numba's
    ``Dispatcher`` that refuses the call (:func:`_compiled_only`).

    Takes what ``numba.njit`` takes, as a decorator with or without arguments."""
    from numba import njit

    private: Any = njit  # the two options are not in numba's public signature
    made = private(*args, no_cpython_wrapper=True, no_cfunc_wrapper=True, **kwargs)
    if len(args) == 1 and isinstance(args[0], types.FunctionType):  # used as @inner_njit
        return _compiled_only(made)
    return lambda function: _compiled_only(made(function))


def _compiled_only(compiled: T) -> T:
    """``compiled`` (a dispatcher) made to refuse a call from Python (a TypeError), compiled code
    calling it as before: its class swapped for a subclass of numba's ``Dispatcher`` that
    overrides ``__call__`` alone (:func:`inner_njit`). With numba's JIT disabled
    (``NUMBA_DISABLE_JIT=1``) it is the Python function, returned as it is."""
    if is_numba_function(compiled):
        compiled.__class__ = _compiled_only_class()
    return compiled


@functools.cache
def _compiled_only_class() -> type[Dispatcher]:
    from numba.core.dispatcher import Dispatcher

    class CompiledOnly(Dispatcher):
        """A compiled function without a Python wrapper (:func:`inner_njit`)."""

        def __call__(self, *args: object, **kwargs: object) -> None:
            name = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
            raise TypeError(f"{name} is compiled for compiled code only (nlcx._numba_compat.inner_njit)")

    return CompiledOnly


def is_numba_function(value: object) -> TypeGuard[Dispatcher]:
    """Whether ``value`` is a function numba compiled or will compile (a dispatcher, whose
    ``py_func`` is its Python source; numba's ``numba.core.dispatcher.Dispatcher``)."""
    from numba.core.dispatcher import Dispatcher as Dispatcher

    return isinstance(value, Dispatcher)


def register_typeof(cls: type[T], typer: Callable[[T, object], Type]) -> None:
    """Type instances of ``cls`` with ``typer(value, context)`` when a compiled function is called
    (numba's private ``typeof_impl``)."""
    from numba.core.typing.typeof import typeof_impl

    typeof_impl.register(cls)(typer)


def is_tested(version: str) -> bool:
    """Whether numba ``version`` (e.g. ``"0.68.1"``, ``"0.69.0rc1"``) is a release of :data:`TESTED`."""
    match = re.match(r"(\d+)\.(\d+)", version)
    return match is not None and (int(match[1]), int(match[2])) in TESTED


def check_version(version: str | None = None) -> bool:
    """Warn in one line (:class:`UntestedNumbaWarning`) unless numba ``version`` (default: the
    imported numba's) is one of :data:`TESTED`; whether it is."""
    if version is None:
        import numba

        version = numba.__version__
    if is_tested(version):
        return True
    lowest, highest = min(TESTED), max(TESTED)
    warnings.warn(
        f"numba {version} is untested with nlcx (tested: {lowest[0]}.{lowest[1]} to {highest[0]}.{highest[1]}); "
        "the numba internals it relies on (nlcx._numba_compat) may have changed",
        UntestedNumbaWarning,
        stacklevel=2,
    )
    return False


def serialize_cache_access() -> tuple[str, ...]:
    """Make each read or write of a compiled function's files in numba's disk cache one step
    for every process that shares the cache (idempotent; every numba cache of the process).

    numba keeps a function's overloads in an index file and one data file each. To save one it
    reads the index, takes the first free data-file number, writes the index, then the data file,
    with no lock (numba 0.68; numba/numba#10128 reports the same race for GUFuncs, and its
    maintainers suggest a file lock). Two processes saving different overloads of one function
    at once can both take number 1: the index then names one overload and the data file holds
    the other's machine code, which a later run loads for the wrong types (a crash, or a wrong
    result). Here a save, a load and a flush each hold an exclusive lock (:mod:`filelock`) on
    ``<index>.lock`` beside the index, so the second save reads the first's entry and a load
    never reads an index entry whose data file is still being written. Where the lock file
    cannot be made (a read-only cache), the operation runs unlocked, as numba's own.

    Returns the names of the operations this call wrapped (none if they already were), for
    :func:`restore_cache_access`."""
    from numba.core.caching import IndexDataCacheFile

    wrapped = []
    for name in _CACHE_FILE_OPERATIONS:
        operation = getattr(IndexDataCacheFile, name)
        if not getattr(operation, "serialized", False):
            setattr(IndexDataCacheFile, name, _locked(operation))
            wrapped.append(name)
    return tuple(wrapped)


def restore_cache_access(wrapped: tuple[str, ...]) -> None:
    """Give numba's cache-file operations ``wrapped`` (what :func:`serialize_cache_access`
    returned) back their own, unlocked methods."""
    from numba.core.caching import IndexDataCacheFile

    for name in wrapped:
        setattr(IndexDataCacheFile, name, getattr(IndexDataCacheFile, name).__wrapped__)


def _locked(operation: Callable[..., object]) -> Callable[..., object]:
    """``operation`` of an ``IndexDataCacheFile`` run under the lock of the file's index."""
    from filelock import FileLock

    @functools.wraps(operation)
    def run(cache_file: IndexDataCacheFile, *args: object) -> object:
        try:
            lock = FileLock(f"{cache_file._index_path}.lock")
            lock.acquire()
        except OSError:
            return operation(cache_file, *args)
        try:
            return operation(cache_file, *args)
        finally:
            lock.release()

    run.serialized = True  # type: ignore[attr-defined]  # a mark on the function: patched once
    return run


def cuda_without_fma() -> None:
    """Compile numba-cuda's GPU code without fused multiply-add contraction (libNVVM's
    ``-fma=0``) unless a function asks for fast math: every product and sum then rounds as on
    the CPU. numba-cuda passes its own NVVM options only (``fastmath``, ``opt``), so this wraps
    its private ``nvvm.compile_ir`` (numba-cuda 0.30) once per process."""
    from numba.cuda.cudadrv import nvvm

    compile_ir = nvvm.compile_ir
    if getattr(compile_ir, "without_fma", False):
        return

    @functools.wraps(compile_ir)
    def strict(llvmir: object, **options: object) -> object:
        if not options.get("fastmath", False):
            options.setdefault("fma", False)
        return compile_ir(llvmir, **options)

    strict.without_fma = True  # type: ignore[attr-defined]  # a mark on the function: wrapped once
    nvvm.compile_ir = strict


@contextlib.contextmanager
def on_first_compile(callback: Callable[[], None]) -> Iterator[None]:
    """Within the block, call ``callback`` once, when numba first compiles a function: a miss of
    its disk cache (numba's event API, ``numba.core.event``: a ``numba:compile`` event starts only
    when an overload is neither loaded nor found in the cache)."""
    from numba.core import event

    class FirstCompile(event.Listener):
        fired = False

        def on_start(self, ev: object) -> None:
            if not self.fired:
                self.fired = True
                callback()

        def on_end(self, ev: object) -> None:
            return

    with event.install_listener("numba:compile", FirstCompile()):
        yield


def load_nvvm() -> None:
    """Load NVVM, CUDA's compiler of the kernels (numba-cuda's ``cudadrv.nvvm.NVVM``): raises
    what numba-cuda raises when it cannot be found."""
    from numba.cuda.cudadrv.nvvm import NVVM

    NVVM()


def keep_compiled_kernels(dispatcher: CUDADispatcher, directory: Path, key: str) -> None:
    """Keep the kernels ``dispatcher`` (a numba-cuda kernel) compiles in files of ``directory``
    named by ``key`` and the signature, and load them from there in later processes.

    numba-cuda's own disk cache keys a kernel on its closure's pickled contents, which for a
    kernel built at run time around other device functions differ in every process, so it never
    hits; nlcx builds its kernels that way and knows a key that does not change
    (:func:`nlcx.kernel.device.source_key`). This sets the dispatcher's private ``_cache`` to a
    store with numba-cuda's ``load_overload``/``save_overload``, whose files hold what numba-cuda's
    cache holds (``_Kernel._reduce_states()``: the PTX and cubin); numba-cuda 0.30. A file that
    is missing or unreadable means a compilation; one that cannot be written is skipped."""
    dispatcher._cache = _KernelFiles(directory, key)  # type: ignore[assignment]  # numba-cuda calls its cache by its methods only


class _KernelFiles:
    """numba-cuda's cache interface over one file per kernel signature (:func:`keep_compiled_kernels`)."""

    def __init__(self, directory: Path, key: str) -> None:
        self.directory, self.key = directory, key

    def _path(self, sig: object) -> Path:
        import hashlib

        name = hashlib.sha256(f"{self.key}|{sig}".encode()).hexdigest()[:32]
        return self.directory / f"{name}.kernel"

    def load_overload(self, sig: object, target_context: CUDATargetContext) -> _Kernel | None:
        import pickle

        from numba.cuda.dispatcher import _Kernel

        try:
            payload = pickle.loads(self._path(sig).read_bytes())
        except Exception:  # missing, partly written by another process, or from another numba-cuda
            return None
        target_context.refresh()
        return _Kernel._rebuild(**payload)

    def save_overload(self, sig: object, kernel: _Kernel) -> None:
        import os

        from numba.cuda.serialize import dumps

        try:
            data = dumps(kernel._reduce_states())
            self.directory.mkdir(parents=True, exist_ok=True)
            path = self._path(sig)
            tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
            tmp.write_bytes(data)
            tmp.replace(path)
        except Exception:  # a kernel that cannot be kept is compiled again next time
            return

    def flush(self) -> None:
        return

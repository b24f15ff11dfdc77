"""Every use of numba's private API, in one place, checked against the versions it is tested with.

nlcx relies on things numba does not document as public:

- ``_nrt=False``: a function compiled without numba's reference counting (the hot-loop rule
  of :mod:`nlcx.kernel.abi`); :func:`hot_njit` is ``numba.njit`` with it;
- ``numba.core.typing.typeof.typeof_impl``: how a Python object is typed when the kernel is
  called (:func:`register_typeof`);
- ``numba.core.caching.IndexDataCacheFile`` and its ``_index_path``: the disk cache's index
  file, whose reads and writes nlcx serialises between processes (:func:`serialize_cache_access`);
- the text of the warning numba gives for first-class function types
  (:data:`FIRST_CLASS_FUNCTION_WARNING`).

A numba version outside :data:`TESTED` may have changed any of them: :func:`check_version`
says so in one line (:class:`UntestedNumbaWarning`). Nothing here changes numba or the
process when this module is imported; numba itself is imported on first use.
"""

from __future__ import annotations

import contextlib
import functools
import re
import warnings
from collections.abc import Callable, Iterator
from typing import Any

#: numba versions (major, minor) this module is tested with; pyproject pins the same range.
TESTED: tuple[tuple[int, int], ...] = tuple((0, minor) for minor in range(59, 69))

#: The message numba warns with when a compiled function takes compiled functions as values
#: (the kernel's function tables): a regular expression for :func:`warnings.filterwarnings`.
FIRST_CLASS_FUNCTION_WARNING = "First-class function type feature is experimental"


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


def hot_njit(*args: Any, **kwargs: Any) -> Any:
    """``numba.njit`` without reference counting (numba's private ``_nrt=False``): for functions
    of the kernel's hot loop that allocate nothing (:mod:`nlcx.kernel.abi`, the hot-loop rule).

    Takes what ``numba.njit`` takes, as a decorator with or without arguments."""
    from numba import njit

    private: Any = njit  # _nrt is not in numba's public signature
    return private(*args, _nrt=False, **kwargs)


def register_typeof(cls: type, typer: Callable[[Any, Any], Any]) -> None:
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


def serialize_cache_access() -> None:
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
    cannot be made (a read-only cache), the operation runs unlocked, as numba's own."""
    from numba.core.caching import IndexDataCacheFile

    for name in _CACHE_FILE_OPERATIONS:
        operation = getattr(IndexDataCacheFile, name)
        if not getattr(operation, "serialized", False):
            setattr(IndexDataCacheFile, name, _locked(operation))


def _locked(operation: Callable[..., Any]) -> Callable[..., Any]:
    """``operation`` of an ``IndexDataCacheFile`` run under the lock of the file's index."""
    from filelock import FileLock

    @functools.wraps(operation)
    def run(cache_file: Any, *args: Any) -> Any:
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

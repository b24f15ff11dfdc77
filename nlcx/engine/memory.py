"""The engine's memory: freed blocks kept by the C allocator for reuse."""

from __future__ import annotations

import ctypes
import functools
import os

#: glibc's mallopt parameters (malloc.h) and the values :func:`reuse_freed_memory` sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20
_TRIM_THRESHOLD = 128 << 20


@functools.cache
def reuse_freed_memory() -> bool:
    """Let this process's C allocator keep freed blocks of up to 32 MB for reuse (glibc only;
    elsewhere nothing changes). Returns whether it did.

    Measuring a batch forms rows of a few MB (outputs gathered from the records, errors, the
    terms of the trapezoidal sums). glibc serves a block that large by mapping fresh pages and
    unmaps it when freed, so every such temporary paid a page fault and the zeroing of each of
    its pages; a threshold of 32 MB (and a trim threshold of 128 MB, above which the top of the
    heap is returned to the system) keeps them in the heap. :func:`nlcx.engine.evaluate` calls it, so every
    process that measures runs (``nlcx run``, sweep workers, the reproduction's workers, tuners)
    keeps its freed blocks; it changes how much memory the process keeps, never a value."""
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return False
    except (ValueError, OSError):
        return False
    libc = ctypes.CDLL(None)
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD) and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))

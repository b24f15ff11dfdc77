"""The engine's memory: record arrays lent again between batches, and freed blocks kept for reuse."""

from __future__ import annotations

import ctypes
import functools
import os

import numpy as np


class RecordArena:
    """Record arrays (X, U, logs, friction) handed out again once their runs are done with.

    A sweep batch's records are tens of MB. Fresh from ``np.empty`` for every batch, each of
    their pages costs the kernel a page fault and the operating system's zeroing when first
    written. A sweep worker lends a batch's records from its arena and, once the
    batch's metrics are written, :meth:`release` returns them: the next batch writes into the
    same memory. Only what the last batch used is kept."""

    def __init__(self) -> None:
        self._free: list[np.ndarray] = []
        self._lent: list[np.ndarray] = []

    def take(self, shape: tuple[int, ...]) -> np.ndarray:
        """An array of ``shape`` (its values undefined, as ``np.empty``'s)."""
        for i, a in enumerate(self._free):
            if a.shape == shape:
                a = self._free.pop(i)
                a.flags.writeable = True
                break
        else:
            a = np.empty(shape)
        self._lent.append(a)
        return a

    def release(self) -> None:
        """Every array lent so far may be handed out again: no run reading it is used after this."""
        self._free, self._lent = self._lent, []


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

"""Named layouts of the packed parameter blocks the compiled code reads.

The compiled step functions take their numbers from flat float64 rows (a row per variant;
the kernel hands a plant its parameter rows as columns, ``p[P.M, b]``).
Every block of such a row (a PID loop's header, a schedule's parameters, a friction axis,
a loop element's parameters) is declared once, by name, as a :class:`Layout`. The compiled
code reads the offsets the declaration generates, ``p[row, o + AGS.kp_rate]``, never a
literal position, and the Python side packs and unpacks through the same declaration::

    LOOP = Layout("PIDLoop", ("y_index", "sign", "N"))
    L = LOOP.at                      # a namedtuple of offsets: L.y_index == 0, L.N == 2
    row = LOOP.pack(y_index=0, sign=-1.0, N=100.0)
    LOOP.unpack(row)                 # {'y_index': 0.0, 'sign': -1.0, 'N': 100.0}

numba freezes a module-level namedtuple of ints into constants, so ``o + L.N`` compiles to
the same code as the literal offset. Declare a layout in the module whose compiled functions
read it (numba's cache keys a function on its own module; :mod:`nlcx.compiled_cache` drops
the whole cache when any source file changes, so a layout read from elsewhere stays correct).
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np


class Layout:
    """A block of named float64 fields, packed in declaration order."""

    def __init__(self, name: str, fields: Sequence[str]) -> None:
        if len(set(fields)) != len(fields):
            raise ValueError(f"layout {name}: duplicate field names in {list(fields)}")
        self.name = name
        self.fields: tuple[str, ...] = tuple(fields)
        self._names = frozenset(self.fields)
        #: The offset of each field, as a namedtuple the compiled code reads (``at.sign``); Any to
        #: the type checker, which cannot see the fields a namedtuple is given at run time.
        self.at: Any = namedtuple(name, self.fields)(*range(len(self.fields)))

    @property
    def size(self) -> int:
        """Number of float64 values in one block."""
        return len(self.fields)

    def pack(self, values: Mapping[str, float] | None = None, **kwargs: float) -> np.ndarray:
        """One block from every field by name (bools become 1.0/0.0); missing or unknown names are errors."""
        given = {**(values or {}), **kwargs}
        if given.keys() != self._names:
            unknown = sorted(set(given) - self._names)
            missing = [f for f in self.fields if f not in given]
            raise ValueError(f"layout {self.name}: unknown fields {unknown}, missing fields {missing}")
        return np.array([float(given[f]) for f in self.fields], dtype=float)

    def unpack(self, block: Sequence[float] | np.ndarray, offset: int = 0) -> dict[str, float]:
        """The fields of the block that starts at ``offset`` of ``block``, by name."""
        return {f: float(block[offset + i]) for i, f in enumerate(self.fields)}

    def __repr__(self) -> str:
        return f"Layout({self.name!r}, {self.fields})"

"""The variants' seeds: each child's first state word of ``SeedSequence(seed).spawn(n + 1)[1:]``, at once.

A sweep gives variant i the seed ``int(child.generate_state(1)[0])`` of the (i + 1)-th child
that ``numpy.random.SeedSequence(sweep.seed).spawn`` makes. numpy builds one Python object per
child, several microseconds each: a million-variant plan would spend seconds on its seeds.
:func:`spawned_seeds` computes the same words for a whole range of children in numpy array
arithmetic, following numpy's SeedSequence algorithm (``numpy/random/bit_generator.pyx``:
``mix_entropy`` over the pool, then ``generate_state``) with the child's spawn key as the one
word that differs; ``tests/test_sweep_seeds.py`` holds it to numpy's own results.
"""

from __future__ import annotations

import numpy as np

_INIT_A = np.uint32(0x43B0D7E5)
_MULT_A = np.uint32(0x931E8875)
_INIT_B = np.uint32(0x8B51F9DD)
_MULT_B = np.uint32(0x58F38DED)
_MIX_MULT_L = np.uint32(0xCA01F9DD)
_MIX_MULT_R = np.uint32(0x4973F715)
_XSHIFT = np.uint32(16)
_POOL_SIZE = 4


def _words(value: int) -> list[int]:
    """``value`` as numpy's ``_coerce_to_uint32_array`` splits an int: 32-bit words, least
    significant first; 0 is one word."""
    words = []
    while True:
        words.append(value & 0xFFFFFFFF)
        value >>= 32
        if value == 0:
            return words


class _Hash:
    """numpy's ``hashmix`` with its running constant (which does not depend on the data)."""

    def __init__(self) -> None:
        self.const = _INIT_A

    def __call__(self, value: np.ndarray) -> np.ndarray:
        value = value ^ self.const
        self.const = self.const * _MULT_A
        value = value * self.const
        return value ^ (value >> _XSHIFT)


def _mix(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    result = _MIX_MULT_L * x - _MIX_MULT_R * y
    return result ^ (result >> _XSHIFT)


def spawned_seeds(seed: int, first: int, count: int) -> np.ndarray:
    """The first state word (uint32) of children ``first`` .. ``first + count - 1`` of
    ``SeedSequence(seed)``: ``[int(c.generate_state(1)[0]) for c in SeedSequence(seed).spawn(first + count)[first:]]``.

    Examples
    --------
    >>> import numpy as np
    >>> children = np.random.SeedSequence(7).spawn(4)[1:]
    >>> [int(c.generate_state(1)[0]) for c in children] == spawned_seeds(7, 1, 3).tolist()
    True
    """
    if seed < 0 or first < 0 or first + count > 2**32:
        raise ValueError(f"spawned_seeds: seed {seed} and children {first}..{first + count} out of range")
    with np.errstate(over="ignore"):
        run = _words(seed)
        run += [0] * max(0, _POOL_SIZE - len(run))  # a spawn key follows: numpy pads the run entropy
        entropy = [np.full(count, w, dtype=np.uint32) for w in run]
        entropy.append(np.arange(first, first + count, dtype=np.uint32))  # the spawn key (i,)
        hashmix = _Hash()
        pool = [hashmix(entropy[i]) for i in range(_POOL_SIZE)]
        for src in range(_POOL_SIZE):
            for dst in range(_POOL_SIZE):
                if src != dst:
                    pool[dst] = _mix(pool[dst], hashmix(pool[src]))
        for src in range(_POOL_SIZE, len(entropy)):
            for dst in range(_POOL_SIZE):
                pool[dst] = _mix(pool[dst], hashmix(entropy[src]))
        word = pool[0] ^ _INIT_B
        word = word * (_INIT_B * _MULT_B)
        return word ^ (word >> _XSHIFT)

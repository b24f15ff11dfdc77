"""The stated limits of the counts a user gives nlcx, each checked before any work.

A count past its limit is refused in one line naming the option or key, the value and what is
allowed (:func:`check_count`). The limits of the YAML a config may hold (size, nodes, nesting)
are :mod:`nlcx.safe_yaml`'s; those of a sweep's plan (variants, memory, disk) are sized by
:mod:`nlcx.sweeps.sizing`; those of one run's arrays by :mod:`nlcx.preflight`.
"""

from __future__ import annotations

from nlcx.errors import ConfigError

__all__ = ["MAX_JOBS", "MAX_POINTS", "check_count"]

#: The most worker processes a command takes (``--jobs``, ``jobs=``).
MAX_JOBS = 256
#: The most frozen points of ``nlcx linearize --along`` (``--points``, ``points=``).
MAX_POINTS = 10_000


def check_count(key: str, value: object, lowest: int, highest: int, what: str) -> int:
    """``value`` if it is an integer from ``lowest`` to ``highest``; else a :class:`ConfigError`
    naming ``key`` (``what`` says what the count is)."""
    if isinstance(value, bool) or not isinstance(value, int) or not lowest <= value <= highest:
        raise ConfigError(key, value, f"{what}; allowed: an integer from {lowest:,} to {highest:,}")
    return value

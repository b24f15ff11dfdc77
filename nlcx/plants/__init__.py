"""Plants: right-hand sides f(t, x, u, p) with their metadata, registered by name."""

from __future__ import annotations

from typing import Any

__all__ = ["from_control"]


def __getattr__(name: str) -> Any:
    """``from_control`` (:mod:`nlcx.plants.lti`), imported on first use: the package imports nothing."""
    if name == "from_control":
        from nlcx.plants.lti import from_control

        return from_control
    raise AttributeError(f"module 'nlcx.plants' has no attribute {name!r}")

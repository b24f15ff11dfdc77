"""The ``nlcx`` command line: the Typer application (:data:`app`) and its entry point (:func:`main`).

The commands live in :mod:`nlcx.cli.experiments` (run, sweep, validate, reproduce, report,
calibrate, identify), :mod:`nlcx.cli.inspecting` (diff, metrics, list) and
:mod:`nlcx.cli.analysis` (linearize); importing this package registers them on :data:`app`.
What a command sets for its process (the garbage collector, warnings, matplotlib's backend)
is set and restored by :func:`command_settings`.
"""

from __future__ import annotations

import atexit
import functools
import gc

from nlcx.cli import analysis, experiments, inspecting
from nlcx.cli._app import app, command_settings, one_line_errors

__all__ = ["app", "command_settings", "main", "one_line_errors"]

_COMMANDS = (experiments, inspecting, analysis)  # imported for the commands they register


def main() -> None:  # pragma: no cover - console entry point
    """The ``nlcx`` command.

    When the interpreter exits, everything still alive is frozen first (:func:`_freeze_at_exit`),
    so its final collections do not walk the import graph of numba, pandas and matplotlib, a
    noticeable part of a short run."""
    _freeze_at_exit()
    app()


@functools.cache
def _freeze_at_exit() -> None:
    """Freeze the heap when the interpreter exits: exit handlers run before its final garbage
    collections. Until then nothing is frozen on the command's behalf."""
    atexit.register(gc.freeze)

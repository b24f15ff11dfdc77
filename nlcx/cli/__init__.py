"""The ``nlcx`` command line: the Typer application (:data:`app`) and its entry point (:func:`main`).

The commands live in :mod:`nlcx.cli.experiments` (run, sweep, validate, reproduce, report,
calibrate, identify) and :mod:`nlcx.cli.inspecting` (diff, metrics, list); importing this
package registers them on :data:`app`.
"""

from __future__ import annotations

import gc

from nlcx.cli import experiments, inspecting
from nlcx.cli._app import app, one_line_errors

__all__ = ["app", "main", "one_line_errors"]

_COMMANDS = (experiments, inspecting)  # imported for the commands they register


def main() -> None:  # pragma: no cover - console entry point
    """The ``nlcx`` command.

    The garbage collector is off while a command imports its libraries (the long commands
    switch it back on, see :func:`_imported`), and at exit everything still alive is frozen,
    so the interpreter's final collection does not walk the import graph of numba, pandas and
    matplotlib (about half a second of a three-second run)."""
    gc.disable()
    try:
        app()
    finally:
        gc.freeze()

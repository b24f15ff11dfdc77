"""The ``nlcx`` command line: the Typer application (:data:`app`) and its entry point (:func:`main`).

The commands live in :mod:`nlcx.cli.experiments` (run, sweep, validate, report),
:mod:`nlcx.cli.inspecting` (diff, metrics, list, schema) and :mod:`nlcx.cli.analysis`
(linearize); importing this package registers them on :data:`app`, and the thesis's commands
(reproduce, baselines, calibrate, identify) by name, imported when used (:mod:`nlcx.cli.lazy`).
What a command sets for its process (numba's cache access, the garbage collector, warnings,
matplotlib's backend) is set and restored by :func:`nlcx.runtime.command`.
"""

from __future__ import annotations

from nlcx import runtime
from nlcx.cli import analysis, experiments, inspecting, lazy
from nlcx.cli._app import app, one_line_errors
from nlcx.terminal import echo

__all__ = ["app", "main", "one_line_errors"]

_COMMANDS = (experiments, inspecting, analysis, lazy)  # imported for the commands they register


def main() -> None:  # pragma: no cover - console entry point
    """The ``nlcx`` command.

    A misused command line (an unknown option or command, a missing argument) is one line on
    stderr, ``usage error: ...; see nlcx COMMAND --help`` (exit 2), like every other refusal.
    When the interpreter exits, everything still alive is frozen first (:func:`nlcx.runtime.freeze_at_exit`),
    so its final collections do not walk the import graph of numba, pandas and matplotlib, a
    noticeable part of a short run."""
    import sys

    import typer

    runtime.freeze_at_exit()
    command = typer.main.get_command(app)
    try:
        status = command.main(prog_name="nlcx", standalone_mode=False)
    except typer.Abort:
        echo("interrupted", err=True)
        sys.exit(130)
    except typer.TyperException as exc:  # the parser's errors: a usage error names its command
        context = getattr(exc, "ctx", None)
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        where = f"; see {context.command_path} --help" if context is not None else ""
        line = message.splitlines()[0].rstrip(".") if message else "bad command line"
        echo(f"usage error: {line}{where}", err=True)
        sys.exit(getattr(exc, "exit_code", 2))
    sys.exit(status if isinstance(status, int) else 0)

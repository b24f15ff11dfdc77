"""The thesis's commands, registered by name and help and imported when one is used.

The thesis is a study built on nlcx (:mod:`nlcx.thesis`): its commands (:mod:`nlcx.thesis.cli`)
are listed by ``nlcx --help`` from :data:`THESIS_COMMANDS` alone, and the module of one is
imported only when it runs or shows its own help (:class:`LazyCommand`). Importing
:mod:`nlcx.cli` and running ``nlcx run`` leave the thesis unimported. This table is the one
place outside ``nlcx/thesis`` that names the thesis's modules (tests/test_architecture.py).
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, cast

import typer
from typer.core import TyperCommand

from nlcx.cli._app import app
from nlcx.cli._help import readable

if TYPE_CHECKING:
    from collections.abc import Callable

    from typer._click import Context

#: command -> (``module:function`` of its function, the one line of help ``nlcx --help`` lists).
THESIS_COMMANDS: dict[str, tuple[str, str]] = {
    "reproduce": (
        "nlcx.thesis.cli:reproduce",
        "Regenerate the thesis's figures and tables (ours beside theirs) and check its claims.",
    ),
    "baselines": (
        "nlcx.thesis.cli:baselines",
        "AGS PID against the baselines (LQR, sliding mode) on the four pendulums, in the thesis's scenarios and "
        "a robustness sweep (docs/baselines.md): one directory, one report.",
    ),
    "calibrate": (
        "nlcx.thesis.cli:calibrate",
        "Fit unprinted numbers (e.g. the conventional gains) to a thesis table with the seeded GA.",
    ),
    "identify": (
        "nlcx.thesis.cli:identify",
        "Fit loop hypotheses to the train tables, rank them on validation (resumable).",
    ),
}


class LazyCommand(TyperCommand):
    """A command of :data:`THESIS_COMMANDS`: the group lists it by its name and help; the command
    itself, its options and its own help, is built from its function when it is first used
    (:meth:`load`), and parses and runs the command line."""

    @functools.cached_property
    def loaded(self) -> TyperCommand:
        """The command built from its function, as ``@app.command()`` builds one."""
        from nlcx.registry import load_entry_point

        name = str(self.name)
        single = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
        function = cast("Callable[..., object]", load_entry_point(THESIS_COMMANDS[name][0]))  # the command's
        single.command(name)(function)
        command = typer.main.get_command(single)
        assert isinstance(command, TyperCommand), f"{name}: one function makes one command"
        return readable(command)

    def make_context(
        self, info_name: str | None, args: list[str], parent: Context | None = None, **extra: object
    ) -> Context:
        """The loaded command's context for ``args``: it parses them (its ``--help`` included),
        and the group runs it."""
        return self.loaded.make_context(info_name, args, parent=parent, **extra)


def _placeholder() -> None:  # pragma: no cover - a LazyCommand hands its command line to the loaded command
    """Never called: :meth:`LazyCommand.make_context` gives the command line to the loaded command."""


for _name, (_, _help) in THESIS_COMMANDS.items():
    app.command(_name, cls=LazyCommand, help=_help)(_placeholder)

"""The Typer application, the argument types and the error handling every command shares."""

from __future__ import annotations

import functools
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, TypeVar

import typer

from nlcx import compiled_cache, runtime
from nlcx.cli._help import ReadableGroup
from nlcx.errors import NlcxError
from nlcx.limits import MAX_JOBS, check_count
from nlcx.terminal import echo

app = typer.Typer(
    cls=ReadableGroup,
    add_completion=True,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Reproducible experiments on the control of nonlinear systems.\n\n"
    "Shell completion (bash, zsh, fish): nlcx --install-completion, or nlcx --show-completion to print the script.",
)


def _print_version(value: bool) -> None:
    """``--version``: print ``nlcx <version>`` and exit before any command runs."""
    if value:
        from nlcx._version import __version__

        echo(f"nlcx {__version__}")
        raise typer.Exit()


#: Commands that compare files and load no compiled code: numba's cache is not checked for them
#: (:func:`nlcx.compiled_cache.ready` imports numba).
FILE_COMMANDS = frozenset({"diff"})


@app.callback()
def _options(
    ctx: typer.Context,
    version: Annotated[
        bool,
        typer.Option(
            "--version", "-V", callback=_print_version, is_eager=True, help="Print the version of nlcx and exit."
        ),
    ] = False,
) -> None:
    """Reproducible experiments on the control of nonlinear systems."""
    ctx.with_resource(runtime.command())  # left when the command ends
    if ctx.invoked_subcommand not in FILE_COMMANDS:
        ctx.with_resource(runtime.cache_access())  # before the command loads any compiled function
        compiled_cache.ready()


F = TypeVar("F", bound=Callable[..., object])

ConfigArg = Annotated[Path, typer.Argument(help="Experiment YAML file.", show_default=False)]
OverridesArg = Annotated[
    list[str] | None,
    typer.Argument(
        help="Overrides in Hydra's grammar: key=value (set), +key=value (add), ++key=value (add or set), "
        "~key or ~key=value (delete); e.g. simulation.t_end=30.",
        show_default=False,
    ),
]
NoReport = Annotated[bool, typer.Option("--no-report", help="Do not write report.html / report.md.")]
AllowEnv = Annotated[
    bool,
    typer.Option(
        "--allow-env",
        help="Let the config's ${...} call every OmegaConf resolver, oc.env (the process's environment) "
        "included; recorded in the manifest. Off, a config reads only its own values.",
    ),
]


def one_line_errors(func: F) -> F:
    """Report errors as one line on stderr instead of a traceback: an nlcx error as it words
    itself (exit 2 for a refused input, 1 for work that failed: :attr:`NlcxError.exit_code`);
    anything else as an internal error, without Python's name for it (exit 1). Every line is
    made printable first (:func:`nlcx.terminal.printable`)."""

    @functools.wraps(func)
    def wrapper(*args: object, **kwargs: object) -> object:
        try:
            return func(*args, **kwargs)
        except (typer.Exit, typer.Abort):
            raise
        except NlcxError as exc:
            echo(_first_line(str(exc)), err=True)
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt as stop:
            terminated = isinstance(stop, runtime.Terminated)
            echo(
                f"{'terminated' if terminated else 'interrupted'}: the output directory was left as it was "
                "(a sweep keeps its finished batches to resume from)",
                err=True,
            )
            raise typer.Exit(143 if terminated else 130) from None
        except BrokenPipeError:  # the reader stopped early (nlcx diff ... | head): nothing more to say
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            raise typer.Exit(1) from None
        except MemoryError:
            echo("error: out of memory; allowed: a smaller config, sweep or input", err=True)
            raise typer.Exit(1) from None
        except Exception as exc:
            if os.environ.get("NLCX_DEBUG"):
                raise
            text = _first_line(str(exc)) or "no message"
            echo(f"internal error: {text} (a defect of nlcx; set NLCX_DEBUG=1 for a traceback)", err=True)
            raise typer.Exit(1) from None

    return wrapper  # type: ignore[return-value]  # functools.wraps keeps the signature Typer reads


def _first_line(text: str) -> str:
    """The first line of ``text`` (an error's message is one line; anything below is dropped)."""
    lines = text.splitlines()
    return lines[0] if lines else ""


PluginsOpt = Annotated[
    list[Path] | None,
    typer.Option(
        "--plugins",
        help="A Python file of plugins (plants, controllers) to import first, as a config's imports: does; "
        "repeat for several.",
        show_default=False,
    ),
]


def load_plugins(files: list[Path] | None) -> None:
    """Import the ``--plugins`` files (relative to the working directory) before the command reads
    anything (:mod:`nlcx.plugins`; the manifest records them with the config's own ``imports``)."""
    if files:
        from nlcx import plugins

        plugins.load(plugins.resolved([str(f) for f in files], Path.cwd(), key="--plugins"), key="--plugins")


def checked_jobs(jobs: int | None) -> int | None:
    """``--jobs`` checked before any work: None (the command's default) or 1 to
    :data:`nlcx.limits.MAX_JOBS`."""
    if jobs is not None:
        check_count("--jobs", jobs, 1, MAX_JOBS, "worker processes")
    return jobs


def fmt(value: float) -> str:
    """A metric's value in a table of the terminal: four significant digits, NaN as a dash."""
    return "—" if value is None or math.isnan(value) else f"{value:.4g}"

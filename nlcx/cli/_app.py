"""The Typer application, the argument types and the error handling every command shares."""

from __future__ import annotations

import functools
import gc
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer

from nlcx.errors import NlcxError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Reproducible experiments on the control of nonlinear systems.",
)


def _print_version(value: bool) -> None:
    """``--version``: print ``nlcx <version>`` and exit before any command runs."""
    if value:
        from nlcx._version import __version__

        typer.echo(f"nlcx {__version__}")
        raise typer.Exit()


@app.callback()
def _options(
    version: Annotated[
        bool,
        typer.Option(
            "--version", "-V", callback=_print_version, is_eager=True, help="Print the version of nlcx and exit."
        ),
    ] = False,
) -> None:
    """Reproducible experiments on the control of nonlinear systems."""


F = TypeVar("F", bound=Callable[..., Any])

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


def one_line_errors(func: F) -> F:
    """Report nlcx errors as one line on stderr (exit 2) instead of a traceback."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except (typer.Exit, typer.Abort):
            raise
        except NlcxError as exc:
            typer.echo(str(exc), err=True)
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            typer.echo(
                "interrupted: the output directory was left as it was "
                "(a sweep keeps its finished batches to resume from)",
                err=True,
            )
            raise typer.Exit(130) from None
        except BrokenPipeError:  # the reader stopped early (nlcx diff ... | head): nothing more to say
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            raise typer.Exit(1) from None
        except Exception as exc:
            if os.environ.get("NLCX_DEBUG"):
                raise
            typer.echo(f"error: {type(exc).__name__}: {exc} (set NLCX_DEBUG=1 for a traceback)", err=True)
            raise typer.Exit(1) from None

    return wrapper  # type: ignore[return-value]


def _imported() -> None:
    """Collect garbage again from here on, leaving out what the imports built (frozen).

    :func:`main` holds the collector off while a command imports numba, pandas and
    matplotlib: collecting their object graphs over and over costs ~15 % of the imports."""
    gc.freeze()
    gc.enable()


def _fmt(value: float) -> str:
    return "—" if value is None or math.isnan(value) else f"{value:.4g}"

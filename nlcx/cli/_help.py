"""How the commands' help and usage lines name their parameters.

Typer writes a required argument as ``{config}`` in the usage line, every flag with a type
(``<bool>``) and every other option with its Python type (``<path>``, ``<list[str]>``).
:func:`readable` makes them read as a command's manual does: arguments in capitals
(``nlcx run [OPTIONS] CONFIG [OVERRIDES]...``), flags bare, and options with a metavar of
what they take (``PATH``, ``N``, ``NUMBER``, ``TEXT``, the choices ``a|b``), an explicit
``metavar=`` as it is. The application's group (:class:`ReadableGroup`) gives each of its
commands' parameters these names (:func:`readable`); Typer's classes are left as they are.
"""

from __future__ import annotations

import types
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

from typer.core import TyperArgument, TyperCommand, TyperGroup, TyperOption

if TYPE_CHECKING:
    from typer._click import Command as ClickCommand
    from typer._click import Context, Parameter

#: A command of the command line (a group is one).
C = TypeVar("C", bound="ClickCommand")

#: The metavar of an option's value, by its Python type.
METAVARS: dict[object, str] = {int: "N", float: "NUMBER", str: "TEXT", Path: "PATH"}


class Argument(TyperArgument):
    """An argument named in capitals (CONFIG, OVERRIDES), without a type beside it."""

    @property
    def display_name_raw(self) -> str:
        """The argument as the usage line, the help and a usage error name it."""
        return (self.metavar or self.name or "").upper()

    def _usage_display_name(self) -> str:
        name = self.display_name_raw
        name = name if self.required else f"[{name}]"
        return name + ("..." if self.nargs != 1 else "")

    def display_type_rich(self, ctx: Context) -> str | None:
        """Nothing beside an argument's name: CONFIG says what it is."""
        return None


def value_metavar(annotation: object) -> str:
    """The metavar of a value of type ``annotation``: :data:`METAVARS`, a tuple's members
    side by side, a list's element (the option repeats), ``a|b`` for a Literal."""
    origin = typing.get_origin(annotation)
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    if origin is typing.Literal:
        return "|".join(str(a) for a in args)
    if origin is list or origin is typing.Union or origin is types.UnionType:
        return value_metavar(args[0]) if args else "TEXT"
    if origin is tuple:
        return " ".join(value_metavar(a) for a in args)
    if isinstance(annotation, type) and issubclass(annotation, Path):
        return "PATH"
    return METAVARS.get(annotation, "TEXT")


class Option(TyperOption):
    """An option with a readable metavar: its own, none for a flag, else :func:`value_metavar`."""

    def display_type_rich(self, ctx: Context) -> str | None:
        if self.metavar is not None:
            return self.metavar
        if self.is_flag or self.count:
            return None
        desc = self.type_descriptor
        if desc.is_choice:
            return "|".join(str(c) for c in desc.choices or ())
        if desc.is_path:
            return "PATH"
        return value_metavar(desc.annotation)


def readable(command: C) -> C:
    """``command`` (and a group's commands, recursively) with its parameters named as this
    module names them: a Typer command becomes a :class:`Command` (a group keeps its class),
    whose parameters, the ones Typer adds included (--help, --install-completion), are
    :class:`Argument` and :class:`Option` (subclasses without state of their own)."""
    if type(command) is TyperCommand:
        cast(TyperCommand, command).__class__ = Command
    for param in command.params:
        _named(param)
    if isinstance(command, TyperGroup):
        for sub in command.commands.values():
            readable(sub)
    return command


def _named(param: Parameter) -> Parameter:
    if type(param) is TyperArgument:
        param.__class__ = Argument
    elif type(param) is TyperOption:
        param.__class__ = Option
    return param


class Command(TyperCommand):
    """A command whose parameters are named readably (see :func:`readable`)."""

    def get_params(self, ctx: Context) -> list[Parameter]:
        return [_named(param) for param in super().get_params(ctx)]


class ReadableGroup(TyperGroup):
    """The application's group: its own and its commands' parameters named readably."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        readable(self)

    def get_params(self, ctx: Context) -> list[Parameter]:
        return [_named(param) for param in super().get_params(ctx)]

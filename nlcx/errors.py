"""Errors that the command line reports as one line, without a traceback."""

from __future__ import annotations

import difflib
from collections.abc import Callable, Iterable


class NlcxError(Exception):
    """Base class of the errors the CLI prints as a single line."""

    #: The command line's exit status for this error: 2, a refused input; 1, work that failed.
    exit_code = 2


class ConfigError(NlcxError):
    """A configuration value is invalid: names the key path, the value and what is allowed."""

    def __init__(self, path: str, value: object, allowed: str) -> None:
        self.path = path
        self.value = value
        self.allowed = allowed
        super().__init__(self.line())

    def __reduce__(self) -> tuple[type, tuple[str, object, str]]:
        return (type(self), (self.path, self.value, self.allowed))

    def line(self) -> str:
        """The one-line message: ``config error: <path> = <value>: <allowed>``."""
        shown = _short_repr(self.value)
        where = self.path or "<config>"
        return f"config error: {where} = {shown}: {self.allowed}"


_MISSING = object()


def _short_repr(value: object, limit: int = 80) -> str:
    if value is _MISSING:
        return "(missing)"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


MISSING = _MISSING


def did_you_mean(name: object, choices: Iterable[str], shown: Callable[[str], str] = str) -> str:
    """`` (did you mean 'NAME'?)``, the closest of ``choices`` to ``name`` by
    :func:`difflib.get_close_matches` as ``shown`` writes it (e.g. a file's name as its path);
    empty when none is close (or ``name`` is not text). Every error about an unknown name
    carries this hint."""
    if not isinstance(name, str):
        return ""
    close = difflib.get_close_matches(name, [str(c) for c in choices], n=1)
    return f" (did you mean {shown(close[0])!r}?)" if close else ""

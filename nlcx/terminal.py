"""Text for a terminal: every character a terminal would obey instead of showing, escaped.

Names that come from files (a CSV's column names, a controller's label, a path) may hold
control characters. Written to a terminal as they are, ``ESC ]0;...`` changes its title and
``ESC [31m`` its colours; a right-to-left override reorders what the reader sees. The
command line passes everything it prints through :func:`printable`, which shows each such
character as its Python escape (``\\x1b``, ``\\u202e``), and keeps line breaks and tabs.
"""

from __future__ import annotations

__all__ = ["echo", "printable"]

#: Characters shown as escapes: C0 controls but tab and line feed, DEL, C1 controls, the
#: bidirectional overrides and isolates, and lone surrogates (which no terminal can encode).
_UNSAFE = [*range(0x00, 0x09), *range(0x0B, 0x20), *range(0x7F, 0xA0), *range(0x202A, 0x202F),
           *range(0x2066, 0x206A), *range(0xD800, 0xE000)]  # fmt: skip
_TABLE = {code: ascii(chr(code))[1:-1] for code in _UNSAFE}


def printable(text: str) -> str:
    """``text`` with every character a terminal would act on (:data:`_UNSAFE`) escaped.

    Examples
    --------
    >>> printable("theta\\x1b]0;owned\\x07")
    'theta\\\\x1b]0;owned\\\\x07'
    >>> printable("two\\nlines")
    'two\\nlines'
    """
    return text.translate(_TABLE)


def echo(message: str = "", err: bool = False, nl: bool = True) -> None:
    """``typer.echo`` of :func:`printable` ``message``."""
    import typer

    typer.echo(printable(message), err=err, nl=nl)

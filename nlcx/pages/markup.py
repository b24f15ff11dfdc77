"""What keeps a page's values text: escaping for the Markdown twin, and links to files.

Every value a template prints is escaped (see :func:`nlcx.pages.render.environment`): the HTML
pages by Jinja2's autoescaping, the Markdown pages by :func:`markdown_text`. Markdown renderers
pass inline HTML through, so :func:`markdown_text` writes ``&``, ``<`` and ``>`` as entities
(no tag, comment or autolink can start), backslash-escapes ``[``, ``]`` (no link or image),
``|`` (no new table cell), backticks and backslashes, and joins lines (no new block).
What nlcx generates itself — the SVG charts, a fenced code block — is :class:`markupsafe.Markup`
and passes through both kinds of page unchanged, so every value inside it is escaped where it
is built.
"""

from __future__ import annotations

import re
from urllib.parse import quote

from markupsafe import Markup

_MARKDOWN = str.maketrans(
    {
        "&": "&amp;",
        "<": "&lt;",
        ">": "&gt;",
        "\\": "\\\\",
        "[": "\\[",
        "]": "\\]",
        "|": "\\|",
        "`": "\\`",
        "\r": " ",
        "\n": " ",
    }
)


def markdown_text(value: object) -> str:
    """``value`` as Markdown text that renders as exactly its characters (a Markup value, which
    nlcx generated, as it is)."""
    if hasattr(value, "__html__"):
        return str(value)
    return str(value).translate(_MARKDOWN)


def href(path: object) -> str:
    """A relative link to a file: the path URL-quoted and starting with ``./`` or ``../``, so
    no file name becomes another scheme (``javascript:x.png`` -> ``./javascript%3Ax.png``), an
    attribute or a Markdown link's end."""
    quoted = quote(str(path), safe="/")
    return quoted if quoted.startswith(("./", "../")) else "./" + quoted


def fenced(text: object, language: str = "") -> Markup:
    """``text`` as a Markdown fenced code block, its fence longer than any run of backticks in
    it (the text cannot close the block)."""
    text = str(text)
    longest = max((len(run) for run in re.findall(r"`+", text)), default=0)
    fence = "`" * max(3, longest + 1)
    body = text if text.endswith("\n") or not text else text + "\n"
    return Markup(f"{fence}{language}\n{body}{fence}")


def code(text: object) -> Markup:
    """``text`` as an inline Markdown code span in a table cell: delimited by more backticks
    than any run in it, lines joined, ``|`` escaped (GitHub's tables split cells at ``|`` even
    in code)."""
    text = str(text).replace("\r", " ").replace("\n", " ").replace("|", "\\|")
    longest = max((len(run) for run in re.findall(r"`+", text)), default=0)
    ticks = "`" * (longest + 1)
    pad = " " if text.startswith("`") or text.endswith("`") else ""
    return Markup(f"{ticks}{pad}{text}{pad}{ticks}")

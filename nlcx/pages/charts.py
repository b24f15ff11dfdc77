"""Small pieces of the pages drawn straight into them as SVG (no image files, no script).

:func:`legend` draws a page's colour key. Every text inside it is escaped here: the piece is
:class:`markupsafe.Markup`, which a page prints as it is.
"""

from __future__ import annotations

from collections.abc import Iterable

from markupsafe import Markup, escape


def legend(keys: Iterable[tuple[str, str]]) -> Markup:
    """A colour key, once per page: ``keys`` as (label, colour) pairs."""
    items = "".join(
        f'<span class="key"><svg width="10" height="10"><rect width="10" height="10" fill="{escape(colour)}"/></svg> '
        f"{escape(label)}</span>"
        for label, colour in keys
    )
    return Markup(f'<p class="legend">{items}</p>')

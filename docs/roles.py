"""Griffe extension (``mkdocs.yml``: the python handler's ``extensions``): docstrings as the site shows them.

nlcx's docstrings are numpydoc with Sphinx roles (``:func:`nlcx.run```), which ``help()`` and editors
show as they are. Before mkdocstrings renders a docstring, this extension rewrites, in the docstring
text it renders (the source is untouched):

- each role into a cross-reference to the object's full path, resolved as Python would from the
  docstring's own scope (``:func:`build``` in ``nlcx.config`` is ``nlcx.config.build``). A role to an
  object of nlcx is a link where that object has a page and code where it has none; ``~`` shows
  the last part of the path only, ``!`` and an object outside nlcx (``:mod:`filelock```) are code.
  A role naming an ``nlcx.`` path that does not exist is a required reference, so ``mkdocs build
  --strict`` fails on it instead of showing a dead name;
- a doctest (``>>>`` lines and their output) outside an ``Examples`` section into a ``pycon`` code
  block, where Markdown would read the ``>>>`` as nested quotes.
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

#: A Sphinx role of the Python domain: ``:func:`target```, ``:class:`~path```, ``:meth:`title <target>```.
ROLE = re.compile(r":(?:py:)?(?P<role>func|class|mod|meth|attr|data|obj|exc|const):`(?P<body>[^`]+)`")
#: A numpydoc section heading's underline.
UNDERLINE = re.compile(r"^\s*-{3,}\s*$")
#: The numpydoc sections whose doctests griffe already lays out as code.
EXAMPLE_SECTIONS = {"examples", "example"}


def _lookup(collection: griffe.ModulesCollection, path: str) -> Any:
    """The object at ``path`` in ``collection``, or None."""
    try:
        return collection[path]
    except (KeyError, ValueError, griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None


def resolve(obj: griffe.Object, target: str, collection: griffe.ModulesCollection) -> str | None:
    """The full path of the object ``target`` names in the docstring of ``obj``, or None if
    nlcx has no such object: a full path as it is, else its first part resolved from ``obj``'s
    scope (its members, then its parents') and the rest looked up below it."""
    target = target.lstrip(".")
    if _lookup(collection, target) is not None:
        return target
    head, _, rest = target.partition(".")
    try:
        base = obj.resolve(head)
    except (griffe.NameResolutionError, AttributeError):
        return None
    path = f"{base}.{rest}" if rest else base
    return path if _lookup(collection, path) is not None else None


def role_markup(obj: griffe.Object, body: str, collection: griffe.ModulesCollection, package: str) -> str:
    """The Markdown (with autorefs' inline HTML) that shows one role's ``body`` in a docstring of
    ``package``."""
    explicit = re.fullmatch(r"(?P<title>.+?)\s*<(?P<target>[^<>]+)>", body)
    title, target = (explicit["title"], explicit["target"]) if explicit else (None, body)
    plain = target.startswith("!")
    short = target.startswith("~")
    target = target.lstrip("!~")
    shown = title or (target.rsplit(".", 1)[-1] if short else target)
    code = f"<code>{html.escape(shown)}</code>"
    if plain:
        return code
    path = resolve(obj, target, collection)
    if path is not None:
        return f'<autoref identifier="{html.escape(path)}" optional>{code}</autoref>'
    if target.startswith(f"{package}."):  # a stale path: a required reference, which --strict refuses
        return f'<autoref identifier="{html.escape(target)}">{code}</autoref>'
    return code


def fence_doctests(text: str) -> str:
    """``text`` with each doctest outside an ``Examples`` section (a ``>>>`` line, its ``...``
    lines and its output up to a blank line) inside a ``pycon`` code block."""
    lines = text.splitlines()
    out: list[str] = []
    section = ""
    fenced = False
    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if stripped.startswith(("```", "~~~")):
            fenced = not fenced
        if i + 1 < len(lines) and UNDERLINE.match(lines[i + 1]) and stripped:
            section = stripped.lower()
        if not fenced and stripped.startswith(">>>") and section not in EXAMPLE_SECTIONS:
            indent = line[: len(line) - len(line.lstrip())]
            block = []
            while i < len(lines) and lines[i].strip():
                block.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i].strip())
                i += 1
            out += [f"{indent}```pycon", *(indent + b for b in block), f"{indent}```"]
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


class SphinxRoles(griffe.Extension):
    """Rewrite the roles and doctests of every docstring of ``package`` once it is loaded."""

    def __init__(self, package: str = "nlcx") -> None:
        super().__init__()
        self.package = package

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        if pkg.path != self.package:
            return
        collection = loader.modules_collection
        seen: set[int] = set()

        def visit(obj: griffe.Object) -> None:
            if id(obj) in seen:
                return
            seen.add(id(obj))
            if obj.docstring is not None:
                value = fence_doctests(obj.docstring.value)
                obj.docstring.value = ROLE.sub(lambda m: role_markup(obj, m["body"], collection, self.package), value)
            for member in obj.members.values():
                if not member.is_alias:
                    visit(member)  # type: ignore[arg-type]

        visit(pkg)

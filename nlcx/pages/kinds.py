"""The report page of each kind of output directory, found by the kind its manifest names
(``nlcx_output``: :data:`nlcx.manifest.MARKER`).

nlcx's own kinds, ``run`` and ``sweep``, are built in. A study built on nlcx adds the pages of
its own outputs under the entry-point group ``nlcx.pages``: the entry point's name is the kind
of output, its value a :class:`ReportPage`, e.g. in the study's pyproject.toml::

    [project.entry-points."nlcx.pages"]
    reproduction = "nlcx.thesis.pages.reproduction:PAGE"

A page's module is imported when a directory of its kind is reported, not before.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from nlcx.errors import ConfigError
from nlcx.registry import load_entry_point

#: The entry-point group of the report pages of other packages' outputs.
GROUP = "nlcx.pages"
#: nlcx's own pages: kind -> ``module:attribute`` of its :class:`ReportPage`.
BUILT_IN = {"run": "nlcx.pages.run:PAGE", "sweep": "nlcx.pages.sweep:PAGE"}


@dataclass(frozen=True)
class ReportPage:
    """How the report of one kind of output directory is made.

    ``templates`` is the folder of its templates ``<kind>.html.j2`` and ``<kind>.md.j2`` (they
    may extend ``base.html.j2`` of :data:`nlcx.pages.render.TEMPLATES`).
    ``context(directory, configs, repo)`` gathers everything the page shows from the
    directory's files, and may write the tables it derives for the page
    (:data:`nlcx.pages.writing.PAGES`): ``configs`` is ``nlcx report --configs`` (None: the
    page's default), ``repo`` the nlcx checkout (None for an installed nlcx)."""

    templates: Path
    context: Callable[[Path, Path | None, Path | None], Mapping[str, object]]


@functools.cache
def _declared() -> dict[str, str]:
    """kind -> entry point of every page: the built-in ones, then the entry points' (a built-in
    kind is never replaced)."""
    pages = dict(BUILT_IN)
    for entry in entry_points(group=GROUP):
        pages.setdefault(entry.name, entry.value)
    return pages


def kinds() -> list[str]:
    """The kinds of output directory that have a report page, the built-in ones first."""
    return list(_declared())


def has_page(kind: str) -> bool:
    """Whether output directories of ``kind`` have a report page (a built-in kind without
    reading the entry points)."""
    return kind in BUILT_IN or kind in _declared()


def page(kind: str) -> ReportPage:
    """The report page of ``kind``, its module imported. A ConfigError naming the entry point
    when ``kind`` has none or it does not name a :class:`ReportPage`."""
    declared = BUILT_IN if kind in BUILT_IN else _declared()
    if kind not in declared:
        raise ConfigError(GROUP, kind, f"a kind of output with a report page: {', '.join(kinds())}")
    found = load_entry_point(declared[kind])
    if not isinstance(found, ReportPage):
        raise ConfigError(f"{GROUP}.{kind}", declared[kind], "an entry point naming an nlcx.pages.kinds.ReportPage")
    return found

"""Render a directory's report: detect its kind, gather its numbers, fill the templates.

Every value a template prints is escaped, so a page shows what a config, a CSV or a file name
holds as text and never runs it: the HTML templates (``*.html.j2``, and templates without a
name) by Jinja2's HTML autoescaping, the Markdown templates (``*.md.j2``) by
:func:`nlcx.pages.markup.markdown_text`, applied to every printed value. Only
:class:`markupsafe.Markup` passes unescaped: the charts and code blocks nlcx builds, which
escape the values inside them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import jinja2

from nlcx import manifest, report
from nlcx.errors import ConfigError
from nlcx.pages import kinds, markup
from nlcx.pages.output_tables import has_table

TEMPLATES = Path(__file__).parent / "templates"


def kind_of(directory: Path) -> str:
    """The kind of output ``directory`` holds: the one its manifest names (``nlcx_output``) when
    that kind has a report page (:mod:`nlcx.pages.kinds`); else a sweep by its tables ``sweep``
    and ``metrics`` in either form (:func:`~nlcx.pages.output_tables.has_table`), a run by its
    metrics.csv."""
    named = _named_kind(directory)
    if named is not None and kinds.has_page(named):
        return named
    if has_table(directory, "sweep") and has_table(directory, "metrics"):
        return "sweep"
    if (directory / "metrics.csv").is_file():
        return "run"
    raise ConfigError(
        "DIR", str(directory), f"an nlcx output directory of a kind with a report page: {', '.join(kinds.kinds())} "
        "(its manifest names none of them and it holds no sweep's or run's tables)",
    )  # fmt: skip


def _named_kind(directory: Path) -> str | None:
    """The kind of output ``directory``'s manifest names; None without a manifest."""
    if not (directory / manifest.MANIFEST).is_file():
        return None
    kind = manifest.load(directory).get(manifest.MARKER)
    return kind if isinstance(kind, str) else None


def number(value: object, digits: int = 4) -> str:
    """A number as the page prints it (— for missing, inf, otherwise ``digits`` significant)."""
    if value is None or value == "":
        return "—"
    if isinstance(value, (int, float)):
        if isinstance(value, float) and math.isnan(value):
            return "—"
        if isinstance(value, float) and math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.{digits}g}"
    return str(value)


def is_html(name: str | None) -> bool:
    """Whether a template is HTML (escaped as HTML): all but the Markdown ones (``*.md.j2``)."""
    return name is None or not name.endswith(".md.j2")


@jinja2.pass_eval_context
def _finalize(eval_ctx: jinja2.nodes.EvalContext, value: object) -> object:
    """Every printed value: left to autoescaping on an HTML page, escaped as Markdown text on
    a Markdown page."""
    return value if eval_ctx.autoescape else markup.markdown_text(value)


def _markdown_only(build: Callable[..., object]) -> Callable[..., object]:
    """A filter that builds Markdown (:func:`~nlcx.pages.markup.fenced`, :func:`~nlcx.pages.markup.code`):
    on an HTML page its result is plain text, escaped like any other value."""

    @jinja2.pass_eval_context
    def apply(eval_ctx: jinja2.nodes.EvalContext, value: object, *args: object) -> object:
        built = build(value, *args)
        return str(built) if eval_ctx.autoescape else built

    return apply


def environment(templates: Path | None = None) -> jinja2.Environment:
    """The templates' environment: the templates of :data:`TEMPLATES`, then those of
    ``templates`` (a page's own folder); every printed value escaped (HTML or Markdown, by the
    template's name), the filters ``num``, ``href``, ``fenced`` and ``code``."""
    folders = [TEMPLATES, *([templates] if templates is not None and templates != TEMPLATES else [])]
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(folders),
        autoescape=is_html,
        finalize=_finalize,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters.update(
        num=number, href=markup.href, fenced=_markdown_only(markup.fenced), code=_markdown_only(markup.code)
    )
    return env


def repository() -> Path | None:
    """The nlcx checkout (for links into docs/), or None for an installed package."""
    root = Path(__file__).resolve().parents[2]
    return root if (root / "docs").is_dir() else None


def write_report(directory: Path, configs: Path | None = None) -> tuple[Path, Path]:
    """Write DIR/report.html and DIR/report.md (atomically): the page of the kind of output DIR
    holds (:func:`kind_of`, :func:`nlcx.pages.kinds.page`), from its files; ``configs`` is handed
    to the page (``nlcx report --configs``)."""
    directory = directory.resolve()
    kind = kind_of(directory)
    page = kinds.page(kind)
    ctx = page.context(directory, configs, repository())
    env = environment(page.templates)
    html, md = directory / "report.html", directory / "report.md"
    report.write_text(html, env.get_template(f"{kind}.html.j2").render(**ctx))
    report.write_text(md, env.get_template(f"{kind}.md.j2").render(**ctx))
    return html, md

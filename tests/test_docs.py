"""The documentation site builds with --strict and holds the generated references."""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _text(page: Path) -> str:
    """A built page's text, tags removed."""
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8")))


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT, capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert build.returncode == 0, build.stdout + build.stderr
    return out


@pytest.mark.slow
def test_the_python_api_reference_documents_every_public_name(site: Path) -> None:
    import nlcx

    text = _text(site / "reference" / "python" / "index.html")
    for name in nlcx.__all__:
        if not name.startswith("_"):
            assert name in text, f"nlcx.{name} is not in the API reference"
    assert "Examples" in text and "load_run" in text


@pytest.mark.slow
def test_the_configuration_reference_lists_every_key_with_its_default(site: Path) -> None:
    from nlcx.config import SimulationSection

    text = _text(site / "reference" / "configuration" / "index.html")
    for key, field in SimulationSection.model_fields.items():
        assert f"simulation.{key}" in text
        assert field.description and field.description.split(",")[0] in text
    for plugin_key in ("settling_band", "error_ags", "mu_s", "x_pendulum"):
        assert plugin_key in text


@pytest.mark.slow
def test_the_cli_reference_lists_every_command_and_option(site: Path) -> None:
    import typer

    from nlcx.cli import app
    from nlcx.cli.lazy import LazyCommand

    text = _text(site / "reference" / "cli" / "index.html")
    command = typer.main.get_command(app)
    for name, sub in command.commands.items():  # type: ignore[attr-defined]
        if isinstance(sub, LazyCommand):  # a thesis command: its options are its function's
            sub = sub.loaded
        if sub.hidden:
            continue
        assert f"nlcx {name}" in text
        for param in sub.params:
            for opt in getattr(param, "opts", []):
                if opt.startswith("--"):
                    assert opt in text, f"nlcx {name} {opt} is not in the CLI reference"


@pytest.mark.slow
def test_every_tutorial_and_guide_page_is_built(site: Path) -> None:
    for page in (ROOT / "docs").rglob("*.md"):
        relative = page.relative_to(ROOT / "docs").with_suffix("")
        built = site / relative / "index.html" if relative.name != "index" else site / relative.parent / "index.html"
        assert built.is_file(), f"{page.relative_to(ROOT)} was not built"


#: A Sphinx role left as it is in the built HTML: ``:func:`x``` or ``:func:<code>x</code>``.
RAW_ROLE = re.compile(r":(func|class|mod|meth|attr|data|obj|exc):(`|<code>)")


def _schema_keys(node: Any, defs: dict[str, Any], prefix: str, seen: frozenset[str] = frozenset()) -> set[str]:
    """Every dotted key the JSON schema node accepts under ``prefix``: a mapping's values under
    ``<*>`` (and the labels it names, ``uncertainty``'s registered names, too), a list's items
    under the same key as a single item."""
    if not isinstance(node, dict):
        return set()
    keys: set[str] = set()
    ref = node.get("$ref")
    if isinstance(ref, str):
        name = ref.rsplit("/", 1)[1]
        if name not in seen:
            keys |= _schema_keys(defs[name], defs, prefix, seen | {name})
    for combinator in ("anyOf", "oneOf", "allOf"):
        for option in node.get(combinator, []):
            keys |= _schema_keys(option, defs, prefix, seen)
    for branch in ("then", "else"):
        keys |= _schema_keys(node.get(branch), defs, prefix, seen)
    mapping = isinstance(node.get("additionalProperties"), dict)
    for key, value in node.get("properties", {}).items():
        full = f"{prefix}{'<*>' if mapping else key}"
        keys.add(full)
        keys |= _schema_keys(value, defs, full + ".", seen)
    if mapping:
        keys |= _schema_keys(node["additionalProperties"], defs, f"{prefix}<*>.", seen)
    keys |= _schema_keys(node.get("items"), defs, prefix, seen)
    return keys


def config_keys() -> set[str]:
    """Every key of an experiment or sweep config file, from nlcx's JSON schema (``nlcx schema``)."""
    from nlcx.schema import experiment_schema

    schema = experiment_schema()
    return _schema_keys(schema, schema["$defs"], "")


def _reference_key(key: str) -> str:
    """A key as the test compares it: each ``<label>`` as ``<*>``, a list's ``[i]`` dropped."""
    return re.sub(r"<[^<>]*>", "<*>", key).replace("[i]", "")


@pytest.mark.slow
def test_no_page_shows_a_raw_sphinx_role(site: Path) -> None:
    found = {
        str(page.relative_to(site)): len(RAW_ROLE.findall(page.read_text(encoding="utf-8")))
        for page in site.rglob("*.html")
    }
    assert not {page: n for page, n in found.items() if n}, "raw Sphinx roles in the built site"
    api = (site / "reference" / "python" / "index.html").read_text(encoding="utf-8")
    assert 'href="../api/#nlcx.results.load_run"' in api  # a role became a link to its object


def test_the_role_and_doctest_rewriting(tmp_path: Path) -> None:
    import griffe

    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import roles
    finally:
        sys.path.remove(str(ROOT / "docs"))
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "__init__.py").write_text(
        '"""Top.\n\n>>> 1 + 1\n2\n\n'
        'See :func:`helper`, :class:`~demo.Thing`, :mod:`filelock`, :func:`demo.gone`.\n"""\n'
        "class Thing:\n    pass\n\ndef helper():\n    pass\n"
    )
    extensions = griffe.load_extensions(roles.SphinxRoles(package="demo"))
    text = griffe.GriffeLoader(extensions=extensions, search_paths=[str(tmp_path)]).load("demo").docstring.value
    assert "```pycon\n>>> 1 + 1\n2\n```" in text
    assert '<autoref identifier="demo.helper" optional><code>helper</code></autoref>' in text
    assert '<autoref identifier="demo.Thing" optional><code>Thing</code></autoref>' in text
    assert "<code>filelock</code>" in text and "filelock</autoref>" not in text
    assert '<autoref identifier="demo.gone"><code>demo.gone</code></autoref>' in text  # required: --strict fails
    assert not RAW_ROLE.search(text)


@pytest.mark.slow
def test_the_configuration_reference_holds_every_key_of_the_schema(site: Path) -> None:
    page = (site / "reference" / "configuration" / "index.html").read_text(encoding="utf-8")
    shown = {_reference_key(html.unescape(k)) for k in re.findall(r"<dt><code>([^<]+)</code></dt>", page)}
    keys = {_reference_key(k) for k in config_keys()}
    for key in ("sweep.random.n", "sweep.random.params.<*>.dist", "extends", "vars", "imports", "simulation.t_end"):
        assert key in keys, f"the schema walk missed {key}"
    missing = sorted(keys - shown)
    assert not missing, f"{len(missing)} config keys are not in the configuration reference: {missing[:20]}"

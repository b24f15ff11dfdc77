"""The documentation site builds with --strict and holds the generated references."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

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

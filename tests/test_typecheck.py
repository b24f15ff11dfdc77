"""mypy is part of the test suite: the package type-checks under pyproject.toml's [tool.mypy]."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_mypy_finds_no_errors_in_the_package() -> None:
    assert importlib.util.find_spec("mypy"), "mypy is a test dependency (pip install -e '.[test]')"
    proc = subprocess.run([sys.executable, "-m", "mypy", "nlcx"], cwd=ROOT, capture_output=True, text=True, check=False)
    errors = [line for line in proc.stdout.splitlines() if ": error:" in line]
    assert proc.returncode == 0, f"{len(errors)} mypy errors:\n" + "\n".join(errors) + proc.stderr


IGNORE = re.compile(r"#\s*type:\s*ignore(\[[^\]]*\])?(?P<rest>.*)$")


def unexplained_ignores(source: str) -> list[int]:
    """Line numbers of ``# type: ignore`` comments with no reason after them on their line."""
    lines = []
    for number, line in enumerate(source.splitlines(), start=1):
        match = IGNORE.search(line)
        if match and not re.match(r"\s*#\s*\w", match["rest"]):
            lines.append(number)
    return lines


def test_every_type_ignore_in_the_package_gives_its_reason_on_its_line() -> None:
    found = {
        f"{path.relative_to(ROOT)}:{line}"
        for path in sorted((ROOT / "nlcx").rglob("*.py"))
        for line in unexplained_ignores(path.read_text())
    }
    assert not found, f"type: ignore without a reason: {sorted(found)}"


def test_the_ignore_rule_refuses_a_planted_bare_ignore() -> None:
    planted = "x: int = 'a'  # type: ignore[assignment]\ny: int = 'b'  # type: ignore\nz: int = 1\n"
    explained = "x: int = 'a'  # type: ignore[assignment]  # a string on purpose\n"
    assert unexplained_ignores(planted) == [1, 2]
    assert unexplained_ignores(explained) == []


@pytest.mark.slow
def test_the_type_check_fails_on_a_planted_error(tmp_path: Path) -> None:
    """mypy under the project's configuration reports a wrong type: the check can fail."""
    planted = tmp_path / "planted.py"
    planted.write_text("def gain(k_p: float) -> float:\n    return k_p\n\n\ngain('1.0')\n")
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"), str(planted)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert 'incompatible type "str"; expected "float"' in proc.stdout

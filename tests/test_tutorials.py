"""The tutorials in docs/tutorials run as a reader would run them, and print what they show.

Each tutorial runs in a fresh directory that holds the repository's ``configs`` (a link) and a
copy of ``results/baseline``, so its relative paths work and nothing is written into the
repository. Its fenced blocks are taken in order:

- a block with a ``title="NAME"`` attribute is a file the reader saves: it is written to NAME
  and not run. A NAME that already exists there (a file of the repository's ``configs``) is
  shown, not saved: the block must say what the file says (YAML: the same data);
- ```` ```python ```` blocks run in one namespace per tutorial, in that directory;
- ```` ```sh ```` blocks: each ``nlcx ...`` line runs through the command line in-process and
  must exit with status 0; ``pip install -e PATH`` registers the entry points of
  ``PATH/pyproject.toml`` and puts PATH on ``sys.path``, as an editable install would;
- a plain ```` ``` ```` block right after a python or sh block (nothing but blank lines between)
  is what it prints, compared as doctest compares (whitespace normalised, ``...`` matches
  anything);
- every yaml and toml block is a file (it has a title): a reader told to save one must be told
  where.
"""

from __future__ import annotations

import contextlib
import doctest
import io
import re
import shlex
import shutil
import sys
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from nlcx import registry
from nlcx.cli import app

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - pytest depends on tomli before Python 3.11
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs"
TUTORIALS = sorted((ROOT / "docs" / "tutorials").glob("*.md"))

#: An opening or closing fence: its indentation, its backticks and the info string after them.
FENCE = re.compile(r"^(?P<indent> *)(?P<ticks>`{3,})(?P<info>[^`]*)$")
#: ``key="value"`` attributes of a fence's info string.
ATTRIBUTE = re.compile(r'(?P<key>[\w-]+)="(?P<value>[^"]*)"')
#: Languages whose blocks are files, never run.
FILE_LANGUAGES = ("yaml", "toml")
CHECK_FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


@dataclass(frozen=True)
class Block:
    """One fenced block of a tutorial."""

    language: str
    title: str | None
    text: str
    #: The line of the opening fence (1-based), for the messages.
    line: int
    #: Only blank lines lie between the previous block's closing fence and this one.
    follows_directly: bool


def fenced_blocks(markdown: str) -> list[Block]:
    """The fenced blocks of ``markdown`` in order (indented blocks, e.g. in an admonition, dedented)."""
    lines = markdown.splitlines()
    blocks: list[Block] = []
    i, last_end = 0, -2
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if opening is None:
            i += 1
            continue
        indent, ticks, info = opening["indent"], opening["ticks"], opening["info"].strip()
        body: list[str] = []
        j = i + 1
        while j < len(lines) and not re.fullmatch(rf"{indent}{ticks}`*\s*", lines[j]):
            body.append(lines[j][len(indent) :])
            j += 1
        assert j < len(lines), f"line {i + 1}: a fence that is never closed"
        attributes = {m["key"]: m["value"] for m in ATTRIBUTE.finditer(info)}
        words = info.strip("{}").split()
        language = words[0].lstrip(".") if words and "=" not in words[0] else ""
        between = lines[last_end + 1 : i]
        blocks.append(
            Block(
                language=language,
                title=attributes.get("title"),
                text="\n".join(body) + "\n",
                line=i + 1,
                follows_directly=last_end >= 0 and all(not line.strip() for line in between),
            )
        )
        last_end, i = j, j + 1
    return blocks


def check_output(where: str, shown: str, printed: str) -> None:
    """``printed`` matches the tutorial's ``shown`` output the way doctest matches (ELLIPSIS,
    NORMALIZE_WHITESPACE); else an assertion naming ``where`` with doctest's difference."""
    checker = doctest.OutputChecker()
    if not checker.check_output(shown, printed, CHECK_FLAGS):
        difference = checker.output_difference(doctest.Example("", shown), printed, CHECK_FLAGS)
        raise AssertionError(f"{where}: the output differs from the one shown\n{difference}")


def logical_lines(script: str) -> list[str]:
    """The commands of a shell block: continuation lines joined, blank lines and comments left out."""
    joined = re.sub(r"\s*\\\n\s*", " ", script)
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.strip().startswith("#")]


class Reader:
    """Follows one tutorial in ``workdir``: saves its files, runs its code and commands."""

    def __init__(self, tutorial: Path, workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
        self.tutorial = tutorial
        self.workdir = workdir
        self.monkeypatch = monkeypatch
        self.namespace: dict[str, Any] = {"__name__": "__main__"}

    def where(self, block: Block) -> str:
        return f"{self.tutorial.name}:{block.line}"

    def follow(self) -> int:
        """Every block in order; an output block is compared with what the block before it printed.
        Returns how many output blocks were compared."""
        printed: str | None = None
        compared = 0
        for block in fenced_blocks(self.tutorial.read_text(encoding="utf-8")):
            if block.language == "" and block.title is None:
                if printed is not None and block.follows_directly:
                    check_output(self.where(block), block.text, printed)
                    compared += 1
                printed = None
            elif block.title is not None:
                self.save(block)
                printed = None
            elif block.language in FILE_LANGUAGES:
                raise AssertionError(f'{self.where(block)}: a {block.language} block without a title="FILE"')
            elif block.language == "python":
                printed = self.run_python(block)
            elif block.language == "sh":
                printed = self.run_shell(block)
            else:
                printed = None
        return compared

    def save(self, block: Block) -> None:
        """Write a titled block to its file; a file of the repository (under the ``configs`` link)
        is not written but must say what the block shows (a YAML file: the same data)."""
        assert block.title is not None
        target = self.workdir / block.title
        if target.resolve().is_relative_to(self.workdir.resolve()):
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(block.text, encoding="utf-8")
            return
        assert target.is_file(), f"{self.where(block)}: the repository has no {block.title}"
        shown, actual = block.text, target.read_text(encoding="utf-8")
        if target.suffix in (".yaml", ".yml"):
            shown, actual = yaml.safe_load(shown), yaml.safe_load(actual)
        assert shown == actual, f"{self.where(block)}: the block differs from {block.title}"

    def run_python(self, block: Block) -> str:
        """Run the block in the tutorial's namespace; what it printed."""
        code = compile(block.text, self.where(block), "exec")
        stdout = io.StringIO()
        with contextlib.redirect_stdout(stdout):
            exec(code, self.namespace)
        return stdout.getvalue()

    def run_shell(self, block: Block) -> str:
        """Run the block's commands; what they printed, one after the other."""
        printed = []
        for line in logical_lines(block.text):
            words = shlex.split(line)
            if words[0] == "nlcx":
                printed.append(self.run_nlcx(block, words[1:]))
            elif words[:3] == ["pip", "install", "-e"] and len(words) == 4:
                self.install_editable(self.workdir / words[3])
            else:
                raise AssertionError(f"{self.where(block)}: the test cannot run {line!r}")
        return "".join(printed)

    def run_nlcx(self, block: Block, args: list[str]) -> str:
        result = CliRunner().invoke(app, args)
        if result.exit_code != 0:
            trace = "".join(traceback.format_exception(*result.exc_info)) if result.exc_info else ""
            raise AssertionError(
                f"{self.where(block)}: nlcx {shlex.join(args)} exited with {result.exit_code}\n{result.output}\n{trace}"
            )
        return result.output

    def install_editable(self, folder: Path) -> None:
        """What ``pip install -e FOLDER`` does for nlcx: FOLDER importable, and the entry points of
        its pyproject.toml in the groups ``nlcx.<kind>`` registered in ``nlcx.registry.ALL[kind]``."""
        project = tomllib.loads((folder / "pyproject.toml").read_text(encoding="utf-8"))["project"]
        self.monkeypatch.syspath_prepend(str(folder))
        for group, entries in project.get("entry-points", {}).items():
            kind = group.removeprefix("nlcx.")
            assert group.startswith("nlcx.") and kind in registry.ALL, f"not an nlcx entry-point group: {group}"
            for name, entry_point in entries.items():
                registry.ALL[kind].register(name, entry_point)


@pytest.fixture
def reader_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A fresh directory with ``configs`` (a link to the repository's) and a copy of
    ``results/baseline``, as the working directory and first on ``sys.path`` (where a reader's
    ``python`` finds the modules they saved), in a terminal 120 columns wide. On the way out,
    the plugins the tutorial registered are taken out of the registries again (a registry has
    no unregister: its entries are restored as they were) and its modules are forgotten."""
    (tmp_path / "configs").symlink_to(CONFIGS, target_is_directory=True)
    shutil.copytree(ROOT / "results" / "baseline", tmp_path / "results" / "baseline")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv("COLUMNS", "120")  # a terminal wide enough for a whole progress bar
    saved = {kind: (dict(reg._entries), dict(reg._loaded), reg._scanned) for kind, reg in registry.ALL.items()}
    yield tmp_path
    for kind, (entries, loaded, scanned) in saved.items():
        reg = registry.ALL[kind]
        reg._entries, reg._loaded, reg._scanned = entries, loaded, scanned
    for name, module in list(sys.modules.items()):
        file = getattr(module, "__file__", None)
        if file is not None and Path(file).is_relative_to(tmp_path):
            del sys.modules[name]


def test_there_are_the_six_tutorials() -> None:
    assert [p.stem for p in TUTORIALS] == [
        "fit-hypotheses",
        "own-controller",
        "plant-plugin",
        "reproduce-a-table",
        "robustness-sweep",
        "script-an-experiment",
    ]


def test_fenced_blocks_finds_titles_languages_and_output_blocks() -> None:
    markdown = (
        'Save `a.yaml`:\n\n```yaml title="a.yaml"\nk: 1\n```\n\n```python\nprint(1)\n```\n\n```\n1\n```\n'
        "Text.\n\n```\nnot an output\n```\n\n!!! note\n    ```sh\n    nlcx --version\n    ```\n"
    )
    blocks = fenced_blocks(markdown)
    assert [(b.language, b.title, b.text, b.follows_directly) for b in blocks] == [
        ("yaml", "a.yaml", "k: 1\n", False),
        ("python", None, "print(1)\n", True),
        ("", None, "1\n", True),
        ("", None, "not an output\n", False),
        ("sh", None, "nlcx --version\n", False),
    ]


def test_check_output_accepts_an_ellipsis_and_refuses_another_number() -> None:
    check_output("t", "done in ... s\n  a   1\n", "done in 2.31 s\na 1\n")
    with pytest.raises(AssertionError, match="the output differs"):
        check_output("t", "a 1\n", "a 2\n")


def test_a_titled_block_is_saved_and_a_repository_file_is_checked(
    reader_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    reader = Reader(reader_dir / "t.md", reader_dir, monkeypatch)
    reader.save(Block("yaml", "sub/a.yaml", "k: 1\n", 1, False))
    assert (reader_dir / "sub" / "a.yaml").read_text() == "k: 1\n"
    robustness = (CONFIGS / "sweeps" / "robustness.yaml").read_text()
    reader.save(Block("yaml", "configs/sweeps/robustness.yaml", robustness + "# a comment\n", 2, False))
    with pytest.raises(AssertionError, match=r"differs from configs/sweeps/robustness\.yaml"):
        reader.save(Block("yaml", "configs/sweeps/robustness.yaml", robustness.replace("n: 200", "n: 20"), 3, False))
    with pytest.raises(AssertionError, match=r"has no configs/new\.yaml"):
        reader.save(Block("yaml", "configs/new.yaml", "k: 1\n", 4, False))
    assert not (CONFIGS / "new.yaml").exists()


def test_logical_lines_joins_continuations_and_drops_comments() -> None:
    assert logical_lines("# a comment\nnlcx run a.yaml \\\n    --out b\n\npip install -e .\n") == [
        "nlcx run a.yaml --out b",
        "pip install -e .",
    ]


@pytest.mark.slow
@pytest.mark.parametrize("tutorial", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_the_tutorial_runs_and_prints_what_it_shows(
    tutorial: Path, reader_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert Reader(tutorial, reader_dir, monkeypatch).follow() > 0, "no output block was compared"

"""Every command's --help reads plainly, and nlcx completes itself in bash, zsh and fish."""

from __future__ import annotations

import re

import pytest
import typer
from typer.testing import CliRunner

from nlcx.cli import app

runner = CliRunner()


def _commands() -> list[str]:
    return sorted(typer.main.get_command(app).commands)  # type: ignore[attr-defined]


#: What must not reach a reader: reStructuredText roles and literals, Typer's type labels and
#: its braces around a required argument.
RAW = re.compile(r"``|:[a-z]+:`|<bool>|<path>|<str>|<int>|<float>|<list\[|\{[a-z_]+\}")


@pytest.mark.parametrize("command", ["", *_commands()])
def test_help_has_no_raw_markup(command: str) -> None:
    result = runner.invoke(app, [*filter(None, [command]), "--help"], prog_name="nlcx", terminal_width=200)
    assert result.exit_code == 0, result.output
    assert "Usage: nlcx" in result.output
    assert RAW.search(result.output) is None, RAW.search(result.output)


def test_the_usage_line_names_arguments_in_capitals_and_options_by_what_they_take() -> None:
    result = runner.invoke(app, ["run", "--help"], prog_name="nlcx", terminal_width=200)
    assert "Usage: nlcx run [OPTIONS] CONFIG [OVERRIDES]..." in result.output
    row = next(line for line in result.output.splitlines() if "--out" in line)
    assert re.search(r"--out\s+PATH\s+Run directory", row), row
    flag = next(line for line in result.output.splitlines() if "--no-report" in line)
    assert re.search(r"--no-report\s+Do not write", flag), flag
    sweep = runner.invoke(app, ["sweep", "--help"], prog_name="nlcx", terminal_width=200)
    jobs = next(line for line in sweep.output.splitlines() if "--jobs" in line)
    assert re.search(r"--jobs\s+-j\s+N\s", jobs), jobs


def test_identify_help_is_plain_text() -> None:
    result = runner.invoke(app, ["identify", "--help"], prog_name="nlcx", terminal_width=200)
    assert result.exit_code == 0
    assert 'A spec with "chapter: 5" is chapter 5\'s study' in result.output


def test_a_usage_error_stays_one_line_and_names_the_argument_in_capitals(capsys: pytest.CaptureFixture[str]) -> None:
    import sys

    from nlcx.cli import main

    argv = sys.argv
    sys.argv = ["nlcx", "run"]
    try:
        with pytest.raises(SystemExit) as exited:
            main()
    finally:
        sys.argv = argv
    assert exited.value.code == 2
    assert capsys.readouterr().err.splitlines() == ["usage error: Missing argument 'CONFIG'; see nlcx run --help"]


def test_the_app_help_says_how_to_install_completion() -> None:
    result = runner.invoke(app, ["--help"], prog_name="nlcx", terminal_width=200)
    assert "Shell completion (bash, zsh, fish): nlcx --install-completion" in result.output
    assert "--install-completion" in result.output and "--show-completion" in result.output


@pytest.mark.parametrize(
    ("shell", "line"),
    [
        ("bash", "complete -o default -F _nlcx_completion nlcx"),
        ("zsh", "#compdef nlcx"),
        ("fish", "complete --command nlcx --no-files"),
    ],
)
def test_the_completion_script_of_each_shell(shell: str, line: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION", "1")  # the shell named, not detected
    result = runner.invoke(app, ["--show-completion", shell], prog_name="nlcx")
    assert result.exit_code == 0, result.output
    assert line in result.output and "_NLCX_COMPLETE" in result.output


def test_completion_completes_a_command() -> None:
    env = {"_NLCX_COMPLETE": "complete_bash", "COMP_WORDS": "nlcx valid", "COMP_CWORD": "1"}
    result = runner.invoke(app, [], prog_name="nlcx", env=env)
    assert result.exit_code == 0 and result.output.split() == ["validate"]

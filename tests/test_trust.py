"""What nlcx guarantees a careless or hostile user: it never deletes what it did not write, never
reads past its inputs, never returns data it cannot vouch for, and answers every bad input
with one line (docs/guide/guarantees.md)."""

from __future__ import annotations

import json
import re
import textwrap
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

import nlcx
from nlcx import manifest, rundir, safe_yaml
from nlcx.cli import app
from nlcx.errors import ConfigError
from nlcx.manifest import IntegrityError

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "x_error_ags.yaml"
SHORT = ["simulation.t_end=1", "outputs.figure=false"]
runner = CliRunner()
#: A Python exception's name, as no message to a user may show it.
EXCEPTION_NAME = re.compile(r"\b[A-Z][A-Za-z]*(Error|Exception)\b|Traceback")


@pytest.fixture
def tmp_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A new directory for each test, with a short name. A one-line error quotes a value of at
    most 80 characters (:mod:`nlcx.errors`) and these tests assert that it quotes a file's whole
    path, so the path must stay short wherever the tests run: pytest's own ``tmp_path`` is
    named after the test, and under pytest-xdist sits one level deeper (``popen-gw0/``)."""
    return tmp_path_factory.mktemp("t")


def one_line(result: object, code: int = 2) -> str:
    """The single stderr line of a refused command (exit ``code``), which names no exception."""
    assert result.exit_code == code, result.output  # type: ignore[attr-defined]
    lines = result.stderr.splitlines()  # type: ignore[attr-defined]
    assert len(lines) == 1, result.stderr  # type: ignore[attr-defined]
    assert not EXCEPTION_NAME.search(lines[0]), lines[0]
    return lines[0]


def tree(directory: Path) -> dict[str, bytes]:
    """Every file under ``directory`` (relative path -> bytes)."""
    return {str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}


def sweep_config(tmp_path: Path, extra: dict[str, object] | None = None, n: int = 4) -> Path:
    """A sweep of ``n`` cart masses of x_error_ags, 1 s long, a batch a variant, without figures."""
    raw = yaml.safe_load(CONFIG.read_text())
    raw.update(name="sw", outputs={"figure": False, "timeseries": False})
    raw["simulation"]["t_end"] = 1.0
    raw["sweep"] = {"grid": {"plant.params.M": [0.9 + 0.1 * k for k in range(n)]}, "batch_size": 1, **(extra or {})}
    path = tmp_path / "sw.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


# ------------------------------------------------------------------ a directory nlcx did not write


@pytest.mark.parametrize(
    "files",
    [
        {"thesis.tex": "draft\n", "sweep.csv": "a,b\n1,2\n"},
        {"thesis.tex": "draft\n", "parts/000000-0123456789.index.csv": "variant\n"},
        {"thesis.tex": "draft\n", "tables/t.csv": "", "claims.csv": ""},
        {"thesis.tex": "draft\n", "manifest.json": json.dumps({"nlcx_output": "run"})},
    ],
    ids=["sweep.csv", "parts", "tables-and-claims", "manifest-without-mark"],
)
def test_a_directory_nlcx_did_not_write_is_never_replaced(tmp_path: Path, files: dict[str, str]) -> None:
    """Whatever names its files have, a directory without nlcx's mark is refused in one line,
    byte for byte as it was, and nothing is left beside it."""
    mine = tmp_path / "mydata"
    for name, text in files.items():
        (mine / name).parent.mkdir(parents=True, exist_ok=True)
        (mine / name).write_text(text)
    before = tree(mine)
    line = one_line(runner.invoke(app, ["run", str(CONFIG), *SHORT, "--out", str(mine)]))
    assert line == f"output error: --out = '{mine}': {rundir.UNMARKED}; allowed: {rundir.ALLOWED}"
    assert tree(mine) == before
    assert [p.name for p in tmp_path.iterdir()] == ["mydata"], "no lock file, no staging directory"


def test_a_marked_directory_holding_a_users_file_is_not_replaced(tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert runner.invoke(app, ["run", str(CONFIG), *SHORT, "--no-report", "--out", str(out)]).exit_code == 0
    (out / "notes.txt").write_text("mine\n")
    before = tree(out)
    line = one_line(runner.invoke(app, ["run", str(CONFIG), *SHORT, "--out", str(out)]))
    assert "holds files nlcx did not write (notes.txt); move them out first" in line
    assert tree(out) == before


def test_report_writes_only_into_a_directory_nlcx_marked(tmp_path: Path) -> None:
    """A directory that looks like a run (metrics.csv, config.yaml) keeps its own report.html."""
    out = tmp_path / "run"
    assert runner.invoke(app, ["run", str(CONFIG), *SHORT, "--no-report", "--out", str(out)]).exit_code == 0
    looks_alike = tmp_path / "copy"
    looks_alike.mkdir()
    for name in ("metrics.csv", "config.yaml"):
        (looks_alike / name).write_bytes((out / name).read_bytes())
    (looks_alike / "report.html").write_text("<p>my page</p>\n")
    line = one_line(runner.invoke(app, ["report", str(looks_alike)]))
    assert line.startswith(f"output error: DIR = '{looks_alike}': is not an output directory nlcx wrote")
    assert (looks_alike / "report.html").read_text() == "<p>my page</p>\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["copy", "run", rundir.lock_path(out).name])


@pytest.mark.parametrize("where", ["cwd", "parent", "home", "root"])
def test_the_working_directory_its_parents_home_and_root_are_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    """Even empty, they are never an output directory, and a refusal leaves no file anywhere."""
    work = tmp_path / "home" / "work"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    target = {"cwd": ".", "parent": "..", "home": str(tmp_path / "home"), "root": "/"}[where]
    root_before = {p.name for p in Path("/").iterdir()}
    line = one_line(runner.invoke(app, ["run", str(CONFIG), *SHORT, "--out", target]))
    assert "which nlcx never writes into" in line
    assert work.is_dir() and not any(work.iterdir())
    assert {p.name for p in (tmp_path / "home").iterdir()} == {"work"}
    assert {p.name for p in Path("/").iterdir()} == root_before


# ------------------------------------------------------------------ configs that cannot exhaust the machine

BOMB = "vars:\n  a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"  a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 9)}]\n" for k in range(1, 9)
)


def test_an_alias_bomb_is_refused_by_validate_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "bomb.yaml"
    path.write_text(BOMB)
    assert len(BOMB) < 512
    line = one_line(runner.invoke(app, ["validate", str(path)]))
    assert line == (
        f"config error: <config> = '{path}': more than {safe_yaml.MAX_NODES:,} values (aliases expanded); "
        f"allowed: at most {safe_yaml.MAX_NODES:,}"
    )


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("a: " + "[" * 500 + "]" * 500 + "\n", f"nested deeper than {safe_yaml.MAX_DEPTH} levels"),
        ("title: x\n" + "# padding\n" * 600_000, "bytes; allowed: a YAML file of at most"),
        ('name: a\ntitle: "\\ud800"\n', "lone surrogate"),
    ],
    ids=["nested-500-deep", "over-5-MB", "lone-surrogate"],
)
def test_the_yaml_limits_name_the_file(tmp_path: Path, text: str, problem: str) -> None:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    line = one_line(runner.invoke(app, ["validate", str(path)]))
    assert line.startswith(f"config error: <config> = '{path}': ") and problem in line


def test_bytes_that_are_not_utf8_are_refused_naming_the_file(tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    path.write_bytes(b"name: caf\xe9\n")
    line = one_line(runner.invoke(app, ["validate", str(path)]))
    assert line == f"config error: <config> = '{path}': not UTF-8 text (byte 0xe9 at offset 9)"


def test_a_run_directorys_config_cannot_blow_up_its_report(tmp_path: Path) -> None:
    """A config.yaml holding an alias bomb, recorded in the manifest as if nlcx had written it:
    the report refuses it in one line instead of writing a page of megabytes."""
    out = tmp_path / "run"
    assert runner.invoke(app, ["run", str(CONFIG), *SHORT, "--no-report", "--out", str(out)]).exit_code == 0
    (out / "config.yaml").write_text(BOMB + "name: x\n")
    manifest.update(out, ["config.yaml"])
    line = one_line(runner.invoke(app, ["report", str(out)]), code=1)
    assert "aliases expanded" in line and "report.html not written" in line
    assert not (out / "report.html").exists()
    assert manifest.load(out)["report"]["status"] == "failed"


# ------------------------------------------------------------------ nothing of the process reaches an output


def test_an_environment_variable_reaches_no_output_unless_allowed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    secret = "hunter2-" + "x" * 8
    monkeypatch.setenv("MY_SECRET", secret)
    override = "title=${oc.env:MY_SECRET,none}"
    out = tmp_path / "run"
    line = one_line(runner.invoke(app, ["run", str(CONFIG), *SHORT, override, "--out", str(out)]))
    assert "calls the resolver oc.env, which is off" in line and "--allow-env" in line and secret not in line
    assert not out.exists()
    one_line(runner.invoke(app, ["validate", str(CONFIG), override]))
    with pytest.raises(ConfigError, match=r"oc\.env, which is off"):
        nlcx.run(CONFIG, [*SHORT, override])
    allowed = runner.invoke(app, ["run", str(CONFIG), *SHORT, override, "--allow-env", "--out", str(out)])
    assert allowed.exit_code == 0, allowed.output
    assert yaml.safe_load((out / "config.yaml").read_text())["title"] == secret
    assert manifest.load(out)["allow_env"] is True


def test_extends_names_yaml_files_only_and_errors_quote_no_file(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x:0:0:root:/root:/bin/bash\n")
    child = tmp_path / "child.yaml"
    child.write_text(f"extends: {secret}\nname: c\n")
    line = one_line(runner.invoke(app, ["validate", str(child)]))
    assert "a YAML file (.yaml or .yml)" in line and "root:x" not in line
    for text in ("token: 'hunter2\n", "hunter2 secret line\n", "- 'hunter2'\n- 1\n"):
        other = tmp_path / "other.yaml"
        other.write_text(text)
        child.write_text("extends: other.yaml\nname: c\n")
        line = one_line(runner.invoke(app, ["validate", str(child)]))
        assert "hunter2" not in line and str(other) in line


# ------------------------------------------------------------------ integrity on read


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run") / "run"
    nlcx.run(CONFIG, SHORT, out=out)
    return out


def _copy(source: Path, target: Path) -> Path:
    import shutil

    return Path(shutil.copytree(source, target))


@pytest.mark.parametrize("name", ["metrics.csv", "timeseries.csv", "config.yaml"])
def test_load_run_refuses_a_truncated_file_naming_it(saved_run: Path, tmp_path: Path, name: str) -> None:
    """Cut mid-line, the file is refused; nothing of it is read in part."""
    out = _copy(saved_run, tmp_path / "run")
    data = (out / name).read_bytes()
    (out / name).write_bytes(data[: len(data) // 2 + 7])
    with pytest.raises(IntegrityError) as info:
        nlcx.load_run(out)
    assert str(info.value).startswith(f"integrity error: {out / name}: ")
    assert "truncated or altered" in str(info.value) and "\n" not in str(info.value)


def test_a_deleted_time_series_and_a_disabled_one_say_different_things(saved_run: Path, tmp_path: Path) -> None:
    out = _copy(saved_run, tmp_path / "run")
    (out / "timeseries.csv").unlink()
    with pytest.raises(IntegrityError, match=r"timeseries.csv: missing: .*its manifest lists it"):
        nlcx.load_run(out)
    nlcx.run(CONFIG, [*SHORT, "outputs.timeseries=false"], out=tmp_path / "none")
    with pytest.raises(ConfigError, match=r"written without time series \(outputs.timeseries: false\)"):
        nlcx.load_run(tmp_path / "none").trajectory("proposed")


def test_a_manifest_with_wrong_types_is_one_line(saved_run: Path, tmp_path: Path) -> None:
    for broken, where in (
        ({"runs": [{"controller": 3}]}, "runs.0.controller"),
        ({"checksums": {"metrics.csv": {"sha256": "x", "bytes": -1}}}, "checksums.metrics.csv.sha256"),
        ({"runs": "all"}, "runs"),
    ):
        out = _copy(saved_run, tmp_path / where)
        record = json.loads((out / "manifest.json").read_text())
        (out / "manifest.json").write_text(json.dumps({**record, **broken}))
        with pytest.raises(IntegrityError) as info:
            nlcx.load_run(out)
        message = str(info.value)
        assert message.startswith(f"integrity error: {out / 'manifest.json'}: {where}") and "\n" not in message
        assert not EXCEPTION_NAME.search(message)


def _interrupted_sweep(tmp_path: Path) -> tuple[Path, Path]:
    """A sweep of four variants stopped after its second batch: (its config, its target)."""
    from nlcx import sweeps

    config, out = sweep_config(tmp_path), tmp_path / "out"

    def stop(done: int, total: int, failed: int) -> None:
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweeps.run(config, out_dir=out, executor="serial", progress=stop, with_report=False)
    assert len(list((rundir.partial_dir(out) / "parts").glob("*.sums.json"))) == 2
    return config, out


def test_a_truncated_part_is_refused_on_resume_naming_it(tmp_path: Path) -> None:
    config, out = _interrupted_sweep(tmp_path)
    part = sorted((rundir.partial_dir(out) / "parts").glob("*.metrics.*"))[0]
    part.write_bytes(part.read_bytes()[:-40])
    line = one_line(runner.invoke(app, ["sweep", str(config), "--executor", "serial", "--out", str(out)]))
    assert line.startswith(f"integrity error: {part}: ") and "--force" in line
    assert not out.exists()
    forced = runner.invoke(app, ["sweep", str(config), "--executor", "serial", "--force", "--out", str(out)])
    assert forced.exit_code == 0, forced.output
    assert len(nlcx.results.read_output_table(out, "sweep")) == 4


def test_a_resumed_sweep_equals_one_run_in_one_go(tmp_path: Path) -> None:
    config, out = _interrupted_sweep(tmp_path)
    resumed = runner.invoke(app, ["sweep", str(config), "--executor", "serial", "--out", str(out)])
    assert resumed.exit_code == 0 and "2 computed, 2 already done" in resumed.output, resumed.output
    alone = tmp_path / "alone"
    assert runner.invoke(app, ["sweep", str(config), "--executor", "serial", "--out", str(alone)]).exit_code == 0
    for stem in ("metrics", "sweep"):
        pd.testing.assert_frame_equal(
            nlcx.results.read_output_table(out, stem), nlcx.results.read_output_table(alone, stem), check_exact=True
        )
    manifest.verify(out)  # every file as its manifest lists it, the parts' seals included


# ------------------------------------------------------------------ results first, pages second


def test_a_sweep_whose_runs_are_all_unstable_writes_its_results_and_says_so(tmp_path: Path) -> None:
    config = sweep_config(tmp_path, n=2)
    out = tmp_path / "out"
    result = runner.invoke(app, ["sweep", str(config), "simulation.bounds.theta=1e-9", "--executor", "serial",
                                 "--out", str(out)])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "unstable 2" in result.output
    assert {"manifest.json", "config.yaml", "sweep.parquet", "metrics.parquet", "report.html"} <= {
        p.name for p in out.iterdir()
    }
    assert set(nlcx.results.read_output_table(out, "sweep").status) == {"unstable"}
    assert "No usable metric: every variant failed or was unstable" in (out / "report.html").read_text()
    assert manifest.load(out)["report"] == {"status": "ok"}


def test_a_sweep_whose_variants_all_fail_keeps_its_directory(tmp_path: Path) -> None:
    """Failed variants are results too: the directory, its manifest and tables are written (the
    command exits 1, as for any failed variant, and lists them)."""
    config = sweep_config(tmp_path, {"grid": {"plant.params.g": [-9.8, -1.0]}})
    out = tmp_path / "out"
    result = runner.invoke(app, ["sweep", str(config), "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 1 and "failed 2" in result.output
    assert not EXCEPTION_NAME.search(result.output)
    assert set(nlcx.results.read_output_table(out, "sweep").status) == {"failed"}
    assert "No usable metric" in (out / "report.md").read_text()
    manifest.verify(out)


def test_a_report_that_fails_leaves_the_results_and_records_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def fail(directory: Path, configs: Path | None = None) -> None:
        raise RuntimeError("the template broke")

    monkeypatch.setattr("nlcx.pages.render.write_report", fail)
    out = tmp_path / "run"
    line = one_line(runner.invoke(app, ["run", str(CONFIG), *SHORT, "--out", str(out)]), code=1)
    assert line.startswith(f"report error: {out}/report.html not written: an internal error of the report")
    assert "the results are complete" in line
    again = nlcx.load_run(out)  # every table is there, and verifies
    assert set(again.controllers) == {"conventional", "proposed"}
    assert manifest.load(out)["report"]["status"] == "failed"
    assert "the template broke" in manifest.load(out)["report"]["error"]


# ------------------------------------------------------------------ bounded work and one line for each bad number


@pytest.mark.parametrize(
    ("args", "start"),
    [
        (["validate", str(CONFIG), "simulation.t_end=inf"], "config error: simulation.t_end = 'inf': must be a finite"),
        (["run", str(CONFIG), "simulation.t_end=.inf"], "config error: simulation.t_end = inf: must be a finite"),
        (["run", str(CONFIG), "simulation.dt=.nan"], "config error: simulation.dt = nan: must be a finite"),
        (["run", str(CONFIG), "plant.params.M=.nan"], "config error: plant.params.M = nan: must be a finite"),
        (["run", str(CONFIG), "reference.x.time=30"], "config error: reference.x.time = 30.0: too late to measure"),
        (["run", str(CONFIG), 'title="\\ud800"'], "config error: title = "),
        (["run", str(CONFIG), "vars.x=" + "[" * 300 + "]" * 300], "config error: vars.x = "),
        (["sweep", str(ROOT / "configs/sweeps/robustness.yaml"), "--jobs", "0"], "config error: --jobs = 0: "),
        (["sweep", str(ROOT / "configs/sweeps/robustness.yaml"), "--jobs", "10000"], "config error: --jobs = 10000: "),
        (["reproduce", "--only", "table-2.3", "--jobs", "-1"], "config error: --jobs = -1: "),
        (["linearize", str(CONFIG), "--along", "e", "--points", "1000000000"], "config error: --points = 1000000000"),
    ],
    ids=[
        "t_end-inf-validate",
        "t_end-inf",
        "dt-nan",
        "param-nan",
        "step-after-t_end",
        "surrogate",
        "deep-override",
        "jobs-0",
        "jobs-10000",
        "jobs-negative",
        "points",
    ],
)
def test_every_bad_number_is_one_line_before_any_work(tmp_path: Path, args: list[str], start: str) -> None:
    out = tmp_path / "out"
    extra = ["--out", str(out)] if args[0] in ("run", "sweep", "reproduce", "linearize") else []
    line = one_line(runner.invoke(app, [*args, *extra]))
    assert line.startswith(start), line
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == [], "refused before any work"


def test_jobs_past_the_limit_are_refused_in_python_too() -> None:
    with pytest.raises(ConfigError, match=r"jobs = 0: worker processes; allowed: an integer from 1 to 256"):
        nlcx.sweep(ROOT / "configs/sweeps/robustness.yaml", jobs=0)


def test_an_unexpected_failure_is_one_line_without_pythons_name(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(*args: object, **kwargs: object) -> None:
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr("nlcx.config.load", broken)
    line = one_line(runner.invoke(app, ["validate", str(CONFIG)]), code=1)
    assert line == "internal error: float division by zero (a defect of nlcx; set NLCX_DEBUG=1 for a traceback)"


# ------------------------------------------------------------------ text to a terminal


ESCAPE = "\x1b]0;owned\x07\x1b[31m"


def test_metrics_and_diff_show_control_characters_escaped(tmp_path: Path) -> None:
    import numpy as np

    t = np.linspace(0.0, 10.0, 1001)
    y = 1.0 - np.exp(-t)
    pd.DataFrame({"t": t, f"y{ESCAPE}": y}).to_csv(tmp_path / "a.csv", index=False)
    pd.DataFrame({"t": t, f"y{ESCAPE}": y * 1.1}).to_csv(tmp_path / "b.csv", index=False)
    for args, code in (
        (["metrics", str(tmp_path / "a.csv"), "--time", "t", "--reference", "1"], 0),
        (["diff", str(tmp_path / "a.csv"), str(tmp_path / "b.csv")], 1),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == code, result.output
        assert "\x1b" not in result.output and "\x07" not in result.output
        assert "\\x1b]0;owned\\x07" in result.output


def test_printable_escapes_what_a_terminal_obeys() -> None:
    from nlcx.terminal import printable

    assert printable("a\x1b[2Jb\u202ec\x9bd\ud800e\tf\ng") == "a\\x1b[2Jb\\u202ec\\x9bd\\ud800e\tf\ng"


# ------------------------------------------------------------------ litter


def test_a_refused_target_leaves_nothing_beside_it(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "keep.txt").write_text("keep\n")
    config = sweep_config(tmp_path)
    for args in (
        ["run", str(CONFIG), *SHORT],
        ["sweep", str(config), "--executor", "serial"],
        ["reproduce", "--only", "table-2.3"],
        ["linearize", str(CONFIG)],
    ):
        one_line(runner.invoke(app, [*args, "--out", str(mine)]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "sw.yaml"]


def test_the_guarantees_page_states_what_nlcx_overwrites_refuses_and_verifies() -> None:
    text = (ROOT / "docs" / "guide" / "guarantees.md").read_text()
    for promise in ("overwrites", "refuses", "verifies", "--allow-env", "5 MB", "100 000", str(safe_yaml.MAX_DEPTH)):
        assert promise in text, promise
    assert textwrap.dedent(text).count("\n## ") >= 4

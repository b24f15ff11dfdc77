"""Output directories written whole: staged, replaced whole, refused when not nlcx's, locked,
and their manifests' record of how, when and where they were made."""

from __future__ import annotations

import json
import os
import platform
import socket
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

import nlcx
from nlcx import atomic_install, config, engine, rundir
from nlcx import manifest as manifests
from nlcx.cli import app
from nlcx.results import read_output_table

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "x_error_ags.yaml"
NLCX = [sys.executable, "-m", "nlcx.cli"]
REFUSED = f"{rundir.UNMARKED}; allowed: {rundir.ALLOWED}"
runner = CliRunner()


def snapshot(directory: Path) -> dict[str, bytes]:
    """Every file under ``directory`` (relative path -> bytes)."""
    return {str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}


def siblings(directory: Path) -> set[str]:
    """The names beside ``directory`` in its parent, itself left out."""
    return {p.name for p in directory.parent.iterdir()} - {directory.name}


def write_sweep(tmp_path: Path, n: int = 4) -> Path:
    """A sweep of ``n`` random cart masses of x_error_ags, 2 s long, one variant a batch."""
    raw = yaml.safe_load(CONFIG.read_text())
    raw.update(name="sw", outputs={"figure": False, "timeseries": False})
    raw["simulation"]["t_end"] = 2.0
    raw["sweep"] = {"random": {"n": n, "params": {"plant.params.M": {"dist": "uniform", "relative": 0.2}}}}
    raw["sweep"]["batch_size"] = 1
    path = tmp_path / "sw.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def test_a_rerun_replaces_the_run_directory_whole(tmp_path: Path) -> None:
    """A short run without time series, figure or report into the directory of a full run
    leaves only its own files: nothing of the first run beside the second's config."""
    out = tmp_path / "D"
    assert runner.invoke(app, ["run", str(CONFIG), "--out", str(out)]).exit_code == 0
    assert {"timeseries.csv", "figure.png", "report.html", "report.md"} <= {p.name for p in out.iterdir()}
    args = ["simulation.t_end=5", "outputs.timeseries=false", "outputs.figure=false", "--no-report"]
    second = runner.invoke(app, ["run", str(CONFIG), *args, "--out", str(out)])
    assert second.exit_code == 0, second.output
    assert {p.name for p in out.iterdir()} == {"config.yaml", "metrics.csv", "manifest.json", ".nlcx-output"}
    assert yaml.safe_load((out / "config.yaml").read_text())["simulation"]["t_end"] == 5
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["files"] == ["config.yaml", "metrics.csv"] and manifest["nlcx_output"] == "run"
    assert siblings(out) == {rundir.lock_path(out).name}, "no staged or set-aside directory is left behind"


@pytest.mark.parametrize("exchange", [True, False], ids=["names-exchanged", "renamed-aside-and-in"])
def test_the_new_directory_replaces_the_old_one_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exchange: bool
) -> None:
    """Both ways of replacing (one exchange of names, or two renames) leave the new files only,
    and nothing beside the target but its lock file."""
    out = tmp_path / "D"
    with rundir.staged(out) as stage:
        (stage / "old.csv").write_text("old\n")
        (stage / "sub").mkdir()
        (stage / "sub" / "old.txt").write_text("old\n")
        manifests.write(stage, {rundir.MARKER: "run"})
    calls: list[bool] = []
    real_exchange = atomic_install._exchange
    monkeypatch.setattr(
        atomic_install, "_exchange", lambda a, b: calls.append(exchange) or (exchange and real_exchange(a, b))
    )
    with rundir.staged(out) as stage:
        assert stage.parent == out.parent and stage.name.startswith(".D.nlcx-tmp-")
        (stage / "new.csv").write_text("new\n")
        written = manifests.write(stage, {rundir.MARKER: "run", "second": True})
        assert snapshot(out)["old.csv"] == b"old\n", "the old directory stays until the new one is complete"
    assert calls == [exchange]
    assert set(snapshot(out)) == {"manifest.json", ".nlcx-output", "new.csv"}
    assert json.loads((out / "manifest.json").read_text()) == written and written["second"] is True
    assert siblings(out) == {rundir.lock_path(out).name}


@pytest.mark.parametrize("interruption", [KeyboardInterrupt, SystemExit])
def test_an_interrupted_write_leaves_the_old_directory_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, interruption: type[BaseException]
) -> None:
    """A run interrupted while it writes its report (the last file) installs nothing: the old
    directory is byte for byte what it was, and the staged one is gone."""
    out = tmp_path / "D"
    result = engine.run_experiment(config.load(CONFIG, ["simulation.t_end=1"]))
    rundir.save_run(result, out, with_report=False)
    before = snapshot(out)

    def fail(directory: Path, configs: Path | None = None) -> None:
        assert (directory / "manifest.json").is_file(), "the report comes after every other file"
        raise interruption("stopped")

    monkeypatch.setattr("nlcx.pages.render.write_report", fail)
    with pytest.raises(interruption, match="stopped"):
        rundir.save_run(result, out)
    assert snapshot(out) == before
    assert siblings(out) == {rundir.lock_path(out).name}


def test_a_directory_nlcx_did_not_write_is_refused_in_one_line(tmp_path: Path) -> None:
    """run, sweep and reproduce refuse a non-empty directory without an nlcx manifest, and a
    file, before computing anything; an empty directory is taken."""
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me\n")
    (tmp_path / "file").write_text("a file\n")
    commands = (
        ["run", str(CONFIG)],
        ["sweep", str(write_sweep(tmp_path))],
        ["reproduce", "--only", "table-2.3", "--configs", str(ROOT / "configs" / "thesis")],
    )
    for target, problem in (
        (foreign, REFUSED),
        (tmp_path / "file", f"exists and is not a directory; allowed: {rundir.ALLOWED}"),
    ):
        for command in commands:
            result = runner.invoke(app, [*command, "--out", str(target)])
            assert result.exit_code == 2, result.output
            assert result.stderr.splitlines() == [f"output error: --out = '{target}': {problem}"]
    assert snapshot(foreign) == {"notes.txt": b"keep me\n"} and (tmp_path / "file").read_text() == "a file\n"
    assert not [p for p in tmp_path.iterdir() if ".nlcx-" in p.name], "a refused target leaves nothing beside it"
    empty = tmp_path / "empty"
    empty.mkdir()
    result = runner.invoke(app, ["run", str(CONFIG), "simulation.t_end=1", "--no-report", "--out", str(empty)])
    assert result.exit_code == 0, result.output
    assert {p.name for p in empty.iterdir()} == {
        ".nlcx-output",
        "config.yaml",
        "metrics.csv",
        "timeseries.csv",
        "figure.png",
        "manifest.json",
    }


def _marked(directory: Path, kind: str = "sweep") -> Path:
    """``directory`` written as nlcx writes an output: a file, then its manifest and mark."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "sweep.csv").write_text("variant\n0\n")
    manifests.write(directory, {rundir.MARKER: kind})
    return directory


def _copied_manifest(directory: Path) -> None:
    """A manifest copied in from a marked directory, whose mark file stays behind."""
    source = _marked(directory.parent / "source")
    directory.mkdir()
    (directory / "manifest.json").write_bytes((source / "manifest.json").read_bytes())


def _other_id(directory: Path) -> None:
    """A marked directory whose mark file names another id than its manifest."""
    _marked(directory)
    (directory / manifests.MARK).write_text(json.dumps({rundir.MARKER: "sweep", manifests.ID_KEY: "0" * 32}))


def _named_like_ours(files: dict[str, str]) -> Callable[[Path], None]:
    def make(directory: Path) -> None:
        directory.mkdir()
        for name, text in files.items():
            (directory / name).parent.mkdir(parents=True, exist_ok=True)
            (directory / name).write_text(text)

    return make


@pytest.mark.parametrize(
    ("make", "ours"),
    [
        (_marked, True),
        (lambda d: _marked(d, "identification"), True),
        (_copied_manifest, False),  # the manifest without its directory's mark
        (_other_id, False),
        (_named_like_ours({"manifest.json": json.dumps({rundir.MARKER: "sweep"})}), False),  # no id, no mark
        (_named_like_ours({"manifest.json": json.dumps({"name": "x", "versions": {"nlcx": "0.1.0"}})}), False),
        (_named_like_ours({"parts/000000-0123456789.index.csv": "variant\n", "parts/x.metrics.csv": ""}), False),
        (_named_like_ours({"sweep.csv": "variant\n"}), False),
        (_named_like_ours({"sweep.parquet/part-000000000.parquet": ""}), False),
        (_named_like_ours({"tables/table_2_3.csv": "", "claims.csv": ""}), False),
        (_named_like_ours({"manifest.json": "[1, 2]", manifests.MARK: "{}"}), False),
    ],
    ids=[
        "marked",
        "marked-in-place",
        "copied-manifest",
        "other-id",
        "marker-without-id",
        "old-manifest",
        "old-sweep-parts",
        "sweep-csv",
        "sweep-parquet",
        "reproduction-files",
        "not-an-object",
    ],
)
def test_which_directories_nlcx_wrote(tmp_path: Path, make: Callable[[Path], object], ours: bool) -> None:
    """Only the mark makes a directory nlcx's: its manifest and its mark file name the same
    random id; file names prove nothing (an output of an older nlcx is refused: removed by hand)."""
    directory = tmp_path / "d"
    make(directory)
    assert rundir.written_by_nlcx(directory) is ours
    if ours:
        rundir.check_target(directory)
    else:
        with pytest.raises(rundir.OutputError, match="carries no nlcx mark"):
            rundir.check_target(directory)


def test_a_killed_writers_leftovers_are_removed_by_the_next_writer(tmp_path: Path) -> None:
    """Staged and set-aside directories of the target go; a name that only begins like them
    (another target's) stays."""
    out = tmp_path / "D"
    for name in (".D.nlcx-tmp-0123abcd", ".D.nlcx-old-89abcdef", ".D.nlcx-tmp-x.nlcx-tmp-0123abcd"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "metrics.csv").write_text("stale\n")
    with rundir.staged(out) as stage:
        (stage / "manifest.json").write_text("{}")
    assert siblings(out) == {rundir.lock_path(out).name, ".D.nlcx-tmp-x.nlcx-tmp-0123abcd"}


def test_the_lock_nests_within_a_process_and_records_its_holder(tmp_path: Path) -> None:
    out = tmp_path / "D"
    assert rundir.lock_owner(out) is None
    with rundir.locked(out):
        with rundir.locked(out):
            assert rundir.lock_owner(out)["pid"] == os.getpid()
        assert rundir.lock_owner(out)["pid"] == os.getpid(), "the inner block leaves the lock to the outer one"
    assert rundir.lock_owner(out) is None


HOLDER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from nlcx import sweeps as sweep

    config, out, ready, go = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]), Path(sys.argv[4])

    def progress(done, total, failed):  # after the first batch: wait, holding the directory
        if done and not go.exists():
            ready.touch()
            while not go.exists():
                time.sleep(0.01)

    sweep.run(config, out_dir=out, executor="serial", progress=progress, with_report=False)
    """
)


def _wait_for(path: Path, process: subprocess.Popen[bytes]) -> None:
    """Until ``path`` exists (``process`` still running)."""
    deadline = time.monotonic() + 120
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, f"{path} did not appear"
        time.sleep(0.01)


@pytest.mark.slow
def test_a_second_writer_is_refused_while_the_first_writes(tmp_path: Path) -> None:
    """A sweep stops after its first batch, holding its directory; another sweep of the same
    directory with --force, and a run into it, exit 2 with one line naming the holder, and
    delete nothing of its parts; the first sweep then completes, its metrics those of the
    same sweep run alone."""
    path = write_sweep(tmp_path)
    out, ready, go = tmp_path / "out", tmp_path / "ready", tmp_path / "go"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(path), str(out), str(ready), str(go)], stderr=subprocess.PIPE
    )
    try:
        _wait_for(ready, holder)
        parts = rundir.partial_dir(out) / "parts"
        written = snapshot(parts)
        assert written, "the first batch's parts are in the staging directory"
        for command in (["sweep", str(path), "--force", "--executor", "serial"], ["run", str(CONFIG)]):
            second = subprocess.run([*NLCX, *command, "--out", str(out)], capture_output=True, text=True)
            assert second.returncode == 2, second.stderr
            (line,) = second.stderr.splitlines()
            owner = rundir.lock_owner(out)
            assert line == (
                f"output error: --out = '{out}': being written by another nlcx process "
                f"(pid {holder.pid}, since {owner['since']}); allowed: wait for it to finish, or choose another --out"
            )
        assert snapshot(parts) == written
        assert not out.exists()
    finally:
        go.touch()
        _, errors = holder.communicate(timeout=300)
    assert holder.returncode == 0, errors
    manifest = json.loads((out / "manifest.json").read_text())
    assert (manifest["variants"], manifest["computed"], manifest["nlcx_output"]) == (4, 4, "sweep")
    assert manifest["argv"] == ["-c", str(path), str(out), str(ready), str(go)] and manifest["overrides"] == []
    alone = tmp_path / "alone"
    assert runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(alone)]).exit_code == 0
    for stem in ("metrics", "sweep"):
        pd.testing.assert_frame_equal(read_output_table(out, stem), read_output_table(alone, stem), check_exact=True)
    assert list(read_output_table(out, "sweep").variant) == [0, 1, 2, 3]
    assert rundir.lock_owner(out) is None and not rundir.partial_dir(out).exists()


def test_a_run_manifest_records_how_when_and_where(tmp_path: Path) -> None:
    out = tmp_path / "D"
    command = ["run", str(CONFIG), "simulation.t_end=1", "outputs.figure=false", "--no-report", "--out", str(out)]
    before = time.time()
    subprocess.run([*NLCX, *command], check=True, capture_output=True)
    after = time.time()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["argv"][1:] == command and Path(manifest["argv"][0]).parts[-2:] == ("cli", "__main__.py")
    assert manifest["overrides"] == ["simulation.t_end=1", "outputs.figure=false"]
    started = datetime.fromisoformat(manifest["started"])
    assert started.utcoffset().total_seconds() == 0
    assert before <= started.timestamp() <= started.timestamp() + manifest["duration_s"] <= after
    assert manifest["duration_s"] > 0
    assert manifest["host"] == socket.gethostname() and manifest["platform"] == platform.platform()
    assert manifest["versions"]["nlcx"] == nlcx.__version__ and "commit" in manifest["git"]
    assert manifest["nlcx_output"] == "run"


def test_save_run_writes_what_nlcx_run_writes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The library's save_run and the command write the same files, bytes for the data; the
    command goes through save_run; a run made from Python records its process's argv."""
    overrides = ["simulation.t_end=2", "outputs.gains_figure=true"]
    result = engine.run_experiment(config.load(CONFIG, overrides))
    saved = rundir.save_run(result, tmp_path / "api", overrides=overrides)
    assert saved == tmp_path / "api"
    calls: list[Path] = []
    save_run = rundir.save_run
    monkeypatch.setattr(rundir, "save_run", lambda result, out, **kw: calls.append(out) or save_run(result, out, **kw))
    command = runner.invoke(app, ["run", str(CONFIG), *overrides, "--out", str(tmp_path / "cli")])
    assert command.exit_code == 0, command.output
    assert calls == [tmp_path / "cli"]
    names = {"config.yaml", "metrics.csv", "timeseries.csv", "figure.png", "gains.png", "manifest.json", ".nlcx-output"}
    for out in (tmp_path / "api", tmp_path / "cli"):
        assert {p.name for p in out.iterdir()} == names | {"report.html", "report.md"}
    for name in ("config.yaml", "metrics.csv", "timeseries.csv"):
        assert (tmp_path / "api" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()
    manifest = json.loads((tmp_path / "api" / "manifest.json").read_text())
    assert manifest["argv"] == sys.argv and manifest["overrides"] == overrides
    assert manifest["files"] == ["config.yaml", "metrics.csv", "timeseries.csv", "figure.png", "gains.png"]

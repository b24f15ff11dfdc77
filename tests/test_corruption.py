"""Corrupted output directories: every reader refuses what it cannot vouch for, in one line naming it.

Built once for the module: a run directory (``nlcx run`` of ``configs/x_error_ags.yaml``, 1 s,
with its figure and report), two finished sweeps of four cart masses, a batch a variant (one
run variant by variant with time series, its parts CSV; one run from columns, its parts
Parquet), and the staging directory of each of those sweeps interrupted after its second
batch (``.<name>.nlcx-partial``).

Every file a finished directory's manifest lists, and every file a partial sweep's seals list,
is damaged in a copy of its directory: cut in half, or one bit flipped in its middle. Manifests
that do not parse and seals that do not parse (or whose entries have the wrong types) are
damaged the same way. Then each reader that reads the file must refuse it with one line naming
it, and change nothing:

- ``nlcx.load_run`` (:class:`~nlcx.manifest.IntegrityError`): the run's ``config.yaml``,
  ``metrics.csv``, time series and manifest;
- ``nlcx report DIR`` (exit 2): every file but the pages it rewrites (``report.html``,
  ``report.md``, ``summary.csv``, ``profiles.csv``, ``report_summary.csv``, ``report_files/``),
  and the manifest;
- ``nlcx diff`` (exit 2), the damaged directory on either side: every table (CSV or Parquet)
  and the manifest;
- a resumed sweep (``nlcx sweep CONFIG --out OUT``, exit 2): every sealed part file and seal,
  in a partial directory and in a finished sweep's, and a finished sweep's manifest.

Each file's slot in a directory is named by a glob pattern and an index (``parts/*.index.csv#2``:
the third part's index); a test checks that the slots cover every file the manifest or the
seals list, and nothing else. The number of cases each reader was tried on is printed at the
end of the module.
"""

from __future__ import annotations

import json
import shutil
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from _hostile import CONFIG, EXCEPTION_NAME, files_under, one_line
from typer.testing import CliRunner

import nlcx
from nlcx import manifest, rundir, sweeps
from nlcx.cli import app
from nlcx.manifest import IntegrityError
from nlcx.pages.writing import is_page
from nlcx.sweeps import seals

runner = CliRunner()

#: The files of each finished directory, by slot: a glob pattern and how many files it matches.
LAYOUTS: dict[str, dict[str, int]] = {
    "run": {
        "config.yaml": 1,
        "figure.png": 1,
        "metrics.csv": 1,
        "timeseries.csv": 1,
        "report.html": 1,
        "report.md": 1,
    },
    "sweep": {
        "config.yaml": 1,
        "sweep.parquet/*.parquet": 1,
        "metrics.parquet/*.parquet": 1,
        "parts/*.index.csv": 4,
        "parts/*.metrics.csv": 4,
        "parts/*.sums.json": 4,
        "timeseries/*.csv": 4,
        "summary.csv": 1,
        "profiles.csv": 1,
        "report.html": 1,
        "report.md": 1,
        "report_files/*.svg": 2,
    },
    "columnar": {
        "config.yaml": 1,
        "sweep.parquet/*.parquet": 4,
        "metrics.parquet/*.parquet": 4,
        "parts/*.index.parquet": 4,
        "parts/*.metrics.parquet": 4,
        "parts/*.sums.json": 4,
        "summary.csv": 1,
        "profiles.csv": 1,
        "report.html": 1,
        "report.md": 1,
        "report_files/*.svg": 2,
    },
}
#: The files the seals of each partial sweep (two batches done) list, by slot.
SEALED: dict[str, dict[str, int]] = {
    "sweep": {"parts/*.index.csv": 2, "parts/*.metrics.csv": 2, "timeseries/*.csv": 2},
    "columnar": {"parts/*.index.parquet": 2, "parts/*.metrics.parquet": 2},
}
#: The seals of each partial sweep, by slot.
SEALS: dict[str, dict[str, int]] = {"sweep": {"parts/*.sums.json": 2}, "columnar": {"parts/*.sums.json": 2}}


def _cut(data: bytes) -> bytes:
    return data[: len(data) // 2]


def _flip(data: bytes) -> bytes:
    middle = len(data) // 2
    return data[:middle] + bytes([data[middle] ^ 0x01]) + data[middle + 1 :]


#: Damage done to a file: its bytes -> the damaged bytes.
DAMAGES: dict[str, Callable[[bytes], bytes]] = {"cut-in-half": _cut, "bit-flipped": _flip}
#: Manifests that do not parse, or are not a manifest.
MANIFEST_DAMAGES: dict[str, Callable[[bytes], bytes]] = {
    "cut-in-half": _cut,
    "not-utf8": lambda data: b"\xff\xfe" + data,
    "a-list": lambda data: b"[]\n",
    "empty": lambda data: b"",
    "wrong-types": lambda data: json.dumps({**json.loads(data), "checksums": "all"}).encode(),
}
#: Seals that do not parse, are not a seal, or whose entries have the wrong types; or cut, or altered.
SEAL_DAMAGES: dict[str, Callable[[bytes], bytes]] = {
    **DAMAGES,
    "not-json": lambda data: b"\x00 not json",
    "a-list": lambda data: b"[]\n",
    "files-a-list": lambda data: json.dumps({**json.loads(data), "files": [1, 2]}).encode(),
    "wrong-types": lambda data: json.dumps(
        {**json.loads(data), "files": {rel: {"sha256": 1, "bytes": "x"} for rel in json.loads(data)["files"]}}
    ).encode(),
}
#: Cases tried, by reader.
TRIED: Counter[str] = Counter()


def slots(layout: dict[str, int], keep: Callable[[str], bool] = lambda pattern: True) -> list[str]:
    """``pattern#index`` for every file of ``layout`` whose pattern ``keep`` keeps."""
    return [f"{pattern}#{k}" for pattern, count in layout.items() if keep(pattern) for k in range(count)]


def resolve(directory: Path, slot: str) -> Path:
    """The file a slot names in ``directory``: the index-th match of its pattern, in path order."""
    pattern, _, index = slot.rpartition("#")
    return sorted(directory.glob(pattern))[int(index)]


def is_table(pattern: str) -> bool:
    return pattern.endswith((".csv", ".parquet"))


def is_part(pattern: str) -> bool:
    return pattern.startswith(("parts/", "timeseries/"))


def damages_for(slot: str) -> dict[str, Callable[[bytes], bytes]]:
    """The damages tried on the file of ``slot``: a seal's (:data:`SEAL_DAMAGES`) or any file's."""
    return SEAL_DAMAGES if slot.rpartition("#")[0].endswith(seals.SEAL) else DAMAGES


def tree(directory: Path) -> dict[str, bytes]:
    """Every file under ``directory`` (relative path -> bytes), hidden ones included."""
    return {path.relative_to(directory).as_posix(): path.read_bytes() for path in files_under(directory)}


def damage(path: Path, how: Callable[[bytes], bytes]) -> Path:
    """Damage the file at ``path`` in place (it must change); ``path``."""
    before = path.read_bytes()
    after = how(before)
    assert after != before, path
    path.write_bytes(after)
    return path


def names(line: str, path: Path) -> None:
    """``line`` is one line, names no Python exception, and names ``path``."""
    assert "\n" not in line and not EXCEPTION_NAME.search(line), line
    assert str(path) in line, (line, path)


@pytest.fixture(scope="module", autouse=True)
def summary(request: pytest.FixtureRequest) -> Iterator[None]:
    """At the module's end, print how many cases each reader was tried on."""
    yield
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    if reporter is None or capture is None:
        return
    with capture.global_and_fixture_disabled():
        reporter.write("\n")
        for reader, n in sorted(TRIED.items()):
            reporter.write_line(f"test_corruption: {reader}: {n} cases")


# ------------------------------------------------------------------ the directories, built once


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Where the module's directories are built."""
    return tmp_path_factory.mktemp("corruption")


@pytest.fixture(scope="module")
def sweep_configs(built: Path) -> dict[str, Path]:
    """The two sweep configs: four cart masses of x_error_ags, 0.2 s each, a batch a variant, no
    figure; ``sweep`` variant by variant with time series, ``columnar`` from columns without."""
    raw = yaml.safe_load(CONFIG.read_text())
    raw.update(name="sw", outputs={"figure": False})
    raw["simulation"]["t_end"] = 0.2
    grid = {"plant.params.M": [0.9, 1.0, 1.1, 1.2]}
    out = {}
    for kind, extra in (("sweep", {"timeseries": True}), ("columnar", {})):
        out[kind] = built / f"{kind}.yaml"
        out[kind].write_text(yaml.safe_dump({**raw, "sweep": {"grid": grid, "batch_size": 1, **extra}}))
    return out


@pytest.fixture(scope="module")
def finished(built: Path, sweep_configs: dict[str, Path]) -> dict[str, Path]:
    """The finished directories: the run and the two sweeps, each complete and verified."""
    out = {kind: built / "finished" / kind for kind in LAYOUTS}
    result = runner.invoke(app, ["run", str(CONFIG), "simulation.t_end=1", "--out", str(out["run"])])
    assert result.exit_code == 0, result.output
    for kind in ("sweep", "columnar"):
        args = ["sweep", str(sweep_configs[kind]), "--executor", "serial", "--out", str(out[kind])]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
    for directory in out.values():
        manifest.verify(directory)
    return out


@pytest.fixture(scope="module")
def partial(built: Path, sweep_configs: dict[str, Path]) -> dict[str, Path]:
    """Each sweep interrupted after its second batch: the directory that holds its target
    (``out``, absent) and the target's staging directory (``.out.nlcx-partial``)."""

    def stop(done: int, total: int, failed: int) -> None:
        if done == 2:
            raise KeyboardInterrupt

    parents = {}
    for kind, config in sweep_configs.items():
        parents[kind] = built / "partial" / kind
        parents[kind].mkdir(parents=True)
        with pytest.raises(KeyboardInterrupt):
            sweeps.run(config, out_dir=parents[kind] / "out", executor="serial", progress=stop, with_report=False)
        assert len(seals.sealed(rundir.partial_dir(parents[kind] / "out"))) == 2
        assert not (parents[kind] / "out").exists()
    return parents


def copy_of(source: Path, target: Path) -> Path:
    """A copy of the directory ``source`` at ``target`` (hidden files included), its own files."""
    return Path(shutil.copytree(source, target))


# ------------------------------------------------------------------ the slots cover every file


@pytest.mark.parametrize("kind", list(LAYOUTS))
def test_the_slots_are_every_file_the_manifest_lists(finished: dict[str, Path], kind: str) -> None:
    """The slots of a finished directory name each file its manifest lists once, and no other;
    none is empty (each can be cut in half)."""
    directory = finished[kind]
    named = [resolve(directory, slot).relative_to(directory).as_posix() for slot in slots(LAYOUTS[kind])]
    assert sorted(named) == sorted(manifest.load(directory)["checksums"])
    assert all((directory / rel).stat().st_size > 1 for rel in named)


@pytest.mark.parametrize("kind", list(SEALED))
def test_the_slots_are_every_file_the_seals_list(partial: dict[str, Path], kind: str) -> None:
    """The slots of a partial sweep name each file its seals list once, and its seals."""
    staging = rundir.partial_dir(partial[kind] / "out")
    named = [resolve(staging, slot).relative_to(staging).as_posix() for slot in slots(SEALED[kind])]
    assert sorted(named) == sorted(seals.known(staging))
    assert [resolve(staging, slot).name for slot in slots(SEALS[kind])] == [
        f"{part}{seals.SEAL}" for part in seals.sealed(staging)
    ]


# ------------------------------------------------------------------ nlcx.load_run


def _load_run_cases() -> list[Any]:
    reads = ("config.yaml", "metrics.csv", "timeseries.csv")
    return [
        pytest.param(slot, how, id=f"{slot}-{how}")
        for slot in slots(LAYOUTS["run"], lambda pattern: pattern in reads)
        for how in DAMAGES
    ]


@pytest.mark.parametrize(("slot", "how"), _load_run_cases())
def test_load_run_refuses_a_damaged_file(finished: dict[str, Path], tmp_path: Path, slot: str, how: str) -> None:
    """``nlcx.load_run`` refuses a damaged config, metrics table or time series: one line
    (:class:`IntegrityError`) naming the file."""
    TRIED["nlcx.load_run"] += 1
    out = copy_of(finished["run"], tmp_path / "run")
    path = damage(resolve(out, slot), DAMAGES[how])
    with pytest.raises(IntegrityError) as info:
        nlcx.load_run(out)
    names(str(info.value), path)


@pytest.mark.parametrize("how", list(MANIFEST_DAMAGES))
def test_load_run_refuses_a_damaged_manifest(finished: dict[str, Path], tmp_path: Path, how: str) -> None:
    """``nlcx.load_run`` refuses a manifest that does not parse, or is not a manifest: one line
    naming it."""
    TRIED["nlcx.load_run"] += 1
    out = copy_of(finished["run"], tmp_path / "run")
    path = damage(out / manifest.MANIFEST, MANIFEST_DAMAGES[how])
    with pytest.raises(IntegrityError) as info:
        nlcx.load_run(out)
    names(str(info.value), path)


# ------------------------------------------------------------------ nlcx report DIR


def _report_cases() -> list[Any]:
    return [
        pytest.param(kind, slot, how, id=f"{kind}-{slot}-{how}")
        for kind, layout in LAYOUTS.items()
        for slot in slots(layout, lambda pattern: not is_page(pattern))
        for how in DAMAGES
    ]


@pytest.mark.parametrize(("kind", "slot", "how"), _report_cases())
def test_report_refuses_a_damaged_file(
    finished: dict[str, Path], tmp_path: Path, kind: str, slot: str, how: str
) -> None:
    """``nlcx report DIR`` refuses a damaged file (any but the pages it rewrites): exit 2, one
    line naming it; no page is written and the manifest is unchanged."""
    TRIED["nlcx report"] += 1
    out = copy_of(finished[kind], tmp_path / "out")
    path = damage(resolve(out, slot), DAMAGES[how])
    before = tree(out)
    names(one_line(runner.invoke(app, ["report", str(out)])), path)
    assert tree(out) == before


@pytest.mark.parametrize("how", list(MANIFEST_DAMAGES))
@pytest.mark.parametrize("kind", list(LAYOUTS))
def test_report_refuses_a_damaged_manifest(finished: dict[str, Path], tmp_path: Path, kind: str, how: str) -> None:
    """``nlcx report DIR`` refuses a manifest that does not parse, or is not a manifest: exit 2,
    one line naming it; nothing is written."""
    TRIED["nlcx report"] += 1
    out = copy_of(finished[kind], tmp_path / "out")
    path = damage(out / manifest.MANIFEST, MANIFEST_DAMAGES[how])
    before = tree(out)
    names(one_line(runner.invoke(app, ["report", str(out)])), path)
    assert tree(out) == before


# ------------------------------------------------------------------ nlcx diff


def _diff_cases() -> list[Any]:
    return [
        pytest.param(kind, slot, how, side, id=f"{kind}-{slot}-{how}-{side}")
        for kind, layout in LAYOUTS.items()
        for slot in slots(layout, is_table)
        for how in DAMAGES
        for side in ("new", "base")
    ]


def _diff(good: Path, damaged: Path, side: str) -> Any:
    """``nlcx diff GOOD DAMAGED`` (the damaged directory as ``new``) or ``nlcx diff DAMAGED GOOD``."""
    pair = [good, damaged] if side == "new" else [damaged, good]
    return runner.invoke(app, ["diff", *map(str, pair)])


@pytest.mark.parametrize(("kind", "slot", "how", "side"), _diff_cases())
def test_diff_refuses_a_damaged_table(
    finished: dict[str, Path], tmp_path: Path, kind: str, slot: str, how: str, side: str
) -> None:
    """``nlcx diff`` refuses a damaged table of either directory: exit 2, one line naming it."""
    TRIED["nlcx diff"] += 1
    out = copy_of(finished[kind], tmp_path / "out")
    path = damage(resolve(out, slot), DAMAGES[how])
    names(one_line(_diff(finished[kind], out, side)), path)


@pytest.mark.parametrize("side", ["new", "base"])
@pytest.mark.parametrize("how", list(MANIFEST_DAMAGES))
@pytest.mark.parametrize("kind", list(LAYOUTS))
def test_diff_refuses_a_damaged_manifest(
    finished: dict[str, Path], tmp_path: Path, kind: str, how: str, side: str
) -> None:
    """``nlcx diff`` refuses to compare the tables of a directory whose manifest does not parse,
    or is not a manifest: exit 2, one line naming it."""
    TRIED["nlcx diff"] += 1
    out = copy_of(finished[kind], tmp_path / "out")
    path = damage(out / manifest.MANIFEST, MANIFEST_DAMAGES[how])
    names(one_line(_diff(finished[kind], out, side)), path)


# ------------------------------------------------------------------ a resumed sweep


def _resume(config: Path, out: Path) -> Any:
    return runner.invoke(app, ["sweep", str(config), "--executor", "serial", "--no-report", "--out", str(out)])


def _partial_cases() -> list[Any]:
    files = [
        pytest.param(kind, slot, how, id=f"partial-{kind}-{slot}-{how}")
        for kind, layout in SEALED.items()
        for slot in slots(layout)
        for how in DAMAGES
    ]
    return files + [
        pytest.param(kind, slot, how, id=f"partial-{kind}-{slot}-{how}")
        for kind, layout in SEALS.items()
        for slot in slots(layout)
        for how in SEAL_DAMAGES
    ]


@pytest.mark.parametrize(("kind", "slot", "how"), _partial_cases())
def test_a_resumed_sweep_refuses_a_damaged_part_of_its_partial_directory(
    partial: dict[str, Path], sweep_configs: dict[str, Path], tmp_path: Path, kind: str, slot: str, how: str
) -> None:
    """A sweep resumed from an interrupted run refuses a damaged sealed part file or seal: exit 2,
    one line naming it (by its path under the staging directory; a seal altered so that it still
    parses is named as the seal of the file it no longer matches); no output directory."""
    TRIED["resumed sweep (partial directory)"] += 1
    parent = copy_of(partial[kind], tmp_path / "parent")
    staging = rundir.partial_dir(parent / "out")
    path = damage(resolve(staging, slot), damages_for(slot)[how])
    line = one_line(_resume(sweep_configs[kind], parent / "out"))
    assert line.startswith("integrity error: "), line
    rel = path.relative_to(staging).as_posix()
    assert rel in line, (line, rel)
    assert not (parent / "out").exists()


def _finished_cases() -> list[Any]:
    files = [
        pytest.param(kind, slot, how, id=f"finished-{kind}-{slot}-{how}")
        for kind in ("sweep", "columnar")
        for slot in slots(LAYOUTS[kind], lambda pattern: is_part(pattern) and not pattern.endswith(seals.SEAL))
        for how in DAMAGES
    ]
    return files + [
        pytest.param(kind, slot, how, id=f"finished-{kind}-{slot}-{how}")
        for kind in ("sweep", "columnar")
        for slot in slots(LAYOUTS[kind], lambda pattern: pattern.endswith(seals.SEAL))
        for how in SEAL_DAMAGES
    ]


@pytest.mark.parametrize(("kind", "slot", "how"), _finished_cases())
def test_a_resumed_sweep_refuses_a_damaged_part_of_a_finished_sweep(
    finished: dict[str, Path], sweep_configs: dict[str, Path], tmp_path: Path, kind: str, slot: str, how: str
) -> None:
    """A sweep rerun into its finished directory, which it resumes from, refuses a damaged part
    file or seal there: exit 2, one line naming it (by its path under the directory: the staging
    directory holds it under the same path); the finished directory is left as it was."""
    TRIED["resumed sweep (finished directory)"] += 1
    out = copy_of(finished[kind], tmp_path / "out")
    path = damage(resolve(out, slot), damages_for(slot)[how])
    before = tree(out)
    line = one_line(_resume(sweep_configs[kind], out))
    assert line.startswith("integrity error: "), line
    rel = path.relative_to(out).as_posix()
    assert rel in line, (line, rel)
    assert tree(out) == before


@pytest.mark.parametrize("how", list(MANIFEST_DAMAGES))
@pytest.mark.parametrize("kind", ["sweep", "columnar"])
def test_a_resumed_sweep_refuses_a_finished_sweep_whose_manifest_is_damaged(
    finished: dict[str, Path], sweep_configs: dict[str, Path], tmp_path: Path, kind: str, how: str
) -> None:
    """A sweep rerun into its finished directory whose manifest does not parse, or is not a
    manifest, refuses it: exit 2, one line naming the manifest; the directory is left as it was."""
    TRIED["resumed sweep (finished directory)"] += 1
    out = copy_of(finished[kind], tmp_path / "out")
    path = damage(out / manifest.MANIFEST, MANIFEST_DAMAGES[how])
    before = tree(out)
    names(one_line(_resume(sweep_configs[kind], out)), path)
    assert tree(out) == before

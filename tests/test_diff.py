"""nlcx diff, and the committed baselines reproduced within tolerance."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import reproduce_only
from typer.testing import CliRunner

from nlcx import manifest
from nlcx.cli import app
from nlcx.diff import KEEP, FileDrift, Tolerances, diff_dirs, render, summary
from nlcx.diff import matching as diff_matching
from nlcx.diff import stream as diff_stream
from nlcx.diff import tables as diff_tables

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / "results" / "baseline" / "tables"
runner = CliRunner()
BASELINE_TABLES = "table-2.3,table-2.5,table-3.2,table-3.7,table-4.2,table-4.4,table-5.1,table-5.8"


def test_diff_catches_injected_drift(tmp_path: Path) -> None:
    new = tmp_path / "new"
    shutil.copytree(BASELINE, new)
    assert runner.invoke(app, ["diff", str(BASELINE), str(new)]).exit_code == 0
    table = pd.read_csv(new / "table_2_3.csv")
    row = (table.signal == "x") & (table.metric == "ts") & (table.controller == "proposed")
    table.loc[row, "nlcx"] *= 1 + 1e-4  # a 0.01 % drift of one settling time
    table.to_csv(new / "table_2_3.csv", index=False)
    result = runner.invoke(app, ["diff", str(BASELINE), str(new), "--cells"])
    assert result.exit_code == 1
    assert "table_2_3.csv" in result.output and "x | ts | proposed" in result.output and "nlcx" in result.output
    assert "drift: 1 cell(s) in 1 of 8 file(s)" in result.output
    loose = runner.invoke(app, ["diff", str(BASELINE), str(new), "--rtol", "ts=1e-3"])
    assert loose.exit_code == 0, loose.output  # a per-metric tolerance lets it pass
    (new / "table_5_1.csv").unlink()
    assert "missing" in runner.invoke(app, ["diff", str(BASELINE), str(new), "--rtol", "1"]).output


def test_a_changed_verdict_is_a_missing_and_an_extra_row(tmp_path: Path) -> None:
    """A report_summary.csv whose verdict (a text column, part of a row's key) changed."""
    base, new = tmp_path / "base.csv", tmp_path / "new.csv"
    rows = {"table": ["Table 2.3", "Table 2.4"], "cells": [14, 14], "within_tolerance": [7, 3]}
    pd.DataFrame(rows | {"verdict": ["partly", "not"]}).to_csv(base, index=False)
    pd.DataFrame(rows | {"verdict": ["not", "not"]}).to_csv(new, index=False)
    result = runner.invoke(app, ["diff", str(base), str(new), "--rtol", "0", "--atol", "0", "--cells"])
    assert result.exit_code == 1, result.output
    assert "Table 2.3 | partly" in result.output and "missing in NEW" in result.output
    assert "Table 2.3 | not" in result.output and "extra in NEW" in result.output


def test_an_infinity_equals_itself_and_nothing_else(tmp_path: Path) -> None:
    """A cell that is infinite in both (an identification fit's relative error of a diverged run)
    has not drifted, even at --rtol 0 --atol 0; an infinity against a number, or against the
    other infinity, has."""
    base, new = tmp_path / "base.csv", tmp_path / "new.csv"
    cells = {"cell": ["a", "b", "c", "d"]}
    pd.DataFrame(cells | {"rel_error": [float("inf"), 0.5, float("inf"), float("-inf")]}).to_csv(base, index=False)
    pd.DataFrame(cells | {"rel_error": [float("inf"), 0.5, 2.0, float("inf")]}).to_csv(new, index=False)
    result = runner.invoke(app, ["diff", str(base), str(new), "--rtol", "0", "--atol", "0", "--cells"])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert lines[0] == "base.csv: 2 cell(s) drifted (rel_error)", result.output  # no finite |diff|
    assert [line.split()[1] for line in lines[2:-1]] == ["c", "d"], result.output
    assert lines[-1].startswith("drift: 2 cell(s)"), result.output


@pytest.mark.slow
def test_committed_baselines_still_reproduce(tmp_path: Path) -> None:
    """The fast subset of thesis tables (chapters 2-5) regenerates to the committed numbers.

    To refresh the baselines after a deliberate change: `make baseline`, review the diff, commit.
    """
    out = tmp_path / "ci"
    result = reproduce_only(BASELINE_TABLES, out)
    assert result.exit_code == 0, result.output
    check = runner.invoke(app, ["diff", str(BASELINE), str(out / "tables")])
    assert check.exit_code == 0, check.output


@pytest.fixture(scope="module")
def run_dirs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The x pendulum's two controllers, then the same with |theta| <= 0.2: the proposed
    controller's angle peaks at 0.23 rad, so that run stops as unstable; the conventional
    one (0.14 rad) runs as before."""
    base, new = tmp_path_factory.mktemp("base"), tmp_path_factory.mktemp("new")
    config = str(ROOT / "configs" / "x_error_ags.yaml")
    for out, extra in ((base, []), (new, ["simulation.bounds.theta=0.2"])):
        result = runner.invoke(app, ["run", config, *extra, "outputs.figure=false", "--no-report", "--out", str(out)])
        assert result.exit_code == 0, result.output
    return base, new


def test_a_changed_status_is_one_line_not_missing_rows(run_dirs: tuple[Path, Path]) -> None:
    base, new = run_dirs
    statuses = pd.read_csv(new / "metrics.csv").groupby("controller").status.unique()
    assert list(statuses["proposed"]) == ["unstable"] and list(statuses["conventional"]) == ["ok"]
    result = runner.invoke(app, ["diff", str(base), str(new), "--only", "metrics.csv", "--cells"])
    assert result.exit_code == 1, result.output
    assert "metrics.csv  proposed  status: ok -> unstable" in result.output
    assert "missing" not in result.output and "extra" not in result.output
    assert "conventional" not in result.output  # its rows are the same
    assert result.output.splitlines()[-1] == "drift: 1 cell(s) in 1 of 1 file(s): metrics.csv 1 (1 status change(s))"


@pytest.mark.slow
def test_only_and_the_drift_of_each_file(run_dirs: tuple[Path, Path]) -> None:
    """Every file by default, its drift counted per file; the time series capped in the table."""
    base, new = run_dirs
    result = runner.invoke(app, ["diff", str(base), str(new), "--cells"])
    assert result.exit_code == 1
    series = {
        name: pd.read_csv(d / "timeseries.csv").groupby("controller").size()
        for name, d in zip(("base", "new"), run_dirs, strict=True)
    }
    lost = int(series["base"]["proposed"] - series["new"]["proposed"])  # samples after the run stopped
    assert lost > 10_000
    summary = result.output.splitlines()[-1]
    assert summary == (
        f"drift: {lost + 1} cell(s) in 2 of 2 file(s): metrics.csv 1 (1 status change(s)), timeseries.csv {lost}"
    )
    shown = [line for line in result.output.splitlines() if line.startswith("timeseries.csv  proposed #")]
    assert len(shown) == 10 and f"... and {lost - 10} more in timeseries.csv" in result.output
    first = int(series["new"]["proposed"])  # the first sample the new run lacks
    assert shown[0].split()[:5] == ["timeseries.csv", "proposed", f"#{first}", "(row)", "present"]
    only = runner.invoke(app, ["diff", str(base), str(new), "--only", "*series.csv", "--only", "nothing*"])
    assert only.exit_code == 1 and "metrics.csv" not in only.output
    assert only.output.splitlines()[-1] == f"drift: {lost} cell(s) in 1 of 1 file(s): timeseries.csv {lost}"


def test_only_matching_nothing_is_one_line(run_dirs: tuple[Path, Path]) -> None:
    base, new = run_dirs
    result = runner.invoke(app, ["diff", str(base), str(new), "--only", "*.json"])
    assert result.exit_code == 2
    assert result.stderr.splitlines() == [
        f"diff error: --only = *.json: matches no file of {base}; allowed: a pattern on the relative paths: "
        "metrics.csv, timeseries.csv"
    ]


def test_a_changed_note_is_a_changed_cell(tmp_path: Path) -> None:
    """A settling time that no longer settles: its value and its note changed, the row is there."""
    rows = {"controller": ["a", "a"], "signal": ["x", "x"], "metric": ["overshoot", "settling_time"], "unit": "s"}
    base, new = tmp_path / "base.csv", tmp_path / "new.csv"
    pd.DataFrame(rows | {"value": [5.0, 9.5], "status": "ok", "note": ["", ""]}).to_csv(base, index=False)
    pd.DataFrame(rows | {"value": [5.0, None], "status": "ok", "note": ["", "did not settle"]}).to_csv(new, index=False)
    result = runner.invoke(app, ["diff", str(base), str(new), "--cells"])
    assert result.exit_code == 1, result.output
    lines = result.output.splitlines()[1:]  # after the file's summary
    assert lines[1].split() == ["base.csv", "a", "|", "x", "|", "settling_time", "|", "s", "value", "9.5", "nan", "nan"]
    assert lines[2].split()[-4:] == ["note", "did", "not", "settle"]
    assert "missing" not in result.output and lines[-1] == "drift: 2 cell(s) in 1 of 1 file(s): base.csv 2"


def test_a_table_without_rows_is_compared_too(tmp_path: Path) -> None:
    """A batch whose variants all failed leaves a metrics file with a header and no row: two
    of them hold no drift; against one with a row, that row is extra."""
    header = '"variant","controller","signal","metric","value","unit","status","note"\n'
    for name in ("base", "same"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "part.metrics.csv").write_text(header)
    same = runner.invoke(app, ["diff", str(tmp_path / "base"), str(tmp_path / "same")])
    assert same.exit_code == 0 and "no drift: 1 file(s)" in same.output, same.output
    (tmp_path / "more").mkdir()
    (tmp_path / "more" / "part.metrics.csv").write_text(header + '4,"a","x","ise",1.5,"","ok",\n')
    more = runner.invoke(app, ["diff", str(tmp_path / "base"), str(tmp_path / "more")])
    assert more.exit_code == 1 and "extra in NEW" in more.output, more.output


# ----------------------------------------------------------------------------- tables read a chunk at a time

ZERO = Tolerances(rtol={"default": 0.0}, atol={"default": 0.0})


@pytest.fixture
def small_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tables read a few rows at a time, so that a small table crosses many chunks."""
    monkeypatch.setattr(diff_tables, "BLOCK_BYTES", 64)
    monkeypatch.setattr(diff_tables, "CHUNK_ROWS", 5)


def _one_table(base: Path, new: Path, tol: Tolerances = ZERO) -> FileDrift:
    """The drift of the one table compared."""
    report = diff_dirs(base, new, tol)
    (table,) = report.files
    return table


def _frames(tmp_path: Path, base: pd.DataFrame, new: pd.DataFrame) -> tuple[Path, Path]:
    """BASE and NEW written as base.csv and new.csv."""
    paths = tmp_path / "base.csv", tmp_path / "new.csv"
    for frame, path in zip((base, new), paths, strict=True):
        frame.to_csv(path, index=False)
    return paths


def _long_form(runs: int = 4) -> pd.DataFrame:
    """A metrics table: per controller, signal and metric one value."""
    rows = [
        {"controller": f"c{c}", "signal": s, "metric": m, "value": c + 0.25 * k + 0.5 * (s == "y")}
        for c in range(runs)
        for s in ("x", "y")
        for k, m in enumerate(("rise_time", "overshoot", "ise"))
    ]
    return pd.DataFrame(rows)


def test_every_drifting_cell_is_counted_and_only_the_first_are_held(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two million rows in which every number moved: the counts are exact, and at no point
    are more than KEEP drifts held."""
    rows = 2_000_000
    t = np.arange(rows) * 1e-3
    controller = pa.DictionaryArray.from_arrays(pa.array(np.arange(rows) * 2 // rows, pa.int32()), ["a", "b"])
    base = pa.table({"controller": controller, "t": t, "x": np.sin(t)})
    new = pa.table({"controller": controller, "t": t + 1.0, "x": np.sin(t) + 1.0})
    pq.write_table(base, tmp_path / "base.parquet")
    pq.write_table(new, tmp_path / "new.parquet")
    held = []
    offer = diff_matching.DriftTally.offer

    def watched(self: diff_matching.DriftTally, found: list[diff_matching.Found]) -> None:
        offer(self, found)
        held.append(len(self.kept))

    monkeypatch.setattr(diff_matching.DriftTally, "offer", watched)
    report = diff_dirs(tmp_path / "base.parquet", tmp_path / "new.parquet", ZERO)
    (table,) = report.files
    assert (table.cells, table.missing_rows, table.extra_rows, table.status_changes) == (2 * rows, 0, 0, 0)
    assert summary(report) == f"drift: {2 * rows} cell(s) in 1 of 1 file(s): base.parquet {2 * rows}"
    assert max(held) == KEEP and len(table.first) == KEEP
    assert [(d.key, d.column) for d in table.first[:4]] == [("a #0", "t"), ("a #0", "x"), ("a #1", "t"), ("a #1", "x")]
    assert render(report).splitlines()[-1] == f"... and {2 * rows - KEEP} more in base.parquet"


def test_reordered_rows_are_matched_on_their_key(tmp_path: Path, small_chunks: None) -> None:
    base = _long_form()
    new = base.sample(frac=1.0, random_state=3).reset_index(drop=True)
    assert _one_table(*_frames(tmp_path, base, new)).total == 0
    new.loc[(new.controller == "c2") & (new.metric == "ise") & (new.signal == "y"), "value"] += 1.0
    table = _one_table(*_frames(tmp_path, base, new))
    assert table.total == table.cells == 1
    assert [(d.key, d.column, d.base, d.new) for d in table.first] == [("c2 | y | ise", "value", 3.0, 4.0)]


def test_an_inserted_and_a_deleted_row_leave_the_others_matched(tmp_path: Path, small_chunks: None) -> None:
    base = _long_form(runs=6)
    extra = pd.DataFrame([{"controller": "c9", "signal": "x", "metric": "ise", "value": 7.0}])
    new = pd.concat([base.drop(index=5).iloc[:20], extra, base.drop(index=5).iloc[20:]], ignore_index=True)
    table = _one_table(*_frames(tmp_path, base, new))
    assert (table.cells, table.missing_rows, table.extra_rows) == (0, 1, 1)
    found = [(d.key, d.new) for d in table.first]
    assert found == [("c0 | y | ise", "missing in NEW"), ("c9 | x | ise", "extra in NEW")]


def test_repeated_keys_are_matched_by_their_occurrence(tmp_path: Path, small_chunks: None) -> None:
    """A time series: the k-th sample of a controller in BASE with its k-th in NEW, whatever
    the order of the controllers; a lost last sample is one missing row."""
    t = np.arange(12) * 0.5
    base = pd.DataFrame({"controller": ["a"] * 12 + ["b"] * 12, "t": np.r_[t, t], "x": np.r_[t**2, -t]})
    new = pd.concat([base.iloc[12:], base.iloc[:11]], ignore_index=True)
    new.loc[new.controller.eq("a") & new.t.eq(1.5), "x"] = 0.0
    table = _one_table(*_frames(tmp_path, base, new))
    assert (table.cells, table.missing_rows, table.extra_rows) == (1, 1, 0)
    assert [(d.key, d.column, d.new) for d in table.first] == [("a #3", "x", 0.0), ("a #11", "(row)", "missing in NEW")]


def test_a_changed_status_leaves_its_rows_out(tmp_path: Path, small_chunks: None) -> None:
    """The run whose status changed: one status change, its rows neither compared nor missing;
    the other runs compared as before."""
    base = _long_form().assign(status="ok", note="")
    unstable = base.controller.eq("c1")
    new = base[~(unstable & base.metric.eq("ise"))].copy()
    new.loc[new.controller.eq("c1"), ["status", "value"]] = ["unstable", -1.0]
    new.loc[new.controller.eq("c3") & new.metric.eq("overshoot") & new.signal.eq("x"), "value"] = 9.0
    paths = _frames(tmp_path, base, new)
    report = diff_dirs(*paths, ZERO)
    (table,) = report.files
    assert (table.status_changes, table.cells, table.missing_rows, table.extra_rows) == (1, 1, 0, 0)
    assert report.drifts == [*table.statuses, *table.first] and report.drifts[0].status_change
    assert [(d.key, d.column, d.base, d.new) for d in table.statuses] == [("c1", "status", "ok", "unstable")]
    assert [(d.key, d.column) for d in table.first] == [("c3 | x | overshoot", "value")]
    result = runner.invoke(app, ["diff", *map(str, paths), "--rtol", "0", "--atol", "0"])
    assert result.exit_code == 1 and "base.csv  c1  status: ok -> unstable" in result.output, result.output
    assert result.output.splitlines()[-1] == "drift: 2 cell(s) in 1 of 1 file(s): base.csv 2 (1 status change(s))"


def test_too_many_runs_compare_statuses_row_by_row(
    tmp_path: Path, small_chunks: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(diff_stream, "STATUS_RUNS", 2)
    base = _long_form().assign(status="ok")
    new = base.assign(status=np.where(base.controller.eq("c1"), "unstable", "ok"))
    table = _one_table(*_frames(tmp_path, base, new))
    assert (table.status_changes, table.cells) == (0, 6)
    (note,) = table.notes
    assert note == "base.csv: more than 2 distinct runs and statuses: statuses compared row by row, not per run"


def test_rows_in_another_order_beyond_the_pending_cap(
    tmp_path: Path, small_chunks: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Past the cap on rows waiting for their match, matching stops: the rest are missing and
    extra rows, and one line says so."""
    monkeypatch.setattr(diff_matching, "PENDING_ROWS", 8)
    base = _long_form(runs=10)
    paths = _frames(tmp_path, base, base.iloc[::-1])
    table = _one_table(*paths)
    assert table.cells == 0 and table.missing_rows == table.extra_rows > 0
    (note,) = table.notes
    assert note.startswith("base.csv: rows not matched after row ") and "more than 8 rows waited" in note
    result = runner.invoke(app, ["diff", *map(str, paths)])
    assert result.exit_code == 1 and note in result.output.splitlines(), result.output


def test_a_column_of_numbers_that_holds_text_further_down_is_a_key(tmp_path: Path, small_chunks: None) -> None:
    """A column taken for numbers from the first rows is a key once text shows further down."""
    base = pd.DataFrame({"case": [str(k) for k in range(30)] + ["last"], "value": np.arange(31.0)})
    new = base.assign(value=base.value.where(base.case.ne("3"), 0.5))
    table = _one_table(*_frames(tmp_path, base, new))
    assert [(d.key, d.column, d.base, d.new) for d in table.first] == [("3", "value", 3.0, 0.5)]


def test_a_csv_and_its_parquet_counterparts_hold_the_same_cells(tmp_path: Path, small_chunks: None) -> None:
    """A CSV against the same table as a Parquet file, and as a dataset of part files."""
    frame = _long_form(runs=5).assign(variant=lambda f: np.arange(len(f)) // 6, status="ok", note="")
    (tmp_path / "csv").mkdir()
    frame.to_csv(tmp_path / "csv" / "metrics.csv", index=False)
    (tmp_path / "file").mkdir()
    frame.to_parquet(tmp_path / "file" / "metrics.parquet", index=False)
    dataset = tmp_path / "dataset" / "metrics.parquet"
    dataset.mkdir(parents=True)
    moved = frame.assign(value=frame.value.where(frame.index != 17, 99.0))
    for k, part in enumerate((moved.iloc[:12], moved.iloc[12:])):
        part.to_parquet(dataset / f"part-{k:05d}.parquet", index=False)
    assert _one_table(tmp_path / "csv", tmp_path / "file").total == 0
    assert _one_table(tmp_path / "file", tmp_path / "csv").total == 0
    table = _one_table(tmp_path / "csv", tmp_path / "dataset")
    assert table.file == "metrics.csv" and table.total == 1
    (drift,) = table.first
    assert (drift.key, drift.column, drift.base, drift.new) == ("c2 | y | ise | 2", "value", 3.0, 99.0)


def _reference_counts(base: pd.DataFrame, new: pd.DataFrame, keys: list[str]) -> tuple[int, int, int]:
    """(cells, missing, extra) at zero tolerance, every row of a key numbered from the top."""
    numbered = [f.assign(_k=f.groupby(keys).cumcount()) for f in (base, new)]
    merged = numbered[0].merge(numbered[1], on=[*keys, "_k"], how="outer", suffixes=("_b", "_n"), indicator=True)
    both = merged[merged["_merge"] == "both"]
    numeric = [c for c in base.columns if c not in keys]
    cells = sum(int((both[f"{c}_b"] != both[f"{c}_n"]).sum()) for c in numeric)
    return cells, int((merged["_merge"] == "left_only").sum()), int((merged["_merge"] == "right_only").sum())


@pytest.mark.parametrize("seed", range(6))
def test_counts_agree_with_numbering_every_row_of_a_key(tmp_path: Path, small_chunks: None, seed: int) -> None:
    """Rows deleted, inserted, moved in blocks and changed, across many chunks: the counts are
    those of matching every row of a key by its number from the top."""
    rng = np.random.default_rng(seed)
    n = 120
    base = pd.DataFrame({"controller": rng.choice(["a", "b", "c"], n), "signal": rng.choice(["x", "y"], n)})
    base["value"] = rng.integers(0, 4, n).astype(float)
    new = base.drop(index=rng.choice(n, 6, replace=False)).reset_index(drop=True)
    block = new.iloc[30:40]
    new = pd.concat([new.iloc[:30], new.iloc[40:70], block, new.iloc[70:]], ignore_index=True)
    new.loc[rng.choice(len(new), 8, replace=False), "value"] += 1.0
    inserted = pd.DataFrame({"controller": ["d", "a"], "signal": ["x", "y"], "value": [1.0, 2.0]})
    new = pd.concat([new.iloc[:50], inserted, new.iloc[50:]], ignore_index=True)
    table = _one_table(*_frames(tmp_path, base, new))
    assert (table.cells, table.missing_rows, table.extra_rows) == _reference_counts(base, new, ["controller", "signal"])


def test_identical_tables_are_not_parsed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Tables of the same bytes have no drift and are never read as tables: a run directory
    against its copy and against itself."""
    base = tmp_path / "base"
    (base / "metrics.parquet").mkdir(parents=True)
    _long_form().to_csv(base / "metrics.csv", index=False)
    _long_form().to_parquet(base / "metrics.parquet" / "part-00000.parquet", index=False)
    shutil.copytree(base, tmp_path / "copy")

    def refused(*args: object) -> None:
        raise AssertionError("a table of the same bytes was parsed")

    monkeypatch.setattr(diff_tables, "_csv_batches", refused)
    monkeypatch.setattr(diff_tables, "_parquet_batches", refused)
    for new in (tmp_path / "copy", base):
        result = runner.invoke(app, ["diff", str(base), str(new)])
        assert result.exit_code == 0 and "no drift: 2 file(s)" in result.output, result.output
    shutil.copy(base / "metrics.csv", tmp_path / "other name.csv")
    result = runner.invoke(app, ["diff", str(base / "metrics.csv"), str(tmp_path / "other name.csv")])
    assert result.exit_code == 0 and "no drift: 1 file(s)" in result.output, result.output


def test_a_truncated_table_is_refused_in_one_line(tmp_path: Path) -> None:
    base, new = tmp_path / "base", tmp_path / "new"
    base.mkdir()
    _long_form().to_csv(base / "metrics.csv", index=False)
    manifest.write(base, {"nlcx_output": "run"})
    shutil.copytree(base, new)
    assert runner.invoke(app, ["diff", str(base), str(new)]).exit_code == 0
    data = (new / "metrics.csv").read_bytes()
    (new / "metrics.csv").write_bytes(data[: len(data) // 2])
    result = runner.invoke(app, ["diff", str(base), str(new)])
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert line.startswith(f"integrity error: {new / 'metrics.csv'}: ") and "truncated" in line


def test_diff_shows_the_configs_differences_then_each_files_drift(run_dirs: tuple[Path, Path]) -> None:
    """The resolved configs first (key: old → new), then per file its drifted cells' count and
    largest |diff|, without the cells unless --cells asks for them."""
    base, new = run_dirs
    result = runner.invoke(app, ["diff", str(base), str(new), "--only", "metrics.csv", "--rtol", "0", "--atol", "0"])
    assert result.exit_code == 1, result.output
    lines = result.output.splitlines()
    assert lines[:2] == ["config:", "  simulation.bounds.theta: (absent) → 0.2"]
    assert lines[2:] == [
        "metrics.csv: 1 status change(s)",
        "metrics.csv  proposed  status: ok -> unstable",
        "drift: 1 cell(s) in 1 of 1 file(s): metrics.csv 1 (1 status change(s))",
    ]
    same = runner.invoke(app, ["diff", str(base), str(base), "--rtol", "0", "--atol", "0"])
    assert same.exit_code == 0 and same.output.splitlines()[0] == "config: identical", same.output


def test_the_summary_of_a_file_counts_its_cells_and_their_largest_difference(tmp_path: Path) -> None:
    base, new = tmp_path / "base.csv", tmp_path / "new.csv"
    cells = {"cell": ["a", "b", "c"]}
    pd.DataFrame(cells | {"u": [1.0, 2.0, 3.0], "v": [0.0, 0.0, 0.0]}).to_csv(base, index=False)
    pd.DataFrame(cells | {"u": [1.5, 2.0, 3.25], "v": [0.0, -2.0, 0.0]}).to_csv(new, index=False)
    result = runner.invoke(app, ["diff", str(base), str(new), "--rtol", "0", "--atol", "0"])
    assert result.exit_code == 1, result.output
    assert result.output.splitlines() == [
        "base.csv: 3 cell(s) drifted (u, v), largest |diff| 2",
        "drift: 3 cell(s) in 1 of 1 file(s): base.csv 3",
    ]
    cells = runner.invoke(app, ["diff", str(base), str(new), "--rtol", "0", "--atol", "0", "--cells"])
    assert cells.exit_code == 1
    assert cells.output.splitlines()[1].split() == ["file", "row", "column", "base", "new", "|diff|"]
    assert [line.split()[1:3] for line in cells.output.splitlines()[2:-1]] == [["a", "u"], ["b", "v"], ["c", "u"]]
    loose = runner.invoke(app, ["diff", str(base), str(new), "--atol", "2"])
    assert loose.exit_code == 0 and loose.output.startswith("no drift: 1 file(s)"), loose.output


def test_a_run_diffed_with_itself_is_identical_by_its_bytes(
    run_dirs: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """No table of a self-diff is parsed: each is the same bytes, reported identical."""
    base, _ = run_dirs

    def refused(*args: object, **kwargs: object) -> None:
        raise AssertionError("a table of the same bytes was compared")

    monkeypatch.setattr(diff_stream, "compare_tables", refused)
    report = diff_dirs(base, base, Tolerances())
    assert report.n_files == 2 and all(f.identical for f in report.files) and not report.drifted
    result = runner.invoke(app, ["diff", str(base), str(base)])
    assert result.exit_code == 0 and "no drift: 2 file(s)" in result.output, result.output

"""nlcx diff, and the committed baselines reproduced within tolerance."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest
from conftest import reproduce_only
from typer.testing import CliRunner

from nlcx.cli import app

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
    result = runner.invoke(app, ["diff", str(BASELINE), str(new)])
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
    result = runner.invoke(app, ["diff", str(base), str(new), "--rtol", "0", "--atol", "0"])
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
    result = runner.invoke(app, ["diff", str(base), str(new), "--rtol", "0", "--atol", "0"])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert [line.split()[1] for line in lines[1:-1]] == ["c", "d"], result.output
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
    result = runner.invoke(app, ["diff", str(base), str(new), "--only", "metrics.csv"])
    assert result.exit_code == 1, result.output
    assert "metrics.csv  proposed  status: ok -> unstable" in result.output
    assert "missing" not in result.output and "extra" not in result.output
    assert "conventional" not in result.output  # its rows are the same
    assert result.output.splitlines()[-1] == "drift: 1 cell(s) in 1 of 1 file(s): metrics.csv 1 (1 status change(s))"


@pytest.mark.slow
def test_only_and_the_drift_of_each_file(run_dirs: tuple[Path, Path]) -> None:
    """Every file by default, its drift counted per file; the time series capped in the table."""
    base, new = run_dirs
    result = runner.invoke(app, ["diff", str(base), str(new)])
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
    result = runner.invoke(app, ["diff", str(base), str(new)])
    assert result.exit_code == 1, result.output
    lines = result.output.splitlines()
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

"""nlcx diff, and the committed baselines reproduced within tolerance."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
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


def test_committed_baselines_still_reproduce(tmp_path: Path) -> None:
    """The fast subset of thesis tables (chapters 2-5) regenerates to the committed numbers.

    To refresh the baselines after a deliberate change: `make baseline`, review the diff, commit.
    """
    out = tmp_path / "ci"
    result = reproduce_only(BASELINE_TABLES, out)
    assert result.exit_code == 0, result.output
    check = runner.invoke(app, ["diff", str(BASELINE), str(out / "tables")])
    assert check.exit_code == 0, check.output

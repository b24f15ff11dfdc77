"""The opt-in Parquet time series (``outputs.timeseries_format: parquet``) end to end: the run
writes timeseries.parquet in place of timeseries.csv with the same values to the last bit,
the same bytes on a rerun; a sweep writes its variants' time series as Parquet; ``nlcx diff``
and ``nlcx metrics`` read it; a bad format is a one-line error."""

from __future__ import annotations

import filecmp
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from nlcx.cli import app

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "x_error_ags.yaml"
CSTR = ROOT / "configs" / "cstr_nonlinear.yaml"
SHORT = ["simulation.t_end=3", "outputs.figure=false"]
runner = CliRunner()


def _run(out: Path, *overrides: str, config: Path = CONFIG) -> Path:
    result = runner.invoke(app, ["run", str(config), *SHORT, *overrides, "--out", str(out), "--no-report", "-q"])
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("parquet")
    return {
        "csv": _run(root / "csv"),
        "parquet": _run(root / "parquet", "outputs.timeseries_format=parquet"),
        "again": _run(root / "again", "outputs.timeseries_format=parquet"),
        # a PID and a single neuron: each one's logs are NaN (null) in the other's rows
        "cstr_csv": _run(root / "cstr_csv", config=CSTR),
        "cstr_parquet": _run(root / "cstr_parquet", "outputs.timeseries_format=parquet", config=CSTR),
    }


def test_the_parquet_file_replaces_the_csv_and_is_listed(runs: dict[str, Path]) -> None:
    names = {p.name for p in runs["parquet"].iterdir()}
    assert "timeseries.parquet" in names and "timeseries.csv" not in names
    assert "timeseries.parquet" in json.loads((runs["parquet"] / "manifest.json").read_text())["files"]
    assert filecmp.cmp(runs["csv"] / "metrics.csv", runs["parquet"] / "metrics.csv", shallow=False)


@pytest.mark.parametrize("plant", ["", "cstr_"])
def test_the_parquet_values_are_the_csvs_to_the_last_bit(runs: dict[str, Path], plant: str) -> None:
    """The CSV holds each float in its shortest round-trip form, which pandas reads back
    exactly, so it must equal the Parquet file's 8-byte floats; NaN is null in both."""
    csv = pd.read_csv(runs[f"{plant}csv"] / "timeseries.csv")
    table = pq.read_table(runs[f"{plant}parquet"] / "timeseries.parquet")
    assert table.column_names == list(csv.columns)
    assert table.num_rows == len(csv) > 1000
    for name in csv.columns:
        column = table.column(name)
        if name == "controller":
            assert column.to_pylist() == csv[name].tolist()
            continue
        ours = column.to_numpy(zero_copy_only=False)
        theirs = csv[name].to_numpy(dtype=np.float64)
        assert np.array_equal(np.isnan(ours), np.isnan(theirs)), name
        assert column.null_count == np.isnan(ours).sum(), name
        assert np.array_equal(ours[~np.isnan(ours)].view(np.int64), theirs[~np.isnan(theirs)].view(np.int64)), name
    nulls = sum(table.column(name).null_count for name in table.column_names)
    assert (nulls > 0) == (plant == "cstr_")


def test_a_rerun_writes_the_same_bytes(runs: dict[str, Path]) -> None:
    assert filecmp.cmp(runs["parquet"] / "timeseries.parquet", runs["again"] / "timeseries.parquet", shallow=False)


def test_diff_reads_parquet_and_finds_a_moved_sample(runs: dict[str, Path], tmp_path: Path) -> None:
    same = runner.invoke(app, ["diff", str(runs["parquet"]), str(runs["again"]), "--rtol", "0", "--atol", "0"])
    assert same.exit_code == 0, same.output
    assert "no drift: 2 file(s)" in same.output  # metrics.csv and timeseries.parquet
    table = pq.read_table(runs["again"] / "timeseries.parquet")
    theta = table.column("theta").to_numpy().copy()
    theta[100] += 1e-9
    moved = tmp_path / "timeseries.parquet"
    pq.write_table(table.set_column(table.column_names.index("theta"), "theta", [theta]), moved)
    base = str(runs["parquet"] / "timeseries.parquet")
    result = runner.invoke(app, ["diff", base, str(moved), "--rtol", "0", "--atol", "0"])
    assert result.exit_code == 1, result.output
    assert "theta" in result.output and "drift: 1 cell(s) in 1 of 1 file(s)" in result.output


def test_metrics_command_measures_a_run_per_controller_from_either_file(runs: dict[str, Path]) -> None:
    """A run's time series holds its controllers one after the other (t restarts at each): both
    files are measured per controller, to the same table."""
    outputs = []
    for name in ("timeseries.csv", "timeseries.parquet"):
        result = runner.invoke(app, ["metrics", str(runs["parquet" if name.endswith("parquet") else "csv"] / name),
                                     "--signal", "x"])  # fmt: skip
        assert result.exit_code == 0, result.output
        outputs.append(result.stdout.replace(name, "FILE"))
    assert outputs[0] == outputs[1]
    assert "controller conventional" in outputs[0] and "controller proposed" in outputs[0]


def test_metrics_command_measures_parquet_as_it_measures_the_csv(runs: dict[str, Path], tmp_path: Path) -> None:
    table = pq.read_table(runs["parquet"] / "timeseries.parquet").to_pandas()
    one = table[table.controller == "proposed"]
    pq.write_table(pa.Table.from_pandas(one, preserve_index=False), tmp_path / "p.parquet")
    one.to_csv(tmp_path / "p.csv", index=False)
    outputs = []
    for name in ("p.csv", "p.parquet"):
        result = runner.invoke(app, ["metrics", str(tmp_path / name), "--signal", "x", "--signal", "theta"])
        assert result.exit_code == 0, result.output
        outputs.append(result.stdout.replace(name, "FILE"))
    assert outputs[0] == outputs[1] and "rise_time" in outputs[0]


def test_an_unreadable_parquet_file_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.parquet"
    bad.write_text("t,y\n0,1\n")
    result = runner.invoke(app, ["metrics", str(bad), "--signal", "y"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"metrics error: FILE = {bad}: not readable as Parquet")


def test_a_bad_format_is_one_line_naming_the_key(tmp_path: Path) -> None:
    result = runner.invoke(app, ["run", str(CONFIG), "outputs.timeseries_format=xlsx", "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert lines == ["config error: outputs.timeseries_format = 'xlsx': allowed values: 'csv' or 'parquet'"]
    assert not (tmp_path / "o").exists()


def test_a_sweep_writes_its_variants_time_series_as_parquet(tmp_path: Path) -> None:
    raw = yaml.safe_load(CONFIG.read_text())
    raw.update(name="pq_sweep", simulation={**raw.get("simulation", {}), "t_end": 1.0})
    raw["outputs"] = {"figure": False, "timeseries_format": "parquet"}
    raw["sweep"] = {"grid": {"plant.params.M": [1.0, 1.1]}, "timeseries": True}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(raw))
    out = tmp_path / "out"
    result = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out), "--no-report"])
    assert result.exit_code == 0, result.output
    files = sorted(p.name for p in (out / "timeseries").iterdir())
    assert files == ["variant_000000.parquet", "variant_000001.parquet"]
    masses = [pq.read_table(out / "timeseries" / name).column("x").to_numpy() for name in files]
    assert masses[0].size == masses[1].size > 100 and not np.array_equal(masses[0], masses[1])

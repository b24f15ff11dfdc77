"""A sweep's tables (``sweep`` and ``metrics``) read the same from either form they are written
in, Parquet datasets or CSV files: :func:`nlcx.results.read_output_table` gives equal frames,
``nlcx diff`` finds no drift between the two forms of one sweep, the report page shows the same
numbers, and a directory holding the Parquet form is a sweep's output directory."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
import pytest
import yaml
from pandas.testing import assert_frame_equal
from typer.testing import CliRunner

from nlcx import manifest, rundir
from nlcx.cli import app
from nlcx.errors import ConfigError
from nlcx.pages import render, sweep
from nlcx.results import read_output_table
from nlcx.sweeps.planning import SweepSection

ROOT = Path(__file__).resolve().parents[1]
STEMS = ("metrics", "sweep")
#: The override that asks for the CSV form, where the sweep section has a format to choose.
CSV_FORM = ["sweep.format=csv"] if "format" in SweepSection.model_fields else []
#: The files of a sweep's report.
REPORT = ("summary.csv", "profiles.csv", "report.html", "report.md", "report_files")
runner = CliRunner()


def _config(tmp: Path) -> Path:
    """A sweep of 6 variants over a text and a number: 4 run (NaN metrics with notes, empty
    notes beside them), 2 fail (a message; no metrics)."""
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    friction = {"kind": "friction", "model": "none", "mu_s": 0.2, "mu_c": 0.15, "viscous": 0.1}
    grid = {"uncertainty.friction.model": ["none", "simple"], "plant.params.M": [1.0, 1.2, -1.0]}
    raw.update(name="tables", outputs={"figure": False, "timeseries": False}, uncertainty={"friction": friction},
               sweep={"seed": 1, "grid": grid, "batch_size": 4})  # fmt: skip
    raw["simulation"]["t_end"] = 2.0
    path = tmp / "tables.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def _sweep(config: Path, out: Path, *overrides: str) -> Path:
    """``nlcx sweep`` of ``config`` into ``out``; it exits 1, its two variants having failed."""
    args = ["sweep", str(config), *overrides, "--executor", "serial", "--out", str(out), "--no-report"]
    result = runner.invoke(app, args)
    assert result.exit_code == 1 and "failed 2, ok 4" in result.output, result.output
    return out


def _write_dataset(table: pa.Table, dataset: Path, cut: int) -> None:
    """``table`` as a Parquet dataset of two part files, rows ``[0, cut)`` and ``[cut, n)``: the
    first with its text columns dictionary-encoded, the second plain."""
    dataset.mkdir()
    first = table.slice(0, cut)
    columns = [c.dictionary_encode() if pa.types.is_string(c.type) else c for c in first.columns]
    pq.write_table(pa.table(columns, names=first.column_names), dataset / "part-000000000.parquet")
    pq.write_table(table.slice(cut), dataset / "part-000000001.parquet")


def parquet_form(source: Path, target: Path) -> Path:
    """A copy of the CSV-form sweep ``source`` with its tables as Parquet datasets (read from
    the CSV by Arrow, not by nlcx: an empty text is null) and without its report."""
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("metrics.csv", "sweep.csv", *REPORT))
    options = pa_csv.ConvertOptions(strings_can_be_null=True, column_types={"config_hash": pa.string()})
    for stem in STEMS:
        table = pa_csv.read_csv(source / f"{stem}.csv", convert_options=options)
        _write_dataset(table, target / f"{stem}.parquet", cut=table.num_rows // 2)
    manifest.update(target)  # the checksums of the converted directory, as nlcx records them
    return target


@pytest.fixture(scope="module")
def forms(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One sweep in the CSV form, and the same sweep converted to the Parquet form."""
    tmp = tmp_path_factory.mktemp("tables")
    csv = _sweep(_config(tmp), tmp / "csv", *CSV_FORM)
    assert {f"{stem}.csv" for stem in STEMS} <= {p.name for p in csv.iterdir()}
    return {"csv": csv, "parquet": parquet_form(csv, tmp / "parquet")}


@pytest.mark.parametrize("stem", STEMS)
def test_both_forms_read_to_the_same_frame(forms: dict[str, Path], stem: str) -> None:
    assert (forms["parquet"] / f"{stem}.parquet").is_dir() and not (forms["parquet"] / f"{stem}.csv").exists()
    csv, parquet = read_output_table(forms["csv"], stem), read_output_table(forms["parquet"], stem)
    assert_frame_equal(parquet, csv, check_exact=True)
    assert list(csv.columns) == pd.read_csv(forms["csv"] / f"{stem}.csv", nrows=0).columns.tolist()
    assert csv.variant.dtype == np.int64


def test_the_metrics_frame_keeps_nan_values_and_empty_notes(forms: dict[str, Path]) -> None:
    """value is float64 with NaN for an undefined metric; a missing note is "" (not NaN); the
    frame equals the Python API's CSV reading of metrics.csv."""
    metrics = read_output_table(forms["parquet"], "metrics")
    assert metrics.value.dtype == np.float64 and metrics.value.isna().any() and metrics.value.notna().any()
    assert metrics.note.notna().all() and (metrics.note == "").any()
    assert (metrics.note[metrics.value.isna()] != "").all()  # an undefined metric says why
    assert set(metrics.status) == {"ok"} and set(metrics.variant) == {0, 1, 2, 3}
    text = dict.fromkeys(("controller", "signal", "metric", "unit", "status", "note"), str)
    expected = pd.read_csv(forms["csv"] / "metrics.csv", dtype=text, keep_default_na=False, na_values={"value": [""]})
    assert_frame_equal(metrics, expected, check_exact=True)


def test_the_sweep_frame_keeps_hashes_as_text_and_messages(forms: dict[str, Path]) -> None:
    index = read_output_table(forms["parquet"], "sweep")
    assert list(index.variant) == list(range(6)) and index.seed.dtype == np.int64
    assert all(isinstance(h, str) and len(h) == 16 for h in index.config_hash)
    assert list(index.status) == ["ok"] * 4 + ["failed"] * 2
    assert list(index.message[:4]) == [""] * 4 and index.message[4].startswith("config error: plant.params.M")
    assert list(index["value:uncertainty.friction.model"]) == ["none", "simple"] * 3
    assert index["value:plant.params.M"].dtype == np.float64


@pytest.mark.skipif(not CSV_FORM, reason="the sweep section has no format to choose")
def test_the_sweeps_own_parquet_form_reads_as_its_csv_form(forms: dict[str, Path], tmp_path: Path) -> None:
    """What ``nlcx sweep`` writes by default reads to the frames of its CSV form."""
    out = _sweep(_config(tmp_path), tmp_path / "default")
    for stem in STEMS:
        assert (out / f"{stem}.parquet").exists() and not (out / f"{stem}.csv").exists()
        assert_frame_equal(read_output_table(out, stem), read_output_table(forms["csv"], stem), check_exact=True)


def test_part_files_are_read_in_name_order_whatever_their_types(tmp_path: Path) -> None:
    """Only ``part-*.parquet`` files, in lexicographic order; a column null in one file and
    text in another, or int32 in one and int64 in another, reads as the CSV would type it."""
    dataset = tmp_path / "sweep.parquet"
    dataset.mkdir()
    parts = {  # name -> (variants, messages)
        "part-9.parquet": ([1], pa.array([None], pa.null())),
        "part-10.parquet": ([0], pa.array(["first"])),
        "part-b.parquet": ([3], pa.array([None], pa.string()).dictionary_encode()),
        "part-a.parquet": ([2], pa.array(["third"]).dictionary_encode()),
    }
    for name, (variants, messages) in parts.items():
        width = pa.int32() if name == "part-9.parquet" else pa.int64()
        pq.write_table(pa.table({"variant": pa.array(variants, width), "message": messages}), dataset / name)
    pq.write_table(pa.table({"variant": [99], "message": ["not a part"]}), dataset / "other.parquet")
    (dataset / "_SUCCESS").write_text("")
    frame = read_output_table(tmp_path, "sweep")
    assert frame.variant.tolist() == [0, 1, 2, 3] and frame.variant.dtype == np.int64
    assert frame.message.tolist() == ["first", "", "third", ""]


def test_a_single_parquet_file_is_a_table_too(tmp_path: Path) -> None:
    table = pa.table({"variant": [0, 0], "controller": ["a", "b"], "value": pa.array([1.5, None]),
                      "note": pa.array([None, "undefined"])})  # fmt: skip
    pq.write_table(table, tmp_path / "metrics.parquet")
    frame = read_output_table(tmp_path, "metrics")
    assert frame.controller.tolist() == ["a", "b"] and frame.note.tolist() == ["", "undefined"]
    assert frame.value.iloc[0] == 1.5 and np.isnan(frame.value.iloc[1])


def test_a_missing_table_is_one_line_naming_both_files(tmp_path: Path) -> None:
    (tmp_path / "sweep.csv").write_text("variant\n0\n")
    with pytest.raises(ConfigError) as info:
        read_output_table(tmp_path, "metrics")
    message = str(info.value)
    assert "\n" not in message and str(tmp_path) in message
    assert "no metrics.parquet or metrics.csv in it" in message
    with pytest.raises(ConfigError, match="stem = 'timeseries': not a table of a sweep; allowed: metrics, sweep"):
        read_output_table(tmp_path, "timeseries")


def test_diff_finds_no_drift_between_the_two_forms(forms: dict[str, Path]) -> None:
    """Each dataset is one table (not its part files), compared with its CSV twin."""
    base, new = str(forms["csv"]), str(forms["parquet"])
    parts = [p for p in (forms["csv"] / "parts").rglob("*") if p.suffix in (".csv", ".parquet")]
    for args in ([base, new], [new, base]):
        result = runner.invoke(app, ["diff", *args, "--rtol", "0", "--atol", "0"])
        assert result.exit_code == 0, result.output
        assert f"no drift: {2 + len(parts)} file(s)" in result.output  # metrics, sweep and the batches' files
    only = runner.invoke(app, ["diff", new, base, "--only", "metrics.*", "--rtol", "0", "--atol", "0"])
    assert only.exit_code == 0 and "no drift: 1 file(s)" in only.output, only.output


def test_diff_reads_a_dataset_as_one_table_and_finds_a_moved_value(forms: dict[str, Path], tmp_path: Path) -> None:
    moved = tmp_path / "metrics.parquet"
    table = pq.read_table(forms["parquet"] / "metrics.parquet")  # the dataset, both parts
    value = table.column("value").to_numpy(zero_copy_only=False).copy()
    k = int(np.flatnonzero(~np.isnan(value))[0])
    value[k] += 1e-9
    _write_dataset(table.set_column(table.column_names.index("value"), "value", [value]), moved, cut=3)
    result = runner.invoke(app, ["diff", str(forms["csv"] / "metrics.csv"), str(moved), "--rtol", "0", "--atol", "0"])
    assert result.exit_code == 1, result.output
    assert result.output.splitlines()[-1] == "drift: 1 cell(s) in 1 of 1 file(s): metrics.csv 1"
    same = runner.invoke(app, ["diff", str(forms["parquet"] / "metrics.parquet"), str(forms["csv"] / "metrics.csv")])
    assert same.exit_code == 0 and "no drift: 1 file(s)" in same.output, same.output


def test_the_report_shows_the_same_numbers_from_either_form(forms: dict[str, Path], tmp_path: Path) -> None:
    pages = {}
    for name, source in forms.items():
        pages[name] = shutil.copytree(source, tmp_path / name, ignore=shutil.ignore_patterns(*REPORT))
        assert render.kind_of(pages[name]) == "sweep"
        result = runner.invoke(app, ["report", str(pages[name])])
        assert result.exit_code == 0, result.output
    for name in ("summary.csv", "profiles.csv", "report.md", "report_files/distributions.svg"):
        assert (pages["parquet"] / name).read_bytes() == (pages["csv"] / name).read_bytes(), name
    assert pd.read_csv(pages["parquet"] / "profiles.csv").n.sum() > 0
    for name, suffix in (("csv", ".csv"), ("parquet", ".parquet")):
        assert sweep.table_files(pages[name]) == {stem: stem + suffix for stem in STEMS}


def test_a_directory_with_the_parquet_form_is_not_ours_by_its_name(forms: dict[str, Path], tmp_path: Path) -> None:
    """Without nlcx's mark, a sweep.parquet proves nothing: the directory is refused as a target."""
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copytree(forms["parquet"] / "sweep.parquet", bare / "sweep.parquet")
    assert not rundir.written_by_nlcx(bare)
    with pytest.raises(rundir.OutputError, match="carries no nlcx mark"):
        rundir.check_target(bare)

"""Sweeps: expansion, seeds, executors, batch = single, resume, failures."""

from __future__ import annotations

import gc
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from nlcx import config, engine, rundir
from nlcx import sweeps as sweep
from nlcx.cli import app
from nlcx.sweeps import assembly, seals

ROOT = Path(__file__).resolve().parent.parent
runner = CliRunner()


def write_sweep(tmp_path: Path, sweep_section: dict, t_end: float = 3.0, name: str = "sw") -> Path:
    """The x pendulum sweep of ``sweep_section``; its tables in CSV unless the section says otherwise."""
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    raw.update(name=name, outputs={"figure": False, "timeseries": False}, sweep={"format": "csv", **sweep_section})
    raw["simulation"]["t_end"] = t_end
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


SPEC = {
    "seed": 7,
    "grid": {"controllers.proposed.loops.theta.schedule.error": ["abs", "signed"]},
    "zip": {"plant.params.m": [0.09, 0.11], "plant.params.g": [9.79, 9.81]},
    "random": {
        "n": 3,
        "params": {
            "plant.params.M": {"dist": "uniform", "relative": 0.2},
            "plant.params.l": {"dist": "normal", "mean": 0.3, "std": 0.01},
        },
    },
    "batch_size": 5,
}


def test_expansion_grid_zip_random_and_seeds(tmp_path: Path) -> None:
    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, SPEC))
    variants, hashes = sweep.plan(base_raw, spec)
    assert len(variants) == 2 * 2 * 3
    assert len(set(hashes)) == len(variants) and len({v.seed for v in variants}) == len(variants)
    m_values = [v.values["plant.params.M"] for v in variants]
    assert all(0.8 <= value <= 1.2 for value in m_values)
    assert [v.values["plant.params.m"] for v in variants[:6]] == [0.09] * 3 + [0.11] * 3
    again, _ = sweep.plan(base_raw, spec)
    assert [v.values for v in again] == [v.values for v in variants] and [v.seed for v in again] == [
        v.seed for v in variants
    ]
    seeds = np.random.SeedSequence(7).spawn(len(variants) + 1)[1:]
    assert [v.seed for v in variants] == [int(s.generate_state(1)[0]) for s in seeds]


@pytest.mark.slow
def test_one_two_and_four_workers_give_the_same_bytes(tmp_path: Path) -> None:
    """Same seed, same bits on any number of workers: metrics.csv, sweep.csv and summary.csv."""
    path = write_sweep(tmp_path, {**SPEC, "batch_size": 2}, t_end=2.0)
    outputs = []
    for jobs in (1, 2, 4):
        out = tmp_path / f"jobs{jobs}"
        result = runner.invoke(app, ["sweep", str(path), "--jobs", str(jobs), "--out", str(out)])
        assert result.exit_code == 0, result.output
        outputs.append([(out / name).read_bytes() for name in ("metrics.csv", "sweep.csv", "summary.csv")])
        assert json.loads((out / "manifest.json").read_text())["jobs"] == jobs
    assert outputs[0] == outputs[1] == outputs[2]


@pytest.mark.slow
def test_serial_pool_and_dask_give_identical_metrics(tmp_path: Path) -> None:
    path = write_sweep(tmp_path, SPEC)
    outputs = []
    for executor in ("serial", "process", "dask"):
        out = tmp_path / executor
        result = runner.invoke(app, ["sweep", str(path), "--executor", executor, "--jobs", "2", "--out", str(out)])
        assert result.exit_code == 0, result.output
        outputs.append(((out / "metrics.csv").read_bytes(), (out / "sweep.csv").read_text()))
    assert outputs[0] == outputs[1] == outputs[2]
    index = pd.read_csv(tmp_path / "serial" / "sweep.csv")
    assert list(index.variant) == list(range(12)) and set(index.status) <= {"ok", "unstable"}
    assert {"value:plant.params.M", "seed", "config_hash", "status", "message"} <= set(index.columns)
    for executor in ("serial", "process", "dask"):  # the manifest's phases add up to its wall time
        timings = json.loads((tmp_path / executor / "manifest.json").read_text())["timings_s"]
        assert set(timings) == {"plan", "batches", "assemble", "wall"} and min(timings.values()) > 0
        assert abs(timings["plan"] + timings["batches"] + timings["assemble"] - timings["wall"]) <= 0.002


def test_batch_equals_single_runs_bit_for_bit(tmp_path: Path) -> None:
    """Trajectories of variants simulated in one kernel call equal each variant run alone."""
    path = write_sweep(tmp_path, SPEC)
    base_raw, spec, _ = sweep.load(path)
    variants, hashes = sweep.plan(base_raw, spec)
    prepared = [
        engine.prepare(config.build(config.interpolate(config.apply_overrides(base_raw, v.overrides()))))
        for v in variants
    ]
    items = [item for p in prepared for item in engine.items_of(p)]
    batched = engine.simulate_items(items, prepared[0].grid, "rk4")
    assert len(batched) == 2 * len(variants)
    for k, p in enumerate(prepared):
        alone = engine.evaluate([p], measure=False)[0].runs
        assert len(alone) == 2  # conventional and proposed
        for j, run in enumerate(alone):
            other = batched[2 * k + j]
            assert np.array_equal(run.x, other.x) and np.array_equal(run.u, other.u) and run.status == other.status
    # and the metrics a sweep batch computes (vectorised over variants) equal single runs',
    # also in a second batch, with the collector on or off (a batch leaves it as it was)
    half = len(variants) // 2
    for collecting in (True, False):
        (gc.enable if collecting else gc.disable)()
        parts = [
            sweep.run_batch(sweep.Batch(base_raw, variants[s], hashes[s], tmp_path / "b", False))
            for s in (slice(0, half), slice(half, None))
        ]
        assert gc.isenabled() is collecting
        gc.enable()
        result = pd.concat([part.metrics for part in parts])
        for k in (0, 7, half, len(variants) - 1):
            single = engine.evaluate([prepared[k]])[0].metrics
            mine = result[result.variant == k].drop(columns="variant").reset_index(drop=True)
            assert list(mine.metric) == list(single.metric)
            assert np.array_equal(mine.value.to_numpy(), single.value.to_numpy(), equal_nan=True)


def test_membership_by_set_lookups_equals_pandas_isin() -> None:
    hashes = pd.Series(["a1", "b2", None, "c3", "a1", "d4"], dtype="str")
    for wanted in ({"a1", "c3"}, {"zz"}, set(), {"a1": 0, "d4": 1, "b2": 2}):
        assert list(assembly._member_of(hashes, wanted)) == list(hashes.isin(list(wanted)))


def test_failed_variant_is_recorded_the_rest_go_on(tmp_path: Path) -> None:
    path = write_sweep(tmp_path, {"grid": {"plant.params.M": [1.0, -1.0, 1.1]}})
    out = tmp_path / "fail"
    result = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 1
    index = pd.read_csv(out / "sweep.csv")
    assert list(index.status) == ["ok", "failed", "ok"]
    assert "plant.params.M" in index.message[1] and "greater than 0" in index.message[1]
    assert "variant 1 failed" in result.output


def test_metrics_joined_from_the_parts_equal_the_merged_ones(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A sweep computed in one go joins its part files into metrics.csv; reading, merging and
    writing them gives the same bytes, with failed variants, runs that did not settle (a
    note) and runs without a note in different parts; a missing note or message is an empty
    field, never the text "nan"."""
    grid = {"plant.params.M": [1.0, -1.0, 1.1], "plant.params.l": [0.3, 0.05]}
    path = write_sweep(tmp_path, {"grid": grid, "batch_size": 2})
    merged = []
    monkeypatch.setattr(assembly, "_merged_metrics", lambda *a: merged.append(1) or _merged(*a))
    out = tmp_path / "out"
    assert runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out)]).exit_code == 1
    assert merged == [], "a sweep computed in one go joins its parts"
    joined = {name: (out / name).read_bytes() for name in ("metrics.csv", "sweep.csv")}
    base_raw, spec, _ = sweep.load(path)
    variants, hashes = sweep.plan(base_raw, spec)
    sweep.assemble(out, variants, hashes, base_raw, spec)  # parts not written by this call: merged
    assert merged == [1]
    assert {name: (out / name).read_bytes() for name in joined} == joined
    metrics = pd.read_csv(out / "metrics.csv", keep_default_na=False)
    index = pd.read_csv(out / "sweep.csv", keep_default_na=False)
    assert list(index.status) == ["ok", "ok", "failed", "failed", "ok", "ok"]
    assert set(index.message[index.status == "ok"]) == {""}
    assert set(metrics.note) == {"", "did not settle within the run"}


_merged = assembly._merged_metrics


def _finished_parts(staged: Path) -> int:
    """The seals of finished batches (a part's files before its seal are an unfinished batch;
    the hidden temporary file of a seal being written is not one)."""
    return sum(not p.name.startswith(".") for p in staged.glob(f"*{seals.SEAL}"))


@pytest.mark.slow
@pytest.mark.parametrize("columnar", [True, False])
def test_resume_after_kill_recomputes_nothing_and_loses_nothing(tmp_path: Path, columnar: bool) -> None:
    """On both paths (a varied mass runs from columns unless sweep.columnar is false)."""
    spec = {
        "random": {"n": 24, "params": {"plant.params.M": {"dist": "uniform", "relative": 0.2}}},
        "batch_size": 2,
        "columnar": columnar,
    }
    path = write_sweep(tmp_path, spec, t_end=8.0)
    out = tmp_path / "resumed"
    staged = rundir.partial_dir(out) / "parts"  # where an unfinished sweep keeps its parts
    cmd = [sys.executable, "-m", "nlcx.cli", "sweep", str(path), "--executor", "serial", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    hang_guard = time.monotonic() + 600  # the wait ends on the parts directory; this only stops a hang
    try:
        while _finished_parts(staged) < 2:
            assert proc.poll() is None, f"the sweep ended (exit {proc.returncode}) before its second part"
            assert time.monotonic() < hang_guard, "no second part after 10 minutes: the sweep hangs"
            time.sleep(0.05)  # the poll's period
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the kill found the sweep still running"
    parts = _finished_parts(staged)
    assert 2 <= parts < 12, "the sweep was killed mid-way, with parts still to compute"
    assert not out.exists(), "an unfinished sweep is not in its directory"
    result = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert f"({24 - 2 * parts} computed, {2 * parts} already done)" in result.output
    again = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out)])
    assert "(0 computed, 24 already done)" in again.output
    clean = tmp_path / "clean"
    assert runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(clean)]).exit_code == 0
    assert (clean / "metrics.csv").read_bytes() == (out / "metrics.csv").read_bytes()
    assert json.loads((out / "manifest.json").read_text())["path"].startswith("columnar" if columnar else "per-variant")
    forced = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out), "--force"])
    assert "(24 computed, 0 already done)" in forced.output
    assert len(list((out / "parts").glob("*.index.*"))) == 12 and not rundir.partial_dir(out).exists()


@pytest.mark.slow
def test_a_rerun_into_a_finished_sweep_resumes_from_its_parts_of_the_same_plan(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A finished sweep's parts (and time series) of variants still in the plan are reused, the
    others are not carried into the new directory; an interrupted rerun leaves the finished
    sweep as it was; --force recomputes everything."""

    def sweep_of(masses: list[float], folder: str) -> Path:
        (tmp_path / folder).mkdir()
        return write_sweep(tmp_path / folder, {"grid": {"plant.params.M": masses}, "timeseries": True})

    def invoke(path: Path, out: Path, *extra: str) -> str:
        result = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out), *extra])
        assert result.exit_code == 0, result.output
        return result.output

    two, three, other = sweep_of([1.0, 1.1], "two"), sweep_of([1.0, 1.1, 1.2], "three"), sweep_of([1.3], "other")
    out = tmp_path / "out"
    assert "(2 computed, 0 already done)" in invoke(two, out)
    assert "(1 computed, 2 already done)" in invoke(three, out)
    invoke(three, tmp_path / "clean")
    for name in ("metrics.csv", "timeseries/variant_000000.csv", "timeseries/variant_000002.csv"):
        assert (out / name).read_bytes() == (tmp_path / "clean" / name).read_bytes()
    finished = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def interrupt(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr("nlcx.sweeps.runner.assemble", interrupt)
    interrupted = runner.invoke(app, ["sweep", str(three), "--executor", "serial", "--out", str(out), "--force"])
    assert interrupted.exit_code == 130
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == finished
    monkeypatch.undo()
    assert "(3 computed, 0 already done)" in invoke(three, out, "--force")
    assert "(1 computed, 0 already done)" in invoke(other, out)
    assert len(list((out / "parts").glob("*.index.csv"))) == 1, "the parts of another plan are not carried"
    invoke(other, tmp_path / "alone")
    assert sorted(p.name for p in (out / "timeseries").iterdir()) == ["variant_000000.csv"]
    assert (out / "timeseries" / "variant_000000.csv").read_bytes() == (
        tmp_path / "alone" / "timeseries" / "variant_000000.csv"
    ).read_bytes(), "variant 0 of the earlier plan (another mass) is not carried"


def test_dry_run_and_bad_sweep_specs(tmp_path: Path) -> None:
    path = write_sweep(tmp_path, SPEC)
    result = runner.invoke(app, ["sweep", str(path), "--dry-run"])
    assert result.exit_code == 0 and "12 variant(s) x 2 controller(s)" in result.output
    bad = write_sweep(tmp_path, {"zip": {"plant.params.M": [1, 2], "plant.params.m": [0.1]}}, name="bad")
    result = runner.invoke(app, ["sweep", str(bad), "--dry-run"])
    assert result.exit_code == 2 and "zip lists must have the same length" in result.stderr
    bad = write_sweep(tmp_path, {"random": {"n": 2, "params": {"plant.params.M": {"dist": "normal"}}}}, name="bad2")
    result = runner.invoke(app, ["sweep", str(bad), "--dry-run"])
    assert result.exit_code == 2 and "sweep.random.params.plant.params.M" in result.stderr


@pytest.mark.parametrize("timeseries", [False, True])
def test_timeseries_only_on_request(tmp_path: Path, timeseries: bool) -> None:
    path = write_sweep(tmp_path, {"grid": {"plant.params.M": [1.0, 1.1]}, "timeseries": timeseries})
    out = tmp_path / "ts"
    assert runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out)]).exit_code == 0
    files = sorted(p.name for p in (out / "timeseries").glob("*.csv")) if (out / "timeseries").exists() else []
    assert files == (["variant_000000.csv", "variant_000001.csv"] if timeseries else [])


def test_a_whole_section_can_be_varied_and_is_recorded_as_json(tmp_path: Path) -> None:
    saturation = {"limits": {"F_x": 2.5}, "anti_windup": "clamping"}
    path = write_sweep(tmp_path, {"grid": {"controllers.conventional.saturation": [None, saturation]}})
    out = tmp_path / "out"
    result = runner.invoke(app, ["sweep", str(path), "--executor", "serial", "--out", str(out)])
    assert result.exit_code == 0, result.output
    index = pd.read_csv(out / "sweep.csv", keep_default_na=False)
    assert list(index["value:controllers.conventional.saturation"]) == ["", json.dumps(saturation, sort_keys=True)]
    metrics = pd.read_csv(out / "metrics.csv")
    peak = metrics[(metrics.controller == "conventional") & (metrics.metric == "peak_input")]
    assert peak[peak.variant == 1].value.abs().max() <= 2.5 < peak[peak.variant == 0].value.abs().max()


def test_sweep_metrics_keeps_only_the_metrics_asked_for(tmp_path: Path) -> None:
    """``sweep.metrics`` keeps those rows of metrics.csv, the same values as a full sweep's, and
    is part of what identifies a result: a rerun keeping other metrics recomputes."""
    spec = {**SPEC, "random": {**SPEC["random"], "n": 2}}
    full, kept = tmp_path / "full", tmp_path / "kept"
    path = write_sweep(tmp_path, spec, t_end=2.0)
    assert runner.invoke(app, ["sweep", str(path), "--out", str(full), "--no-report", "--jobs", "1"]).exit_code == 0
    chosen = ["overshoot", "settling_time"]
    path = write_sweep(tmp_path, {**spec, "metrics": chosen}, t_end=2.0, name="kept")
    result = runner.invoke(app, ["sweep", str(path), "--out", str(kept), "--no-report", "--jobs", "1"])
    assert result.exit_code == 0, result.output
    ours, every = pd.read_csv(kept / "metrics.csv"), pd.read_csv(full / "metrics.csv")
    assert set(ours.metric) == set(chosen)
    pd.testing.assert_frame_equal(ours, every[every.metric.isin(chosen)].reset_index(drop=True))
    assert not set(pd.read_csv(kept / "sweep.csv").config_hash) & set(pd.read_csv(full / "sweep.csv").config_hash)
    bad = write_sweep(tmp_path, {**spec, "metrics": ["overshot"]}, name="bad")
    result = runner.invoke(app, ["sweep", str(bad), "--dry-run"])
    assert result.exit_code == 2 and "unknown metric 'overshot'" in result.output
    assert len(result.output.strip().splitlines()) == 1

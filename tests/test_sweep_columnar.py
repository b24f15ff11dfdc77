"""Columnar sweeps: plans as columns, values packed straight into the kernel's arrays, Parquet tables.

The columnar path must give the per-variant path's results bit for bit (the same CSV bytes),
fall back to it where a varied value is not packed as itself, and write the same bytes on any
number of workers.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from nlcx import config
from nlcx import sweeps as sweep
from nlcx.cli import app
from nlcx.sweeps import columnar, planning
from nlcx.sweeps.seeds import spawned_seeds

ROOT = Path(__file__).resolve().parent.parent
runner = CliRunner()

#: Two loops per variant; masses and lengths far enough off (+-60 %) and a tight theta bound on
#: half the grid, so that some runs stop; a conventional gain and an AGS range varied too.
MIXED = {
    "seed": 11,
    "grid": {"simulation.bounds.theta": [0.35, 3.0]},
    "zip": {"controllers.conventional.loops.theta.schedule.kp": [24.0, 36.0]},
    "random": {
        "n": 6,
        "params": {
            "plant.params.M": {"dist": "uniform", "relative": 0.6},
            "plant.params.l": {"dist": "uniform", "relative": 0.6},
            "controllers.proposed.loops.theta.schedule.kp.max": {"dist": "uniform", "low": 30, "high": 40},
        },
    },
    "batch_size": 4,
}


def write_sweep(tmp_path: Path, section: dict, name: str = "sw", t_end: float = 2.0, **extra: object) -> Path:
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    raw.update(name=name, outputs={"figure": False, "timeseries": False}, sweep=section, **extra)
    raw["simulation"]["t_end"] = t_end
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def run(path: Path, out: Path, *args: str) -> str:
    result = runner.invoke(app, ["sweep", str(path), "--out", str(out), "--no-report", *args])
    assert result.exit_code == 0, result.output
    return result.output


def how(out: Path) -> str:
    return json.loads((out / "manifest.json").read_text())["path"]


@pytest.mark.parametrize("seed", [0, 1, 2026, 2**32 - 1, 2**32 + 5, 2**70 + 3])
def test_spawned_seeds_are_numpy_s_seed_sequence_children(seed: int) -> None:
    children = np.random.SeedSequence(seed).spawn(40)
    expected = [int(c.generate_state(1)[0]) for c in children]
    assert spawned_seeds(seed, 0, 40).tolist() == expected
    assert spawned_seeds(seed, 13, 27).tolist() == expected[13:]


def test_column_plan_is_the_variant_list_as_columns(tmp_path: Path) -> None:
    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, MIXED))
    variants = planning.expand(spec, config.interpolate(base_raw))
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    assert plan is not None and plan.n == len(variants) == 2 * 2 * 6
    for v in variants:
        assert plan.variant(v.index) == v
        assert {k: type(x) for k, x in plan.values(v.index).items()} == {k: type(x) for k, x in v.values.items()}
    texts = {**MIXED, "grid": {"controllers.proposed.loops.theta.schedule.error": ["abs", "signed"]}}
    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, texts, name="texts"))
    assert planning.expand_columns(spec, config.interpolate(base_raw)) is None


def test_fast_variant_hashes_equal_the_planned_ones(tmp_path: Path) -> None:
    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, MIXED))
    _, hashes = sweep.plan(base_raw, spec)
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    assert plan is not None
    digest = planning.base_digest(base_raw, spec)
    batches = columnar.column_batches(base_raw, plan, columnar.Packing({}, 1), digest, tmp_path, 5, None)
    assert [h for b in batches for h in columnar.variant_hashes(b)] == hashes
    odd = columnar.ColumnBatch(
        {}, 3, {"a": np.array([np.inf, 1.0]), "b": np.array([2, 3])}, np.array([4, 5]), ({}, 0), None, "d", tmp_path
    )  # a non-finite value takes the JSON path
    expected = [sweep.variant_hash("d", sweep.Variant(3 + j, {"a": a, "b": b}, s))
                for j, (a, b, s) in enumerate([(np.inf, 2, 4), (1.0, 3, 5)])]  # fmt: skip
    assert columnar.variant_hashes(odd) == expected


@pytest.mark.slow
def test_columnar_and_per_variant_paths_give_the_same_bytes(tmp_path: Path) -> None:
    """Statuses, messages and every metric, bit for bit: metrics.csv and sweep.csv compared byte
    for byte, with runs that stop (a bound) among them."""
    path = write_sweep(tmp_path, {**MIXED, "format": "csv"})
    packed, configs = tmp_path / "packed", tmp_path / "configs"
    run(path, packed, "--jobs", "1")
    run(path, configs, "--jobs", "1", "sweep.columnar=false")
    assert how(packed) == "columnar" and how(configs) == "per-variant: sweep.columnar is false"
    for name in ("metrics.csv", "sweep.csv"):
        assert (packed / name).read_bytes() == (configs / name).read_bytes(), name
    statuses = json.loads((packed / "manifest.json").read_text())["status"]
    assert statuses.get("unstable", 0) > 0 and statuses.get("ok", 0) > 0


@pytest.mark.slow
def test_parquet_tables_hold_the_csv_rows_and_do_not_depend_on_the_workers(tmp_path: Path) -> None:
    path = write_sweep(tmp_path, {**MIXED, "batch_size": 2})
    outs = [tmp_path / f"jobs{j}" for j in (1, 2)]
    for jobs, out in zip((1, 2), outs, strict=True):
        run(path, out, "--jobs", str(jobs))
    for stem in ("metrics", "sweep"):
        files = [sorted((out / f"{stem}.parquet").iterdir()) for out in outs]
        assert [f.name for f in files[0]] == [f.name for f in files[1]] and len(files[0]) > 1
        assert all(a.read_bytes() == b.read_bytes() for a, b in zip(*files, strict=True))
    csv = tmp_path / "csv"
    run(path, csv, "--jobs", "1", "sweep.format=csv")
    for stem in ("metrics", "sweep"):
        table = pq.read_table(outs[0] / f"{stem}.parquet")
        plain = pa.schema([f.with_type(pa.string()) if pa.types.is_dictionary(f.type) else f for f in table.schema])
        options = pacsv.ConvertOptions(column_types=plain, strings_can_be_null=True)
        assert table.cast(plain).equals(pacsv.read_csv(csv / f"{stem}.csv", convert_options=options)), stem


@pytest.mark.parametrize(
    ("section", "extra", "reason"),
    [
        ({"grid": {"controllers.proposed.loops.theta.schedule.error": ["abs", "signed"]}}, {},
         "a varied value is not a number"),
        ({"grid": {"plant.params.M": [1.0, 1.2]}, "timeseries": True}, {}, "the sweep keeps time series"),
        ({"grid": {"plant.params.M": [1.0, 1.2]}},
         {"uncertainty": {"friction": {"kind": "friction", "model": "simple", "mu_s": 0.2, "mu_c": 0.15}}},
         "plant.params.M: it is not packed as itself"),
        ({"grid": {"simulation.dt": [0.001, 0.002]}}, {}, "simulation.dt: it changes the loops' structure"),
        ({"grid": {"uncertainty.noise.power": [1.0e-7, 2.0e-7]}},
         {"uncertainty": {"noise": {"kind": "noise", "power": 1e-7, "sample_time": 0.01, "injection": "measurement"}}},
         "the uncertainties draw from the variant's seed"),
    ],
)  # fmt: skip
def test_what_is_not_packed_as_itself_runs_config_by_config(
    tmp_path: Path, section: dict, extra: dict, reason: str
) -> None:
    """The friction's normal force is (M + m) g: a varied mass enters the arrays transformed."""
    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, section, t_end=0.1, **extra))
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    found = columnar.packing(base_raw, spec, plan)
    assert isinstance(found, str) and found.startswith(reason), found


def test_packing_finds_each_value_in_its_own_slot(tmp_path: Path) -> None:
    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, MIXED, t_end=0.1))
    found = columnar.packing(base_raw, spec, planning.expand_columns(spec, config.interpolate(base_raw)))
    assert isinstance(found, columnar.Packing)
    fields = {key: {(s.item, s.field) for s in slots} for key, slots in found.slots.items()}
    assert fields["plant.params.M"] == fields["plant.params.l"] == {(0, "p"), (1, "p")}
    assert fields["simulation.bounds.theta"] == {(0, "bounds"), (1, "bounds")}
    assert fields["controllers.conventional.loops.theta.schedule.kp"] == {(0, "cp")}
    assert fields["controllers.proposed.loops.theta.schedule.kp.max"] == {(1, "cp")}

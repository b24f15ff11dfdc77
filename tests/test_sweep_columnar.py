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


def test_a_columnar_config_hash_is_the_hash_of_the_variant_s_values_and_seed(tmp_path: Path) -> None:
    """The same values and seed give the same hash whatever the batch and the index; a value one
    ulp off, another seed or another base give another."""
    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, MIXED))
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    assert plan is not None
    digest = planning.base_digest(base_raw, spec)

    def hashes(size: int, columns: dict, seeds: np.ndarray, base: str = digest) -> list[str]:
        found = columnar.Packing({}, 1)
        batches = columnar.column_batches(
            base_raw, planning.ColumnPlan(columns, seeds), found, base, tmp_path, size, None
        )
        return [h for b in batches for h in columnar.variant_hashes(b)]

    ours = hashes(5, plan.columns, plan.seeds)
    assert ours == hashes(7, plan.columns, plan.seeds) and len(set(ours)) == plan.n
    reordered = {k: c[::-1].copy() for k, c in plan.columns.items()}
    assert hashes(3, reordered, plan.seeds[::-1].copy()) == ours[::-1]
    nudged = {**plan.columns, "plant.params.M": np.nextafter(plan.columns["plant.params.M"], np.inf)}
    assert not set(hashes(5, nudged, plan.seeds)) & set(ours)
    assert not set(hashes(5, plan.columns, plan.seeds + 1)) & set(ours)
    assert not set(hashes(5, plan.columns, plan.seeds, base="other")) & set(ours)


def test_an_ensemble_runs_the_kernel_calls_of_its_variants_items(tmp_path: Path) -> None:
    """ensemble_calls on one variant's loops equals kernel_calls on every variant's items."""
    from nlcx.engine import ensembles
    from nlcx.engine.batching import group_key, groups_of, kernel_calls

    base_raw, spec, _ = sweep.load(write_sweep(tmp_path, MIXED, t_end=0.1))
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    assert plan is not None
    items = columnar._Probe(base_raw).template(plan.values(0), int(plan.seeds[0])).items
    assert len({id(item.controller.step) for item in items}) == 2  # a constant and an AGS PID
    for n in (1, 3, 4, 8):
        expected = kernel_calls(groups_of([group_key(item) for item in items] * n), items * n)
        ours = ensembles.ensemble_calls(items, n)
        assert len(ours) == len(expected)
        for (pattern, step), call in zip(ours, expected, strict=True):
            assert step is call.step
            assert call.indices == [e * len(items) + i for e in range(n) for i in pattern]


@pytest.mark.slow
def test_columnar_and_per_variant_paths_give_the_same_bytes(tmp_path: Path) -> None:
    """Statuses, messages and every metric, bit for bit: metrics.csv compared byte for byte and
    sweep.csv cell for cell, with runs that stop (a bound) among them."""
    path = write_sweep(tmp_path, {**MIXED, "format": "csv"})
    packed, configs = tmp_path / "packed", tmp_path / "configs"
    run(path, packed, "--jobs", "1")
    run(path, configs, "--jobs", "1", "sweep.columnar=false")
    assert how(packed) == "columnar" and how(configs) == "per-variant: sweep.columnar is false"
    assert (packed / "metrics.csv").read_bytes() == (configs / "metrics.csv").read_bytes()
    # sweep.csv: the same bytes but for the config hashes, which each path computes its own way
    index = [pacsv.read_csv(out / "sweep.csv").drop_columns(["config_hash"]) for out in (packed, configs)]
    assert index[0].equals(index[1])
    statuses = json.loads((packed / "manifest.json").read_text())["status"]
    assert statuses.get("unstable", 0) > 0 and statuses.get("ok", 0) > 0


def test_a_disturbance_no_column_varies_reaches_every_variant(tmp_path: Path) -> None:
    """The disturbance is held a row per loop; every variant's loops get it, as on the
    per-variant path (metrics.csv the same bytes; all runs finish)."""
    length = {"plant.params.l": {"dist": "uniform", "relative": 0.2}}
    section = {"seed": 5, "format": "csv", "random": {"n": 3, "params": length}}
    load = {"disturbance": {"kind": "disturbance", "amplitude": 20.0, "frequency": 10.0}}
    path = write_sweep(tmp_path, section, t_end=0.5, uncertainty=load)
    packed, configs = tmp_path / "packed", tmp_path / "configs"
    run(path, packed, "--jobs", "1")
    run(path, configs, "--jobs", "1", "sweep.columnar=false")
    assert how(packed) == "columnar"
    assert (packed / "metrics.csv").read_bytes() == (configs / "metrics.csv").read_bytes()
    assert json.loads((packed / "manifest.json").read_text())["status"] == {"ok": 3}


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

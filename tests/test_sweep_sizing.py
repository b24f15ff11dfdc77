"""A sweep plan is sized before it is expanded: its variant count is exact, its memory and
disk estimates bound what nlcx really allocates and writes, and a plan that does not fit is
refused in one line before any work."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import pytest
from typer.testing import CliRunner

from nlcx import sweeps as sweep
from nlcx.cli import app
from nlcx.errors import ConfigError
from nlcx.sweeps import sizing

ROOT = Path(__file__).resolve().parent.parent
ROBUSTNESS = ROOT / "configs" / "sweeps" / "robustness.yaml"
runner = CliRunner()


@pytest.mark.parametrize(
    "overrides",
    [
        [],
        ["sweep.random.n=7"],
        ["~sweep.random", "+sweep.zip={plant.params.M: [0.9, 1.0, 1.1], plant.params.m: [0.1, 0.11, 0.12]}"],
        ["+sweep.zip={plant.params.M: [0.9, 1.0]}", "sweep.random.n=5"],
    ],
)
def test_the_variant_count_is_that_of_the_expansion(overrides: list[str]) -> None:
    base_raw, spec, _ = sweep.load(ROBUSTNESS, overrides)
    variants, _ = sweep.plan(base_raw, spec)
    assert sizing.variant_count(spec) == len(variants)


def test_the_memory_estimate_bounds_what_the_plan_allocates() -> None:
    base_raw, spec, base = sweep.load(ROBUSTNESS, ["sweep.random.n=4000"])
    size = sizing.estimate(spec, base)
    tracemalloc.start()
    try:
        variants, hashes = sweep.plan(base_raw, spec)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(variants) == len(hashes) == size.variants == 12_000
    assert peak <= size.memory <= 4 * peak  # an upper bound, not a wild one


def test_the_memory_estimate_of_a_plan_as_columns_bounds_what_its_expansion_allocates() -> None:
    from nlcx import config
    from nlcx.sweeps import planning

    base_raw, spec, base = sweep.load(ROBUSTNESS, ["~sweep.grid", "sweep.random.n=20000"])
    assert planning.numeric(spec)
    size = sizing.estimate(spec, base, columnar=True)
    interpolated = config.interpolate(base_raw)
    tracemalloc.start()
    try:
        plan = planning.expand_columns(spec, interpolated)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert plan is not None and plan.n == size.variants == 20_000
    assert peak <= size.memory <= 4 * peak
    assert size.memory * 10 < sizing.estimate(spec, base).memory  # as variants: ten times more and over


def test_the_disk_estimate_bounds_what_the_sweep_writes(tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    overrides = ["sweep.random.n=4", "simulation.t_end=2.0"]
    result = runner.invoke(app, ["sweep", str(ROBUSTNESS), *overrides, "--out", str(out), "--jobs", "1", "--no-report"])
    assert result.exit_code == 0, result.output
    _, spec, base = sweep.load(ROBUSTNESS, overrides)
    written = sum(p.stat().st_size for p in out.rglob("*") if p.is_file() and p.name != "config.yaml"
                  and p.name != "manifest.json")  # fmt: skip
    size = sizing.estimate(spec, base)
    assert written <= size.disk <= 4 * written


def test_a_plan_larger_than_memory_or_disk_is_refused_naming_its_largest_factor(tmp_path: Path) -> None:
    _, spec, base = sweep.load(ROBUSTNESS, ["sweep.random.n=1000"])
    size = sizing.check(spec, base, tmp_path, memory=10**12, disk=10**12)
    assert size.variants == 3000
    with pytest.raises(ConfigError, match=r"sweep.random.n = 1000: the plan has 3,000 variants; its expansion needs"):
        sizing.check(spec, base, tmp_path, memory=size.memory, disk=10**12)
    with pytest.raises(ConfigError, match=r"its outputs need ~.* on disk \(1 kB free under"):
        sizing.check(spec, base, tmp_path, memory=10**12, disk=1000)
    sizing.check(spec, base, None, memory=10**12, disk=1000)  # nothing written: no disk check
    _, grid_spec, _ = sweep.load(ROBUSTNESS, ["~sweep.random"])
    with pytest.raises(ConfigError, match=r"sweep.grid.uncertainty.friction.model = '3 values'"):
        sizing.check(grid_spec, base, tmp_path, memory=10, disk=10**12)


def test_a_billion_variant_sweep_is_refused_in_one_line_before_any_work(tmp_path: Path) -> None:
    out = tmp_path / "huge"
    for extra in ([], ["--dry-run"]):
        result = runner.invoke(app, ["sweep", str(ROBUSTNESS), "sweep.random.n=1000000000", "--out", str(out), *extra])
        assert result.exit_code == 2, result.output
        (line,) = result.output.strip().splitlines()  # one line, no progress bar before it
        assert line.startswith("config error: sweep.random.n = 1000000000: the plan has 3,000,000,000 variants")
        assert not out.exists()
    result = runner.invoke(app, ["validate", str(ROBUSTNESS), "sweep.random.n=1000000000"])
    assert result.exit_code == 2 and "3,000,000,000 variants" in result.output
    result = runner.invoke(app, ["validate", str(ROBUSTNESS)])
    assert result.exit_code == 0 and "a sweep of 600 variants" in result.output

"""An ensemble's metric rows: the compiled layout against rows written out one by one, and the
stopped runs' reasons against the per-run text."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from nlcx import config
from nlcx import sweeps as sweep
from nlcx.engine.ensembles import failure_rows
from nlcx.engine.metric_rows import TEXT_COLUMNS, Categories, failed_block, ok_block, ordered
from nlcx.engine.simulate import failure_reason
from nlcx.kernel.abi import STATUS_BOUND, STATUS_NONFINITE
from nlcx.sweeps import columnar, planning

ROOT = Path(__file__).resolve().parent.parent


def expected_rows(blocks: list, cats: Categories, n_variants: int, n_loops: int) -> list[tuple]:
    """Every row as (variant, value, controller, signal, metric, unit, status, note), written out
    variant by variant, loop by loop, from the blocks' own fields."""
    rows = []
    for e in range(n_variants):
        for i in range(n_loops):
            for b in blocks:
                if b.loop != i or e not in b.variants:
                    continue
                k = int(np.flatnonzero(b.variants == e)[0])
                for r in range(b.value.shape[1]):
                    v = b.value[k, r]
                    note = b.note[k] if b.note[k] >= 0 else (b.nan_note[r] if np.isnan(v) else -1)
                    rows.append((e, v, *b.pattern[r], note))
    return rows


def test_rows_are_laid_out_by_variant_then_loop_then_row() -> None:
    cats = Categories()
    rng = np.random.default_rng(3)
    n_variants = 7
    ok0 = np.array([0, 2, 3, 6])
    value0 = rng.normal(size=(ok0.size, 3))
    value0[1, 1] = np.nan  # an undefined metric: its row carries the metric's note
    rows0 = [("x", "overshoot", "%", "never crossed"), ("x", "settling_time", "s", "never settled"),
             ("F", "iae", "", "undefined")]  # fmt: skip
    stopped0 = np.array([1, 4, 5])
    blocks = [
        ok_block(ok0, 0, value0, rows0, cats, "proposed"),
        failed_block(
            stopped0,
            0,
            np.array([0.5, 1.25, 2.0]),
            ["a", "b", "a"],
            [("all", "t_fail", "s"), ("x", "settling_time", "s"), ("theta", "settling_time", "s")],
            cats,
            "proposed",
        ),
        ok_block(np.arange(n_variants), 1, rng.normal(size=(n_variants, 2)), rows0[:2], cats, "conventional"),
    ]
    out = ordered(blocks, cats, n_variants, 2)
    ours = list(zip(out.variant, out.value, *(out.codes[c] for c in TEXT_COLUMNS), strict=True))
    expected = expected_rows(blocks, cats, n_variants, 2)
    assert len(ours) == len(expected) == 4 * 3 + 3 * 3 + 7 * 2
    for got, want in zip(ours, expected, strict=True):
        assert got[0] == want[0] and tuple(got[2:]) == tuple(want[2:])
        assert got[1] == want[1] or (np.isnan(got[1]) and np.isnan(want[1]))
    unit = out.categories["unit"]
    assert "" not in unit and out.codes["unit"][2] == -1  # no unit: missing, not an empty text
    assert out.categories["note"][out.codes["note"][10 + 1]] == "never settled"  # variant 2 (rows 10..): x settling
    failed = out.codes["status"] == out.categories["status"].index("unstable")
    assert failed.sum() == 9 and set(out.variant[failed]) == {1, 4, 5}


def test_stopped_runs_share_a_reason_only_when_it_is_the_same_text(tmp_path: Path) -> None:
    """The reasons written once per distinct (status, index, time, bounds) are each run's own."""
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    mass = {"plant.params.M": {"dist": "uniform", "relative": 0.1}}
    raw.update(name="r", outputs={"figure": False, "timeseries": False})
    raw["sweep"] = {"seed": 1, "random": {"n": 2, "params": mass}}
    raw["simulation"]["t_end"] = 0.5
    path = tmp_path / "r.yaml"
    path.write_text(yaml.safe_dump(raw))
    base_raw, spec, _ = sweep.load(path)
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    assert plan is not None
    template = columnar._Probe(base_raw).template(plan.values(0), int(plan.seeds[0]))
    plant = template.prepared.plant
    rng = np.random.default_rng(0)
    n = 400
    status = rng.choice([0, STATUS_NONFINITE, STATUS_BOUND], size=n)
    n_valid = rng.integers(1, 6, size=n)
    fail_index = np.where(status == STATUS_BOUND, rng.integers(0, len(plant.states), size=n),
                          rng.integers(0, len(plant.states) + len(plant.inputs), size=n))  # fmt: skip
    bounds = np.repeat(plant.bounds[None, :], n, axis=0)
    for same in (True, False):
        if not same:  # two bound sets among the runs
            bounds[::3] *= 2.0
        rows = failure_rows(template, status, n_valid, fail_index, bounds)
        grid = template.prepared.grid
        expected = [failure_reason(plant, int(status[e]), int(fail_index[e]), float(grid.t[n_valid[e] - 1] + grid.dt),
                                    bounds[e]) for e in np.flatnonzero(status != 0)]  # fmt: skip
        assert rows.reasons == expected
        assert len(set(expected)) < len(expected)  # some are shared

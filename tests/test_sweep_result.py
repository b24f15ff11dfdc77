"""SweepResult's stability, plot and trajectories, and the sweep report's first lines, on a short
sweep in which the conventional controller is unstable in half the variants."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import nlcx
from nlcx.errors import ConfigError
from nlcx.pages.sweep import stability, summary

ROOT = Path(__file__).resolve().parent.parent
#: The x pendulum for 2 s, its conventional theta loop's kp 30 (stable) or 2 (it falls), and the
#: pendulum's length drawn within +-20 %: 2 x 2 variants, run from columns (numbers only).
MIXED = {
    "extends": str(ROOT / "configs" / "x_error_ags.yaml"),
    "name": "mixed",
    "outputs": {"figure": False, "timeseries": False},
    "simulation": {"t_end": 2.0},
    "sweep": {
        "seed": 3,
        "grid": {"controllers.conventional.loops.theta.schedule.kp": [30.0, 2.0]},
        "random": {"n": 2, "params": {"plant.params.l": {"dist": "uniform", "relative": 0.2}}},
    },
}
#: configs/sweeps/robustness.yaml for 2 s, one draw per friction model: run config by config (a text is varied).
ROBUSTNESS = ROOT / "configs" / "sweeps" / "robustness.yaml"
SHORT = ["sweep.random.n=1", "simulation.t_end=2"]


@pytest.fixture(scope="module")
def mixed(tmp_path_factory: pytest.TempPathFactory) -> nlcx.SweepResult:
    where = tmp_path_factory.mktemp("mixed")
    (where / "mixed.yaml").write_text(yaml.safe_dump(MIXED))
    return nlcx.sweep(where / "mixed.yaml", executor="serial", out=where / "sweep")


def _bits(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)


def test_stability_counts_each_controllers_runs(mixed: nlcx.SweepResult) -> None:
    table = mixed.stability()
    variants, metrics = mixed.variants, mixed.metrics
    assert list(table.index) == ["conventional", "proposed"]
    assert list(table.columns) == ["ok", "unstable", "failed", "variants", "stable_share"]
    # from the variants table: a variant is unstable when a controller's run stopped, and its message names it
    named = variants.message.str.split(":").str[0].where(variants.status == "unstable")
    assert (variants.status == "failed").sum() == 0 and (table.failed == 0).all()
    assert table.loc["conventional", "unstable"] == (named == "conventional").sum() == 2
    assert table.loc["proposed", "unstable"] == (named == "proposed").sum() == 0
    for controller, row in table.iterrows():
        mine = metrics[metrics.controller == controller]
        stopped = mine[mine.status != "ok"].variant.nunique()
        assert (row.ok, row.unstable) == (len(variants) - stopped, stopped)
        assert row.variants == len(variants) == row.ok + row.unstable + row.failed
        assert row.stable_share == row.ok / len(variants)
    assert table.loc["conventional", "stable_share"] == 0.5 and table.loc["proposed", "stable_share"] == 1.0


def test_stability_counts_a_failed_variant_for_every_controller() -> None:
    metrics = pd.DataFrame({"variant": [0, 0, 1, 1], "controller": ["a", "b", "a", "b"],
                            "status": ["ok", "ok", "ok", "unstable"]})  # fmt: skip
    index = pd.DataFrame({"variant": [0, 1, 2], "status": ["ok", "unstable", "failed"]})
    table = stability(metrics, index)
    assert table.to_dict("index") == {
        "a": {"ok": 2, "unstable": 0, "failed": 1, "variants": 3, "stable_share": 2 / 3},
        "b": {"ok": 1, "unstable": 1, "failed": 1, "variants": 3, "stable_share": 1 / 3},
    }


def test_plot_draws_a_box_per_controller_on_an_axes_per_signal(mixed: nlcx.SweepResult) -> None:
    fig = mixed.plot("ise")
    assert [ax.get_title() for ax in fig.axes] == ["x: ise over 4 variants", "theta: ise over 4 variants"]
    for ax in fig.axes:
        boxes = [p for p in ax.patches if p.get_label() in ("conventional", "proposed")]
        assert [b.get_label() for b in boxes] == ["conventional", "proposed"]  # one box each
        labels = [t.get_text() for t in ax.get_xticklabels()]
        assert labels == ["conventional\nn = 2, unstable 2", "proposed\nn = 4, unstable 0"]
    one = mixed.plot("overshoot", signal="x")
    assert len(one.axes) == 1 and one.axes[0].get_ylabel() == "overshoot (%)"
    with pytest.raises(ConfigError, match=r"metric = 'overshot': not a metric of this sweep; allowed: .*overshoot"):
        mixed.plot("overshot")
    with pytest.raises(ConfigError, match=r"signal = 'theta': no overshoot in this sweep; allowed: x$"):
        mixed.plot("overshoot", signal="theta")


def _same_as_the_sweep(run: nlcx.Result, rows: pd.DataFrame) -> None:
    """Every row the sweep has of the variant: the same status and the same bits in ``run``."""
    mine = run.metrics.set_index(["controller", "signal", "metric"])
    theirs = rows.set_index(["controller", "signal", "metric"])
    assert len(theirs) > 0 and theirs.index.isin(mine.index).all()
    again = mine.loc[theirs.index]
    np.testing.assert_array_equal(_bits(again.value.to_numpy()), _bits(theirs.value.to_numpy()))
    assert again.status.tolist() == theirs.status.astype(str).tolist()


def test_trajectories_run_a_variant_again_to_the_sweeps_bits(mixed: nlcx.SweepResult) -> None:
    runs = mixed.trajectories([3, 0])
    assert list(runs) == [3, 0]
    for index, run in runs.items():
        _same_as_the_sweep(run, mixed.metrics[mixed.metrics.variant == index].drop(columns="variant"))
        assert run.trajectory("proposed").t.iloc[-1] == 2.0
    assert runs[3].status("conventional") == "unstable" and runs[0].status("conventional") == "ok"
    only = mixed.trajectories(0, controller="proposed")[0]
    assert only.controllers == ["proposed"] and set(only.metrics.controller) == {"proposed"}
    np.testing.assert_array_equal(only.trajectory("proposed").to_numpy(), runs[0].trajectory("proposed").to_numpy())


def test_trajectories_refuse_what_is_not_a_variant_that_ran(mixed: nlcx.SweepResult) -> None:
    with pytest.raises(ConfigError, match=r"variants = 9: not a variant of this sweep; allowed: 0 to 3$"):
        mixed.trajectories([9])
    with pytest.raises(ConfigError, match=r"controller = 'lqr': not a controller of this sweep; allowed: conv"):
        mixed.trajectories([0], controller="lqr")
    detached = nlcx.SweepResult(mixed.variants, mixed.metrics, None)
    with pytest.raises(ConfigError, match=r"directory = None: a sweep written to a directory"):
        detached.trajectories([0])


def test_trajectories_run_a_per_variant_sweeps_variant_again_to_its_bits(tmp_path: Path) -> None:
    swept = nlcx.sweep(ROBUSTNESS, SHORT, executor="serial", out=tmp_path / "sweep")
    assert swept.variants["value:uncertainty.friction.model"].tolist() == ["none", "simple", "exponential"]
    runs = swept.trajectories([1, 2])
    for index, run in runs.items():
        _same_as_the_sweep(run, swept.metrics[swept.metrics.variant == index].drop(columns="variant"))


def test_trajectories_read_the_time_series_a_sweep_recorded(tmp_path: Path) -> None:
    recorded = nlcx.sweep(ROBUSTNESS, [*SHORT, "sweep.timeseries=true"], executor="serial", out=tmp_path / "sweep")
    files = sorted(p.name for p in (tmp_path / "sweep" / "timeseries").iterdir())
    assert [f.split(".")[0] for f in files] == ["variant_000000", "variant_000001", "variant_000002"]
    rows = recorded.metrics[recorded.metrics.variant == 2].drop(columns="variant")
    (read,) = recorded.trajectories([2]).values()
    _same_as_the_sweep(read, rows)
    assert len(read.metrics) == len(rows)  # the sweep's rows, as read
    # the same directory without its time series: the variant is run again, to the same samples
    shutil.copytree(tmp_path / "sweep", tmp_path / "bare")
    shutil.rmtree(tmp_path / "bare" / "timeseries")
    bare = nlcx.SweepResult(recorded.variants, recorded.metrics, tmp_path / "bare")
    (again,) = bare.trajectories([2]).values()
    assert again.controllers == read.controllers == ["conventional", "proposed"]
    for controller in read.controllers:
        mine, theirs = read.trajectory(controller), again.trajectory(controller)
        assert list(mine.columns) == list(theirs.columns) and len(mine) == 2001
        np.testing.assert_array_equal(_bits(mine.to_numpy()), _bits(theirs.to_numpy()))


def test_the_sweep_report_opens_with_the_robustness_answer(mixed: nlcx.SweepResult) -> None:
    assert mixed.directory is not None
    md = (mixed.directory / "report.md").read_text().splitlines()
    first = [line for line in md[1:] if line.strip()][:2]
    table = mixed.stability()
    expected = "unstable: " + ", ".join(f"{r.Index} {r.unstable} of {r.variants}" for r in table.itertuples())
    assert expected == "unstable: conventional 2 of 4, proposed 0 of 4"
    assert f"**{expected}**" in first
    html = (mixed.directory / "report.html").read_text()
    main = html.split("<main>")[1]
    assert main.index(expected) < main.index('id="side-by-side"') < main.index('id="summary-table"')
    shares = [float(v) for v in re.findall(r'data-stable-share="([^"]*)"', html)]
    assert shares == table.stable_share.tolist()
    side = [float(v) for v in re.findall(r'data-side-median="([^"]*)"', html)]
    medians = summary(mixed.metrics, mixed.variants).set_index(["signal", "metric", "controller"])
    ordered = [
        medians.loc[(signal, metric, c), "median"]
        for signal, metric in dict.fromkeys((s, m) for s, m, _ in medians.index)
        for c in ("conventional", "proposed")
        if (signal, metric, c) in medians.index and medians.loc[(signal, metric, c), "n"] > 0
    ]
    assert len(ordered) > 20
    np.testing.assert_array_equal(side, ordered)
    header = next(line for line in md if line.startswith("| signal | metric | unit |"))
    assert header == "| signal | metric | unit | conventional | proposed |"

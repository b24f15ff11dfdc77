"""Result.compare's table (nlcx.Comparison): the change % and the better markers checked against
independent computations from the long metrics, its printed form within 80 columns for two and
three controllers, its pandas behaviour, and the run report's first lines."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import nlcx
from nlcx.cli import app
from nlcx.comparison import DIRECTIONS, NEARER_ZERO, SMALLER, TIE, UNDIRECTED
from nlcx.comparison_frame import Comparison, compare
from nlcx.metrics.names import ERROR_METRICS, INPUT_METRICS, METRIC_UNITS, STEP_INFO_UNITS

ROOT = Path(__file__).resolve().parent.parent
X_CONFIG = ROOT / "configs" / "x_error_ags.yaml"
SHORT = ["simulation.t_end=2"]
#: A third controller beside the config's two: time-AGS PID with the ranges and rates of Table 2.2.
TIME_AGS = {
    "kind": "pid",
    "loops": {
        "theta": {"sign": -1, "schedule": {"kind": "time_ags", "kp": {"min": 24, "max": 36},
                  "ki": {"min": 1.5, "max": 3.6}, "kd": {"min": 3, "max": 5},
                  "rate": {"kp": 0.1, "ki": 0.1, "kd": 0.05}}},
        "x": {"sign": 1, "schedule": {"kind": "time_ags", "kp": {"min": -3, "max": -2.4},
              "ki": {"min": -1.2, "max": -1}, "kd": {"min": -4.8, "max": -2},
              "rate": {"kp": 0.1, "ki": 0.1, "kd": 0.25}}},
    },
}  # fmt: skip


@pytest.fixture(scope="module")
def two() -> nlcx.Result:
    return nlcx.run(X_CONFIG, SHORT)


@pytest.fixture(scope="module")
def three() -> nlcx.Result:
    return nlcx.run(X_CONFIG, {"simulation": {"t_end": 2.0}, "controllers": {"time_ags": TIME_AGS}})


def _long(result: nlcx.Result) -> dict[tuple[str, str, str], float]:
    return {
        (c, s, m): v
        for c, s, m, v in result.metrics[["controller", "signal", "metric", "value"]].itertuples(index=False)
    }


def test_every_metric_nlcx_reports_has_a_direction_or_is_listed_without_one() -> None:
    named = set(METRIC_UNITS) | set(STEP_INFO_UNITS) | {"t_fail"}
    assert set(DIRECTIONS) | set(UNDIRECTED) == named
    assert not set(DIRECTIONS) & set(UNDIRECTED)
    assert all(DIRECTIONS[m] == SMALLER for m in (*ERROR_METRICS, *INPUT_METRICS))
    assert DIRECTIONS["steady_state_error"] == NEARER_ZERO
    assert all(DIRECTIONS[m] == SMALLER for m in ("rise_time", "settling_time", "overshoot", "peak_deviation"))


@pytest.mark.parametrize("which", ["two", "three"])
def test_the_printed_table_fits_80_columns_and_names_every_controller(which: str, request: Any) -> None:
    result: nlcx.Result = request.getfixturevalue(which)
    table = result.compare()
    text = repr(table)
    assert str(table) == text
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "..." not in text  # nothing elided
    assert len(result.controllers) == (2 if which == "two" else 3)
    for controller in result.controllers:
        assert re.search(rf"\b{controller}\b", text)
    for signal, metric in table.index:
        assert re.search(rf"^\s+{metric}\s", text, re.MULTILINE), (signal, metric)
    for line in table.verdicts():
        assert line.split(":")[0] in {"x", "theta"}
        assert line in text.replace("\n  ", " ")  # the verdict, as wrapped


@pytest.mark.parametrize("which", ["two", "three"])
def test_change_is_100_times_other_minus_baseline_over_its_magnitude(which: str, request: Any) -> None:
    result: nlcx.Result = request.getfixturevalue(which)
    table = result.compare()
    long = _long(result)
    baseline, *others = result.controllers
    assert list(table.columns) == ["unit", *result.controllers, *(f"change_{c}_pct" for c in others), "better"]
    checked = 0
    for (signal, metric), row in table.iterrows():
        first = long[(baseline, signal, metric)]
        for other in others:
            value = long[(other, signal, metric)]
            if first == 0 or math.isnan(first) or math.isnan(value):
                assert math.isnan(row[f"change_{other}_pct"])
            else:
                assert row[f"change_{other}_pct"] == pytest.approx((value - first) / abs(first) * 100, rel=1e-12)
                checked += 1
    assert checked >= len(table) - 2  # all but the settling times (none within 2 s)


@pytest.mark.parametrize("which", ["two", "three"])
def test_better_follows_each_metrics_direction(which: str, request: Any) -> None:
    result: nlcx.Result = request.getfixturevalue(which)
    table = result.compare(list(dict.fromkeys(result.metrics.metric)))  # every metric of the run
    long = _long(result)
    marked = 0
    for (signal, metric), row in table.iterrows():
        values = {c: long.get((c, signal, metric), math.nan) for c in result.controllers}
        direction = DIRECTIONS.get(metric)
        if direction is None:
            assert row.better == "", metric
            continue
        key = {c: (math.inf if math.isnan(v) else abs(v) if direction == NEARER_ZERO else v) for c, v in values.items()}
        if sum(not math.isnan(v) for v in values.values()) == 0:
            assert row.better == ""
            continue
        if metric not in ("rise_time", "settling_time") and sum(not math.isnan(v) for v in values.values()) < 2:
            assert row.better == ""
            continue
        best = min(key.values())
        winners = [c for c, v in key.items() if v == best]
        assert row.better == (winners[0] if len(winners) == 1 else TIE), (signal, metric, values)
        marked += 1
    assert marked >= 10 and set(table.better) - {"", TIE} <= set(result.controllers)


def test_verdicts_count_the_better_markers(three: nlcx.Result) -> None:
    table = three.compare()
    for line, (signal, rows) in zip(table.verdicts(), table.groupby(level="signal", sort=False), strict=True):
        marked = [b for b in rows.better if b]
        counts = {c: marked.count(c) for c in three.controllers}
        first = max(counts, key=lambda c: counts[c])
        assert line.startswith(f"{signal}: {first} better on {counts[first]} of {len(marked)} metric")
        for c in three.controllers:
            assert f"{c} " in line and str(counts[c]) in line


def test_it_stays_a_dataframe_and_round_trips_through_csv(two: nlcx.Result, tmp_path: Path) -> None:
    table = two.compare()
    assert isinstance(table, Comparison) and isinstance(table, pd.DataFrame)
    assert type(table.round(3)) is Comparison and table.round(3).statuses == table.statuses
    assert (
        type(table.loc[["x"]]) is Comparison and len(table.loc[["x"]]) == (table.index.get_level_values(0) == "x").sum()
    )
    assert type(table.loc[("x", "overshoot")]) is pd.Series
    assert type(table["proposed"]) is pd.Series
    narrowed = table[["unit", "proposed"]]
    assert max(len(line) for line in repr(narrowed).splitlines()) <= 80 and "change %" not in repr(narrowed)
    flat = table.reset_index()  # no longer a comparison: printed as pandas prints it
    assert repr(flat) == repr(pd.DataFrame(flat))
    table.to_csv(tmp_path / "compare.csv")
    back = pd.read_csv(tmp_path / "compare.csv", index_col=[0, 1], keep_default_na=False, na_values=[""])
    np.testing.assert_array_equal(back[["conventional", "proposed"]].to_numpy(), table[["conventional", "proposed"]])
    assert back.better.fillna("").tolist() == table.better.tolist()


def test_the_notebook_table_is_compact_html_with_every_controller(three: nlcx.Result) -> None:
    page = three.compare()._repr_html_()
    assert page is not None and page.count("<table") == 1 and "..." not in page
    for c in three.controllers:
        assert f"<th>{c}</th>" in page
    for line in three.compare().verdicts():
        assert line in page
    assert "<b>" in page  # the better values
    assert three._repr_html_().count("<table") == 1


def test_a_controller_that_stopped_is_not_compared() -> None:
    rows = [("a", "x", "overshoot", 10.0, "%", "ok"), ("b", "x", "overshoot", math.nan, "%", "unstable"),
            ("a", "x", "rise_time", 1.0, "s", "ok"), ("b", "x", "rise_time", math.nan, "s", "unstable")]  # fmt: skip
    metrics = pd.DataFrame(rows, columns=["controller", "signal", "metric", "value", "unit", "status"])
    table = compare(metrics)
    assert table.better.tolist() == ["", ""]
    assert table.verdicts() == ["x: no metric compared, b unstable"]
    assert "unstable" in repr(table).splitlines()[-1]  # b's cell says why it has no value


def test_the_run_report_opens_with_one_line_per_signal(tmp_path: Path) -> None:
    out = tmp_path / "run"
    done = CliRunner().invoke(app, ["run", str(X_CONFIG), *SHORT, "--out", str(out)])
    assert done.exit_code == 0, done.output
    expected = nlcx.load_run(out).compare().verdicts()
    assert [line.split(":")[0] for line in expected] == ["x", "theta"]
    md = (out / "report.md").read_text().splitlines()
    body = [line for line in md[1:] if line.strip()]
    assert body[1:3] == expected  # after the caption: the verdicts, before "## Comparison"
    assert body[3] == "## Comparison"
    html = (out / "report.html").read_text()
    main = html.split("<main>")[1]
    assert main.index('<section id="verdicts">') < main.index('<section id="comparison">')
    assert re.findall(r'<p class="verdict">([^<]*)</p>', html) == expected

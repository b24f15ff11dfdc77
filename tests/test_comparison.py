"""nlcx.comparison: the change %, the thesis's improvement % and the controllers-side-by-side
table, checked against numbers worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from nlcx import comparison
from nlcx.comparison import THESIS_METRICS, change, thesis_improvement
from nlcx.comparison_frame import compare
from nlcx.errors import NlcxError
from nlcx.thesis import tables


def test_thesis_improvement_is_the_thesis_formula_and_nan_where_undefined() -> None:
    assert thesis_improvement(2.0, 1.6) == pytest.approx(25.0)  # (2 - 1.6) / 1.6 = 0.25
    assert thesis_improvement(1.0, 2.0) == pytest.approx(-50.0)  # the later controller is worse
    assert thesis_improvement(3.0, 3.0) == 0.0
    assert math.isnan(thesis_improvement(1.0, 0.0)) and math.isnan(thesis_improvement(1.0, math.nan))
    assert math.isnan(thesis_improvement(math.nan, 2.0))
    assert tables.thesis_improvement is thesis_improvement  # one home for the formula


def test_change_is_against_the_baseline_s_magnitude_and_nan_where_undefined() -> None:
    assert change(2.0, 1.6) == pytest.approx(-20.0)  # (1.6 - 2) / 2
    assert change(1.0, 2.0) == pytest.approx(100.0)
    assert change(-2.0, -1.0) == pytest.approx(50.0)  # (-1 - -2) / |-2|
    assert change(3.0, 3.0) == 0.0
    assert math.isnan(change(0.0, 1.0)) and math.isnan(change(1.0, math.nan)) and math.isnan(change(math.nan, 1.0))


def frame(rows: list[tuple[str, str, str, float, str, str]]) -> pd.DataFrame:
    """A metrics.csv frame from (controller, signal, metric, value, unit, status) rows."""
    out = pd.DataFrame(rows, columns=["controller", "signal", "metric", "value", "unit", "status"])
    return out.assign(note="")


#: Three controllers on a step in x and theta regulated to 0; c stopped (its rows as nlcx writes them).
METRICS = frame(
    [("a", "x", "rise_time", 2.0, "s", "ok"), ("a", "x", "overshoot", 30.0, "%", "ok"),
     ("a", "x", "undershoot", 1.0, "%", "ok"), ("a", "x", "ise", 0.6, "m^2*s", "ok"),
     ("a", "theta", "peak_deviation", 0.1, "rad", "ok"), ("a", "theta", "settling_time", math.nan, "s", "ok"),
     ("b", "x", "rise_time", 2.5, "s", "ok"), ("b", "x", "overshoot", 20.0, "%", "ok"),
     ("b", "x", "undershoot", 2.0, "%", "ok"), ("b", "x", "ise", 0.0, "m^2*s", "ok"),
     ("b", "theta", "peak_deviation", 0.05, "rad", "ok"), ("b", "theta", "settling_time", 4.0, "s", "ok"),
     ("c", "all", "t_fail", 1.2, "s", "unstable"), ("c", "x", "settling_time", math.nan, "s", "unstable"),
     ("c", "theta", "settling_time", math.nan, "s", "unstable")]
)  # fmt: skip


def test_compare_sets_the_controllers_side_by_side_with_the_change_of_each_later_one() -> None:
    table = compare(METRICS)
    assert table.index.names == ["signal", "metric"]
    assert list(table.index) == [("x", "rise_time"), ("x", "overshoot"), ("x", "ise"), ("x", "settling_time"),
                                 ("theta", "peak_deviation"), ("theta", "settling_time")]  # fmt: skip
    assert list(table.columns) == ["unit", "a", "b", "c", "change_b_pct", "change_c_pct", "better"]
    assert table.unit.tolist() == ["s", "%", "m^2*s", "s", "rad", "s"]
    np.testing.assert_array_equal(table.a, [2.0, 30.0, 0.6, np.nan, 0.1, np.nan])
    np.testing.assert_array_equal(table.b, [2.5, 20.0, 0.0, np.nan, 0.05, 4.0])
    np.testing.assert_array_equal(table.c, [np.nan] * 6)  # stopped: nothing to compare
    # 100 (b - a) / |a| by hand: (2.5 - 2) / 2 = 25 %, (20 - 30) / 30 = -33.3 %, (0 - 0.6) / 0.6 = -100 %,
    # x's settling time only c (stopped) has, (0.05 - 0.1) / 0.1 = -50 %, a never settled: undefined.
    np.testing.assert_allclose(table.change_b_pct, [25.0, -100 / 3, -100.0, np.nan, -50.0, np.nan], rtol=1e-12)
    assert table.change_c_pct.isna().all()
    # smaller is better; c stopped is not compared; a never settled, b did: b is better
    assert table.better.tolist() == ["a", "b", "b", "", "b", "b"]
    assert all(table[c].dtype == float for c in table.columns if c not in ("unit", "better"))


def test_compare_takes_exactly_the_metrics_named_and_says_which_names_are_unknown() -> None:
    table = compare(METRICS, ["undershoot", "t_fail"])
    assert list(table.index) == [("x", "undershoot"), ("all", "t_fail")]
    np.testing.assert_array_equal(table.a, [1.0, np.nan])
    assert table.change_b_pct.iloc[0] == pytest.approx(100.0)  # (2 - 1) / 1
    with pytest.raises(NlcxError) as error:
        compare(METRICS, ["ise", "overshot", "itae"])
    message = str(error.value)
    assert "\n" not in message and "'overshot'" in message and "'itae'" in message
    assert "allowed: rise_time, overshoot, undershoot, ise, peak_deviation, settling_time, t_fail" in message


def test_compare_defaults_to_the_thesis_metrics_present() -> None:
    assert THESIS_METRICS == ("rise_time", "settling_time", "overshoot", "peak", "peak_deviation", "ise", "iae", "itae")
    assert set(compare(METRICS).index.get_level_values("metric")) == {
        "rise_time", "overshoot", "ise", "peak_deviation", "settling_time"
    }  # fmt: skip


def test_compare_refuses_the_rows_of_several_runs_and_frames_without_metric_columns() -> None:
    with pytest.raises(NlcxError, match=r"\('a', 'x', 'ise'\) appears twice"):
        compare(pd.concat([METRICS, METRICS.iloc[[3]]]))
    with pytest.raises(NlcxError, match=r"lacks the columns \['metric'\]"):
        compare(METRICS.drop(columns="metric"))


def test_the_pages_comparison_is_compares_table() -> None:
    records = [{**r, "value": float(r["value"])} for r in METRICS.to_dict("records")]
    side_by_side = comparison.comparison(records)
    table = compare(METRICS)
    assert side_by_side.controllers == ("a", "b", "c")
    assert side_by_side.status == {"a": "ok", "b": "ok", "c": "unstable"}
    assert [(r.signal, r.metric) for r in side_by_side.rows] == list(table.index)
    np.testing.assert_array_equal([r.values for r in side_by_side.rows], table[["a", "b", "c"]].to_numpy())
    np.testing.assert_array_equal(
        [r.changes for r in side_by_side.rows], table[["change_b_pct", "change_c_pct"]].to_numpy()
    )
    assert [r.better for r in side_by_side.rows] == table.better.tolist()

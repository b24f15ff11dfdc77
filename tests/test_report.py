"""`nlcx report`: the numbers on each page equal the CSVs it summarises, verdicts follow the
declared tolerances, and run, sweep and reproduce write their page at the end."""

from __future__ import annotations

import math
import re
from html import unescape
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from nlcx import manifest
from nlcx.cli import app
from nlcx.comparison import THESIS_METRICS
from nlcx.results import read_output_table
from nlcx.thesis.pages.tables import cells_of
from nlcx.thesis.pages.tolerances import load as load_tolerances

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
TOLERANCES = CONFIGS / "thesis" / "tolerances.yaml"
runner = CliRunner()


def test_a_run_writes_a_page_whose_metrics_are_metrics_csv(tmp_path: Path) -> None:
    out = tmp_path / "run"
    args = ["run", str(CONFIGS / "x_error_ags.yaml"), "simulation.t_end=8", "--out", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    html = (out / "report.html").read_text()
    metrics = pd.read_csv(out / "metrics.csv")
    shown = [float(v) if v else math.nan for v in re.findall(r'data-value="([^"]*)"', html)]
    np.testing.assert_array_equal(np.array(shown), metrics.value.to_numpy())
    assert '<img class="figure" src="./figure.png"' in html and "Resolved config" in html
    assert (out / "report.md").read_text().count("\n| conventional |") == (metrics.controller == "conventional").sum()
    skipped = tmp_path / "quiet"
    result = runner.invoke(app, [*args[:-1], str(skipped), "--no-report"])
    assert result.exit_code == 0 and not (skipped / "report.html").exists()


def _thesis_rows(metrics: pd.DataFrame) -> list[tuple[str, str, float, float]]:
    """(signal, metric, conventional, proposed) of the thesis's metrics, in metrics.csv's order."""
    values = metrics.set_index(["controller", "signal", "metric"]).value
    keys = metrics[metrics.metric.isin(THESIS_METRICS)][["signal", "metric"]].drop_duplicates()
    return [(s, m, values[("conventional", s, m)], values[("proposed", s, m)]) for s, m in keys.itertuples(index=False)]


def test_a_runs_page_leads_with_the_comparison_then_the_figure_then_the_long_table(tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = runner.invoke(app, ["run", str(CONFIGS / "x_error_ags.yaml"), "simulation.t_end=8", "--out", str(out)])
    assert result.exit_code == 0, result.output
    html = (out / "report.html").read_text()
    md = (out / "report.md").read_text()
    marks = ['<section id="comparison">', '<section id="figures">', '<details id="metrics-details">',
             'id="metrics-table"', '<section id="config">', '<section id="manifest">']  # fmt: skip
    assert [html.index(m) for m in marks] == sorted(html.index(m) for m in marks)
    marks = ["## Comparison", "![figure.png](./figure.png)", "## Metrics", "## Resolved config"]
    assert [md.index(m) for m in marks] == sorted(md.index(m) for m in marks)
    rows = _thesis_rows(pd.read_csv(out / "metrics.csv"))
    assert {(s, m) for s, m, _, _ in rows} >= {("x", "overshoot"), ("x", "peak"), ("theta", "peak_deviation")}
    shown = [float(v) for v in re.findall(r'data-compare="([^"]*)"', html)]
    np.testing.assert_array_equal(shown, [v for _, _, c, p in rows for v in (c, p)])
    changes = [float(v) for v in re.findall(r'data-change="([^"]*)"', html)]
    by_hand = [100 * (p - c) / abs(c) for _, _, c, p in rows]  # 100 (proposed - conventional) / |conventional|
    np.testing.assert_allclose(changes, by_hand, rtol=1e-12)
    for text in (unescape(re.sub(r"<[^>]+>", "", html)), md):
        assert "100 (other − baseline) / |baseline|" in text and "negative where the other controller" in text
    _, _, c, p = rows[0]
    better = "proposed" if p < c else "conventional"  # rise time: smaller is better
    assert f"| rise_time | s | {c:.4g} | {p:.4g} | {100 * (p - c) / abs(c):.3g} | {better} |" in md


def test_a_controller_whose_run_stopped_shows_its_status_in_the_comparison(tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = runner.invoke(app, ["run", str(CONFIGS / "x_error_ags.yaml"), "simulation.t_end=2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    metrics = pd.read_csv(out / "metrics.csv")
    reason = "diverged at t = 1.5 s: |theta| > 1.5708 (simulation.bounds)"
    stopped = pd.DataFrame(  # the rows `nlcx run` writes for a run that stopped
        [["conventional", "all", "t_fail", 1.5, "s", "unstable", reason]]
        + [["conventional", s, "settling_time", math.nan, "s", "unstable", reason] for s in ("x", "theta")],
        columns=metrics.columns,
    )
    pd.concat([stopped, metrics[metrics.controller == "proposed"]]).to_csv(out / "metrics.csv", index=False)
    manifest.update(out, ["metrics.csv"])  # as nlcx records the rows of a stopped run
    assert runner.invoke(app, ["report", str(out)]).exit_code == 0
    html = (out / "report.html").read_text()
    proposed = metrics[(metrics.controller == "proposed") & metrics.metric.isin(THESIS_METRICS)]
    assert html.count('<td class="status">unstable</td>') == len(proposed)
    assert re.findall(r'data-change="([^"]*)"', html) == ["nan"] * len(proposed)
    assert re.findall(r'data-better="([^"]*)"', html) == [""] * len(proposed)  # nothing to compare with
    assert "conventional</b>: diverged at t = 1.5 s: |theta| &gt; 1.5708" in html
    shown = [float(v) for v in re.findall(r'data-compare="([^"]*)"', html)]
    np.testing.assert_array_equal(np.sort(shown), np.sort(proposed.value.to_numpy()))  # only the proposed's
    md = (out / "report.md").read_text()
    assert "- conventional: unstable (diverged at t = 1.5 s: \\|theta\\| &gt; 1.5708 (simulation.bounds))" in md
    assert md.split("## Metrics")[0].count("| unstable |") == len(proposed)  # the comparison's cells


@pytest.mark.slow
def test_the_robustness_sweeps_page_is_its_metrics_aggregated(tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    cfg = str(CONFIGS / "sweeps" / "robustness.yaml")
    result = runner.invoke(app, ["sweep", cfg, "sweep.random.n=8", "--out", str(out), "--jobs", "2"])
    assert result.exit_code == 0, result.output
    metrics = read_output_table(out, "metrics")
    summary = pd.read_csv(out / "summary.csv")
    assert len(summary) == metrics.groupby(["controller", "signal", "metric"]).ngroups > 0
    for row in summary.itertuples(index=False):
        values = metrics[(metrics.controller == row.controller) & (metrics.signal == row.signal)
                         & (metrics.metric == row.metric)]  # fmt: skip
        assert row.unstable == (values.status != "ok").sum()
        assert row.undefined == ((values.status == "ok") & values.value.isna()).sum()
        values = values[values.status == "ok"].value.dropna()
        assert row.n == len(values)
        assert row.median == pytest.approx(values.median(), rel=1e-12, nan_ok=True)
        assert row.q25 == pytest.approx(values.quantile(0.25), rel=1e-12, nan_ok=True)
        assert (row.min, row.max) == (values.min(), values.max()) or len(values) == 0
    html = (out / "report.html").read_text()
    medians = [float(v) for v in re.findall(r'data-median="([^"]*)"', html)]
    np.testing.assert_array_equal(np.array(medians), summary["median"].to_numpy())
    assert html.count('<svg class="sweep-chart"') == 5  # distributions; friction model, M, m, l
    assert "<img" not in html.split('id="distributions"')[1]  # charts inline, no image files
    profiles = pd.read_csv(out / "profiles.csv")
    index = read_output_table(out, "sweep")
    ok = metrics[(metrics.status == "ok") & metrics.value.notna()]
    for row in profiles.sample(n=40, random_state=0).itertuples(index=False):
        column = index[f"value:{row.parameter}"]
        if pd.api.types.is_numeric_dtype(column) and column.nunique() > 20:  # 20 equal-width bins
            edges = np.linspace(column.min(), column.max(), 21)
            low, high = edges[row.bin], edges[row.bin + 1]
            inside = (column >= low) & ((column < high) if row.bin < 19 else (column <= high))
        elif pd.api.types.is_numeric_dtype(column):  # each distinct value, ascending
            inside = column == sorted(column.unique())[row.bin]
        else:  # each level, in order of first appearance
            inside = column.astype(str) == str(row.at)
        variants = index.variant[inside]
        values = ok[(ok.controller == row.controller) & (ok.signal == row.signal) & (ok.metric == row.metric)
                    & ok.variant.isin(variants)].value.astype(float)  # fmt: skip
        assert row.n == len(values)
        assert row.median == pytest.approx(values.median(), rel=1e-12)
        assert (row.q25, row.q75) == pytest.approx((values.quantile(0.25), values.quantile(0.75)), rel=1e-12)
    assert "3 distinct values: none, simple, exponential" in html  # the grid of robustness.yaml
    assert "| conventional | x | rise_time |" in (out / "report.md").read_text()


def test_a_large_sweep_s_profiles_come_from_every_kth_variant(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Above PROFILE_VARIANTS variants the profiles read every k-th variant (index a multiple of
    k), the same numbers as the profiles of those variants' rows alone; the summary reads all."""
    from nlcx.pages import render, sweep_charts

    out = tmp_path / "sweep"
    cfg = str(CONFIGS / "sweeps" / "robustness.yaml")
    assert runner.invoke(app, ["sweep", cfg, "sweep.random.n=4", "--out", str(out), "--jobs", "1"]).exit_code == 0
    full = pd.read_csv(out / "summary.csv")
    monkeypatch.setattr(sweep_charts, "PROFILE_VARIANTS", 5)  # 12 variants: every 3rd
    render.write_report(out)
    profiles = pd.read_csv(out / "profiles.csv")
    metrics, index = read_output_table(out, "metrics"), read_output_table(out, "sweep")
    categories = {c: "category" for c in ("controller", "signal", "metric", "status")}
    kept = metrics[metrics.variant % 3 == 0].astype(categories)
    expected, _ = sweep_charts.profiles(kept, index, "value:plant.params.M")
    mine = profiles[profiles.parameter == "plant.params.M"].reset_index(drop=True)
    pd.testing.assert_frame_equal(mine, expected.astype({"bin": "int64"}), check_dtype=False)
    ok = kept[(kept.status == "ok") & kept.value.notna()]
    assert mine.n.sum() == len(ok) < len(metrics[(metrics.status == "ok") & metrics.value.notna()])
    pd.testing.assert_frame_equal(pd.read_csv(out / "summary.csv"), full)
    assert "Drawn from the variants whose index is a multiple of 3, one in 3" in (out / "report.html").read_text()


def test_cells_are_judged_by_their_metrics_declared_tolerance() -> None:
    tolerances = load_tolerances(TOLERANCES)
    frame = pd.DataFrame(
        {
            "signal": ["x", "x", "x", "x"],
            "metric": ["tr", "tr", "Mp", "kp_min"],
            "controller": ["conventional"] * 4,
            "thesis": [2.0, 2.0, 0.5, 24.0],
            "nlcx": [2.39, 2.41, np.nan, 24.0],
        }
    )
    within = [c.within for c in cells_of(frame, tolerances)]
    assert within == [True, False, False, True]  # 20 % of 2.0 s; a failed cell is never within
    assert tolerances.verdict(9, 10) == "reproduced" and tolerances.verdict(5, 10) == "partly"
    assert tolerances.verdict(4, 10) == "not" and tolerances.verdict(0, 0) == "n/a"
    paired = pd.DataFrame({"set": ["NB"], "nlcx_lower": [-0.36], "thesis_lower": [-0.36], "nlcx_upper": [0.2],
                           "thesis_upper": [0.168]})  # fmt: skip
    assert [(c.label, c.within) for c in cells_of(paired, tolerances)] == [("NB · lower", True), ("NB · upper", False)]


@pytest.mark.slow
def test_a_reproductions_page_and_twin_carry_the_claims_and_the_table_verdicts(reproduction: Path) -> None:
    claims = pd.read_csv(reproduction / "claims.csv").reproduced.value_counts()
    html = unescape((reproduction / "report.html").read_text())
    for verdict in ("yes", "partly", "no"):
        assert f'data-claims="{verdict}">{verdict} {claims.get(verdict, 0)}<' in html
    summary = pd.read_csv(reproduction / "report_summary.csv")
    tolerances = load_tolerances(TOLERANCES)
    table = pd.read_csv(reproduction / "tables" / "table_2_3.csv")
    cells = cells_of(table, tolerances)
    row = summary[summary.table == "Table 2.3"].iloc[0]
    assert (row.cells, row.within_tolerance) == (len(cells), sum(c.within for c in cells))
    assert row.verdict == tolerances.verdict(row.within_tolerance, row.cells)
    md = (reproduction / "report.md").read_text()
    assert f"| Table 2.3 | {row.cells} | {row.within_tolerance} | {row.verdict} |" in md
    assert "Claims: " in md and f"yes {claims.get('yes', 0)}" in md
    assert html.count("<figure id=") == 95 and "missing 0" in html
    manifest = (reproduction / "manifest.json").read_text()
    assert '"profile": "literal"' in manifest and '"wall_s"' in manifest


def test_report_on_a_directory_that_is_none_of_ours_is_a_one_line_error(tmp_path: Path) -> None:
    result = runner.invoke(app, ["report", str(tmp_path)])
    assert result.exit_code == 2
    assert result.output.splitlines() == [
        f"output error: DIR = '{tmp_path}': is not an output directory nlcx wrote (it carries no nlcx mark); "
        "allowed: a run, sweep or reproduction directory nlcx wrote"
    ]
    assert "Traceback" not in result.output


def test_first_rows_are_each_codes_first_occurrence() -> None:
    """Codes first seen early, past the first window and at the very end: each one's first row,
    as a scan of the whole column per code finds it."""
    from nlcx.pages.sweep_charts import first_rows

    rng = np.random.default_rng(7)
    codes = rng.integers(1, 4, size=50_000)
    codes[9_000], codes[30_001], codes[-1] = 4, 5, 6  # beyond 4096 and 4096 + 8192 rows, and last
    codes[[0, 17]] = 0  # rows outside the selection (code 0) are never asked for
    present = np.array([3, 1, 2, 6, 4, 5])
    expected = [int(np.argmax(codes == c)) for c in present]
    assert first_rows(codes, present).tolist() == expected
    assert first_rows(codes, present, window=1).tolist() == expected
    with pytest.raises(ValueError, match=r"codes \[7\] do not occur"):
        first_rows(codes, np.array([1, 7]))

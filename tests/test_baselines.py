"""The baselines study: its configs follow the design rule stated before any run, each baseline
settles the x pendulum's step on its own, and ``nlcx baselines`` writes one directory whose
report shows every controller side by side (checked in Chromium)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from playwright.sync_api import sync_playwright
from typer.testing import CliRunner

import nlcx
from nlcx import manifest
from nlcx.cli import app
from nlcx.thesis import baselines

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs" / "baselines"
runner = CliRunner()


def _generated() -> dict[str, object]:
    """What scripts/make_baseline_configs.py writes, without writing it."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "make_baseline_configs", ROOT / "scripts" / "make_baseline_configs.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {f"{p}_{s}": module.scenario_config(p, s) for p in baselines.PENDULUMS for s in baselines.SCENARIOS}


def test_the_configs_are_the_rules_output() -> None:
    """Every committed scenario config holds what the rule computes now: Bryson's weights and
    the sliding surface at the LQR's slowest poles; nothing was tuned by hand."""
    for name, expected in _generated().items():
        committed = yaml.safe_load((CONFIGS / f"{name}.yaml").read_text())
        assert committed == expected, name
    x = yaml.safe_load((CONFIGS / "x_nominal.yaml").read_text())["controllers"]
    assert x["lqr"]["q"] == [1.0, 1.0, 25.0, 1.0, 1.0] and x["lqr"]["r"] == [0.01]
    assert {k: x["sliding_mode"][k] for k in baselines.SWITCHING} == baselines.SWITCHING


def test_bryson_weights_follow_the_acceptable_values() -> None:
    weights = baselines.bryson(["x", "x_dot", "z", "z_dot", "theta", "theta_dot"], ["F_x", "F_z"], ["x", "z"])
    assert weights["integral"] == ["x", "z"]
    assert weights["q"] == [1.0, 1.0, 1.0, 1.0, 25.0, 1.0, 1.0, 1.0] and weights["r"] == [0.01, 0.01]


@pytest.mark.parametrize("name", ["x_lqr", "x_sliding_mode"])
def test_each_baseline_settles_the_x_pendulums_step(name: str) -> None:
    """configs/baselines/x_lqr.yaml and x_sliding_mode.yaml: the plant named in the file itself;
    x within 5 % of its unit step at the end of the run."""
    raw = yaml.safe_load((CONFIGS / f"{name}.yaml").read_text())
    assert raw["plant"]["name"] == "x_pendulum" and "extends" not in raw
    result = nlcx.run(CONFIGS / f"{name}.yaml")
    (label,) = result.controllers
    frame = result.trajectory(label)
    assert result.status(label) == "ok"
    assert abs(frame["x"].iloc[-1] - 1.0) < 0.05


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``nlcx baselines`` of the x pendulum, 3 s runs and a sweep of 4 variants."""
    out = tmp_path_factory.mktemp("baselines") / "out"
    args = ["baselines", "--configs", str(CONFIGS), "--out", str(out), "--only", "x", "--variants", "4",
            "--set", "simulation.t_end=3", "--jobs", "1"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    return out


def test_the_study_writes_its_tables_runs_and_manifest(study: Path) -> None:
    comparison = pd.read_csv(study / "tables" / "comparison.csv")
    assert set(comparison.scenario) == set(baselines.SCENARIOS)
    assert set(comparison.controller) == {"conventional", "time_ags", "error_ags", "lqr", "sliding_mode"}
    robustness = pd.read_csv(study / "tables" / "robustness.csv")
    assert set(robustness.variants) == {4} and robustness.stable_share.between(0, 1).all()
    run = nlcx.load_run(study / "runs" / "x_nominal")
    merged = comparison[comparison.scenario == "nominal"].set_index(["controller", "signal", "metric"]).value
    for row in run.metrics.itertuples():
        got = merged[(row.controller, row.signal, row.metric)]
        assert (np.isnan(got) and np.isnan(row.value)) or got == row.value
    record = manifest.verify(study)
    assert record["nlcx_output"] == "baselines" and record["variants"] == 4 and record["report"] == {"status": "ok"}


@pytest.mark.browser
def test_the_baselines_page_shows_every_controller_in_chromium(study: Path) -> None:
    from test_report_browser import ARGS, chromium

    errors: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium(), args=ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto((study / "report.html").as_uri())
        page.wait_for_load_state("load")
        tables = page.evaluate("Array.from(document.querySelectorAll('table.comparison')).map(t => t.dataset.scenario)")
        headers = page.evaluate("Array.from(document.querySelectorAll('table.comparison tr:first-child th'))"
                                ".map(th => th.textContent)")  # fmt: skip
        shares = page.evaluate("Array.from(document.querySelectorAll('td.share')).map(td => td.textContent)")
        browser.close()
    assert errors == []
    assert tables == list(baselines.SCENARIOS)
    assert {"conventional", "time_ags", "error_ags", "lqr", "sliding_mode"} <= set(headers)
    assert len(shares) == 5 and all(s.endswith("%") for s in shares)


def test_a_pendulum_the_study_does_not_know_is_one_line(tmp_path: Path) -> None:
    result = runner.invoke(app, ["baselines", "--configs", str(CONFIGS), "--out", str(tmp_path / "o"), "--only", "w"])
    assert result.exit_code == 2 and result.stderr.startswith("config error: --only = 'w': a pendulum; allowed: x, xy")
    assert not (tmp_path / "o").exists()
    shutil.rmtree(tmp_path, ignore_errors=True)

"""Signals that say what they mean: structural poles apart from stability, a report of what was
asked, and a diverging plant of the decorator stopped by its default bounds."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import nlcx
from nlcx.plants.scalar import DEFAULT_BOUND

ROOT = Path(__file__).resolve().parent.parent
CONFIG = str(ROOT / "configs" / "x_error_ags.yaml")


@pytest.mark.parametrize("controller", ["proposed", "conventional"])
def test_a_working_pid_loop_is_stable_apart_from_its_redundant_integrator(controller: str) -> None:
    """The x pendulum's two loops both integrate into F_x: one combination of their integrators
    is a pole at 0 that nothing moves; the loop is stable apart from it."""
    lin = nlcx.linearize(CONFIG, controller)
    (pole,) = lin.marginal
    assert pole.name == "pid_x_integral" and abs(pole.value) < 1e-9
    assert lin.stable
    others = lin.poles[np.hypot(lin.poles.real, lin.poles.imag) > 1e-9]
    assert len(others) == len(lin.poles) - 1 and (others.real < 0).all()


def test_an_unstable_loop_is_not_stable() -> None:
    lin = nlcx.linearize(CONFIG, "proposed", overrides=["controllers.proposed.loops.theta.sign=1"])
    assert float(lin.poles.real.max()) > 1.0
    assert not lin.stable


def test_a_loop_without_a_redundant_integrator_has_no_marginal_pole() -> None:
    lin = nlcx.linearize(CONFIG, "proposed", overrides=["controllers.proposed.loops.x.schedule.ki={min: 0, max: 0}"])
    assert lin.marginal == ()


def test_a_report_made_with_only_shows_the_figures_asked_for(tmp_path: Path) -> None:
    from nlcx.thesis.pages.reproduction import context

    configs = ROOT / "configs" / "thesis"
    (tmp_path / "tables").mkdir()
    everything = context(tmp_path, configs, None)
    assert everything["figure_counts"]["missing"] > 90  # no --only: every figure of the thesis
    (tmp_path / "manifest.json").write_text(json.dumps({"nlcx_output": "reproduction", "only": ["table-2.3"]}))
    tables_only = context(tmp_path, configs, None)
    assert tables_only["figures"] == [] and tables_only["figure_counts"] == {"generated": 0, "missing": 0}
    (tmp_path / "manifest.json").write_text(json.dumps({"only": ["fig-2.4", "table-2.3"]}))
    one = context(tmp_path, configs, None)
    assert [f.figure for f in one["figures"]] == ["2.4"] and one["figure_counts"] == {"generated": 0, "missing": 1}
    (tmp_path / "manifest.json").write_text(json.dumps({"chapters": [3]}))
    chapter = context(tmp_path, configs, None)
    assert chapter["figures"] and {f.chapter for f in chapter["figures"]} == {3}


def test_a_diverging_decorator_plant_stops_at_its_default_bound() -> None:
    """dx/dt = x from x = 1 grows as e^t: without a bound it would reach e^40 by t = 40; the
    default bound 1e6 stops it as unstable near ln(1e6) = 13.8 s."""

    @nlcx.plant("runaway_for_test", states={"x": "m"}, inputs={"u": "N"})
    def runaway(t, x, u, p):  # type: ignore[no-untyped-def]
        return (x[0] + 0.0 * u[0],)

    assert DEFAULT_BOUND == 1e6
    result = nlcx.run({
        "name": "runaway", "plant": {"name": "runaway_for_test", "x0": {"x": 1.0}},
        "controllers": {"off": {"kind": "open_loop"}},
        "simulation": {"t_end": 40.0, "dt": 0.01},
    })  # fmt: skip
    assert result.status("off") == "unstable"
    x = result.trajectory("off")["x"].to_numpy()
    assert np.abs(x).max() <= 1.1 * DEFAULT_BOUND and math.isfinite(x[-1])
    assert result.trajectory("off").t.iloc[-1] < 15.0

"""Figures are planned from the runs and drawn from the plan alone: by the painter process
``nlcx run`` starts, or in this process, to the same PNG bytes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from nlcx import drawing, figure_plans
from tests.conftest import run_raw


def _result(raw: dict[str, Any]) -> Any:
    raw = {
        **raw,
        "simulation": {**raw.get("simulation", {}), "t_end": 8.0},
        "outputs": {"figure_inputs": True, "figure_metrics": ["ise"]},
    }
    return run_raw(raw)


def _jobs(result: Any, directory: Path) -> list[tuple[Path, drawing.FigurePlan]]:
    title = "A title long enough to be wrapped onto a second line by the figure, as the thesis's captions are"
    return [
        (directory / "figure.png", figure_plans.output_plan(result, title)),
        (directory / "gains.png", figure_plans.gains_plan(result)),
    ]


def test_the_painter_process_draws_the_bytes_this_process_draws(tmp_path: Path, x_error_raw: dict) -> None:
    result = _result(x_error_raw)
    drawing.draw_all(_jobs(result, tmp_path / "here"))
    assert drawing.Painter().paint(_jobs(result, tmp_path / "there")) is True
    for name in ("figure.png", "gains.png"):
        here = (tmp_path / "here" / name).read_bytes()
        assert here[:8] == b"\x89PNG\r\n\x1a\n" and len(here) > 10_000
        assert (tmp_path / "there" / name).read_bytes() == here


def test_figures_are_drawn_here_when_the_painter_fails(tmp_path: Path, x_error_raw: dict) -> None:
    result = _result(x_error_raw)
    broken = drawing.Painter([sys.executable, "-c", "import sys; sys.exit(3)"])
    assert broken.paint(_jobs(result, tmp_path / "fallback")) is False
    drawing.draw_all(_jobs(result, tmp_path / "here"))
    for name in ("figure.png", "gains.png"):
        assert (tmp_path / "fallback" / name).read_bytes() == (tmp_path / "here" / name).read_bytes()
    assert sorted(p.name for p in (tmp_path / "fallback").iterdir()) == ["figure.png", "gains.png"]


def test_the_output_plan_holds_each_runs_output_and_the_reference(x_error_raw: dict) -> None:
    result = _result(x_error_raw)
    plant = result.prepared.plant
    plan = figure_plans.output_plan(result)
    assert len(plan.panels) == len(plant.outputs) + len(plant.inputs)
    assert [p.title[:4] for p in plan.panels] == [f"({c}) " for c in "abc"[: len(plan.panels)]]
    for k, sig in enumerate(plant.outputs):
        lines = plan.panels[k].lines
        j = plant.output_names.index(sig.name)
        for run, line in zip(result.runs, lines, strict=False):
            assert line.label.startswith(run.label) and "ise" in line.label
            y = run.x @ plant.C[j]
            assert line.t.size < run.t.size  # thinned for drawing ...
            assert np.all(np.isin(line.y, y))  # ... to samples of the run
            assert line.y.min() == y.min() and line.y.max() == y.max()  # keeping its envelope
        assert lines[-1].label == "reference"


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_nlcx_run_leaves_matplotlib_to_the_painter_and_needs_no_pandas(tmp_path: Path, fmt: str) -> None:
    root = Path(__file__).resolve().parent.parent
    out = tmp_path / "run"
    args = ["run", "configs/x_error_ags.yaml", "simulation.t_end=2", f"outputs.timeseries_format={fmt}"]
    code = (
        "import atexit, sys\n"
        "atexit.register(lambda: print('imported:', sorted({'matplotlib', 'pandas'} & set(sys.modules))))\n"
        "from nlcx.cli import main\n"
        f"sys.argv = ['nlcx', *{args!r}, '--out', {str(out)!r}]\n"
        "main()\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "imported: []" in done.stdout  # the summary, the CSV files and the report page included
    assert "proposed" in done.stdout and (out / "report.html").is_file()
    assert (out / "figure.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / f"timeseries.{fmt}").is_file()


def test_a_painter_closed_without_figures_stops_at_once() -> None:
    painter = drawing.Painter()
    process = painter._process
    assert process is not None and process.poll() is None
    painter.close()
    assert process.returncode is not None  # killed and reaped, not left importing matplotlib
    painter.close()  # closing twice is harmless


def test_every_column_of_the_gains_figure_ends_in_a_time_axis(x_error_raw: dict) -> None:
    plan = figure_plans.gains_plan(_result(x_error_raw))
    assert plan.n_cols * plan.n_rows >= len(plan.panels) > plan.n_cols  # a grid whose last row is not full
    for col in range(plan.n_cols):
        column = plan.panels[col :: plan.n_cols]
        assert [p.xlabel for p in column] == [""] * (len(column) - 1) + ["Time (s)"]


def test_a_painter_left_without_figures_exits_quietly() -> None:
    # the run failed or was interrupted before handing its figures over: no traceback
    done = subprocess.run([sys.executable, "-m", "nlcx.drawing"], input=b"", capture_output=True, timeout=120)
    assert (done.returncode, done.stderr) == (0, b"")


def test_a_written_file_has_a_new_files_permissions_and_the_umask_is_never_changed(tmp_path: Path) -> None:
    """A file written atomically is readable as any file the process creates (0o666 less the
    umask, here 0o640), not private as a temporary file; neither importing nlcx.drawing nor
    writing sets the process's umask, not even for a moment (another thread may create files)."""
    target = tmp_path / "out" / "table.csv"
    code = (
        "import os\n"
        "from pathlib import Path\n"
        "os.umask(0o027)\n"
        "set_masks, umask = [], os.umask\n"
        "os.umask = lambda mask: set_masks.append(mask) or umask(mask)\n"
        "from nlcx import drawing\n"
        f"drawing.atomic_write(Path({str(target)!r}), lambda tmp: tmp.write_text('t,y\\n'))\n"
        f"drawing.atomic_write(Path({str(target)!r}), lambda tmp: tmp.write_text('t,y,u\\n'))\n"
        "print(set_masks)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    assert target.read_text() == "t,y,u\n" and target.stat().st_mode & 0o777 == 0o640
    assert [p.name for p in target.parent.iterdir()] == ["table.csv"]  # no temporary file left

"""``nlcx run`` writes metrics.csv and timeseries.csv from columns, without pandas
(:func:`nlcx.report.write_columns`). Their bytes must be those of the DataFrames the same
columns make, written by :func:`nlcx.report.write_csv`, as before."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from nlcx import report
from tests.conftest import load_yaml, run_raw


def _both(tmp_path: Path, columns: dict[str, Any], frame: pd.DataFrame) -> tuple[bytes, bytes]:
    report.write_columns(tmp_path / "columns.csv", columns)
    report.write_csv(tmp_path / "frame.csv", frame)
    return (tmp_path / "columns.csv").read_bytes(), (tmp_path / "frame.csv").read_bytes()


def _timeseries_frame(result: Any) -> pd.DataFrame:
    """The time series as pandas makes it: one frame per run, concatenated (a column a run
    lacks is NaN in its rows)."""
    frames = []
    for run in result.runs:
        plant, c = result.prepared.plant, run.controller
        cols: dict[str, Any] = {"t": run.t, "controller": run.label}
        cols |= {name: run.x[:, i] for i, name in enumerate(plant.state_names)}
        cols |= {name: run.u[:, i] for i, name in enumerate(plant.input_names)}
        offsets = c.reference_offsets or (0.0,) * len(c.reference_signals)
        for i, (name, off) in enumerate(zip(c.reference_signals, offsets, strict=True)):
            cols[f"{name}_ref" if off == 0 else f"{name}_ref{off:+g}"] = run.r[:, i]
        cols |= {name: run.log[:, i] for i, name in enumerate(c.log_names)}
        frames.append(pd.DataFrame(cols))
    return pd.concat(frames, ignore_index=True)


def test_the_time_series_of_controllers_with_different_logs_is_the_concatenated_frames(tmp_path: Path) -> None:
    raw = load_yaml("cstr_nonlinear.yaml")
    raw["simulation"]["t_end"] = 2.0
    result = run_raw(raw)
    frame = _timeseries_frame(result)
    assert frame.isna().any().any()  # one controller's logs are missing from the other's rows
    columns, expected = _both(tmp_path, report.timeseries_columns(result), frame)
    assert columns == expected
    assert b",," in columns  # the missing values are empty fields


def test_the_metrics_of_a_failed_and_a_completed_run_are_the_metrics_frame(tmp_path: Path, x_error_raw: dict) -> None:
    raw = copy.deepcopy(x_error_raw)
    raw["controllers"]["conventional"]["loops"]["theta"]["sign"] = 1  # positive feedback on the angle
    result = run_raw(raw)
    assert [r.status for r in result.runs] == ["unstable", "ok"]
    assert result.metrics.value.isna().any()
    columns, expected = _both(tmp_path, report.metric_columns(result), result.metrics)
    assert columns == expected
    assert b'"unstable"' in columns


def test_text_and_special_numbers_are_written_as_pandas_hands_them_to_arrow(tmp_path: Path) -> None:
    text = ["plain", 'a "quoted" word', "comma, inside", "é ∞ ü", "", "line\nbreak"]
    numbers = np.array([1.0, math.nan, -math.inf, math.inf, 1e-300, 0.1 + 0.2])
    columns, expected = _both(tmp_path, {"s": text, "v": numbers}, pd.DataFrame({"s": text, "v": numbers}))
    assert columns == expected
    empty, expected_empty = _both(
        tmp_path, {"s": [], "v": np.array([])}, pd.DataFrame({"s": pd.Series([], dtype=object), "v": []})
    )
    assert empty == expected_empty == b'"s","v"\n'

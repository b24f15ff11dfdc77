"""The files of a run directory, read back for :func:`nlcx.results.load_run` (its metrics,
time series and the plant's recorded signals) and copied whole for :meth:`nlcx.results.Result.save`."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

#: The columns of metrics.csv, in order.
METRIC_COLUMNS = ("controller", "signal", "metric", "value", "unit", "status", "note")


def metrics_frame(frame: pd.DataFrame) -> pd.DataFrame:
    """A metrics table with metrics.csv's columns and types: text columns as str (a missing
    note is ""), ``value`` as float64 (undefined is NaN)."""
    out = frame.loc[:, list(METRIC_COLUMNS)].copy()
    for column in METRIC_COLUMNS:
        if column == "value":
            out[column] = out[column].astype(np.float64)
        else:
            out[column] = out[column].fillna("").astype(str)
    return out.reset_index(drop=True)


def read_metrics(path: Path) -> pd.DataFrame:
    """metrics.csv as :func:`metrics_frame` gives it."""
    import pandas as pd

    text = {c: str for c in METRIC_COLUMNS if c != "value"}
    frame = pd.read_csv(path, dtype=text, keep_default_na=False, na_values={"value": [""]})
    return metrics_frame(frame)


def timeseries_file(directory: Path, listed: Mapping[str, object], written: bool = False) -> Path | None:
    """The time series file the manifest lists (timeseries.csv or .parquet), or None where the
    run wrote none.

    ``written``: the run's config wrote one (``outputs.timeseries: true``), so the manifest
    must list it. A time series listed but absent, or written but not listed, is missing: one
    line naming it and how to write it again.

    Raises
    ------
    nlcx.manifest.IntegrityError
        The time series file is missing."""
    from nlcx.manifest import IntegrityError

    for name in ("timeseries.parquet", "timeseries.csv"):
        if name in listed:
            if not (directory / name).is_file():
                raise IntegrityError(directory / name, "missing: the run wrote it and its manifest lists it",
                                     _rewrite(directory))  # fmt: skip
            return directory / name
    if written:
        raise IntegrityError(directory / "timeseries.csv", "missing: the run's config wrote a time series "
                             "(outputs.timeseries: true) and its manifest lists none", _rewrite(directory))  # fmt: skip
    return None


def _rewrite(directory: Path) -> str:
    """How to write a run directory's files again: run its config once more."""
    return f"write the run again: nlcx run {directory / 'config.yaml'} --out {directory}"


def read_timeseries(path: Path | None) -> dict[str, pd.DataFrame] | None:
    """A time series file (CSV or Parquet) split by controller, each without the columns its
    run does not have (another controller's logs: empty in its rows); None without one."""
    import pandas as pd

    if path is None:
        return None
    if path.suffix == ".parquet":
        frame = pd.read_parquet(path)
    else:
        frame = pd.read_csv(path, dtype={"controller": str}, keep_default_na=False, na_values=[""])
    out = {}
    for controller, rows in frame.groupby("controller", sort=False):
        rows = rows.drop(columns="controller").reset_index(drop=True).astype(np.float64)  # "1" in a CSV is 1.0
        out[str(controller)] = rows.loc[:, rows.notna().any(axis=0)]
    return out


def recorded_outputs(record: Mapping[str, object]) -> list[tuple[str, str, str]] | None:
    """(name, unit, label) of the plant's outputs as the manifest records them; None when it
    records none (nothing is then imported to find them: the plant is built, if it is known)."""
    outputs = record.get("outputs")
    if not isinstance(outputs, list) or not all(
        isinstance(o, list) and len(o) == 3 and all(isinstance(v, str) for v in o) for o in outputs
    ):
        return None
    return [(str(n), str(u), str(label)) for n, u, label in outputs]


def outputs_of(config: Mapping[str, object]) -> list[tuple[str, str, str]]:
    """(name, unit, label) of the plant's outputs, from the registered plant of ``config``."""
    from nlcx import config as cfg

    exp = cfg.build(copy.deepcopy(dict(config)))
    model = exp.plant_model
    plant = model.build(exp.section.plant.name, exp.plant_params, exp.section.plant.x0, {})
    return [(s.name, s.unit, s.label) for s in plant.outputs]


#: What the manifest records of the plant besides its outputs: its states and inputs by name, C.
RECORDED_SIGNALS = ("states", "inputs", "output_matrix")


def copy_run(source: Path, target: Path) -> None:
    """Copy a run directory whole (a loaded result saved elsewhere), staged as a run is."""
    import shutil

    from nlcx.rundir import staged

    with staged(target) as tmp:
        for item in source.iterdir():
            if item.is_file():
                shutil.copy2(item, tmp / item.name)

"""Which thesis figure and table comes from which experiment config.

The figure list and the thesis's numbers are the transcribed extracts in ``data/``. Every
result figure of chapters 2-4 is one config under ``configs/thesis/ch<c>/`` (written by
``scripts/make_thesis_configs.py``), except the Lyapunov figures, which plot the nominal
time-AGS and error-AGS runs of their pendulum. Each metrics table is the run of the
nominal or disturbed stabilisation figure it quantifies.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import cache
from importlib.resources import files
from pathlib import Path

import pandas as pd

DATA = files("nlcx.thesis") / "data"
#: Plant of each chapter-2-4 pendulum as the extracts name it -> nlcx plant.
PLANTS = {"x": "x_pendulum", "xy": "xy_pendulum", "xz": "xz_pendulum", "xyz": "xyz_pendulum"}
#: Parameter tables: table -> (kind, plant).
PARAMETER_TABLES = {
    "2.1": ("plant", "x"),
    "2.2": ("ags", "x"),
    "3.1": ("ags", "xy"),
    "3.6": ("ags", "xz"),
    "4.1": ("ags", "xyz"),
}


@dataclass(frozen=True)
class FigureSpec:
    figure: str
    kind: str  # "response" | "lyapunov"
    plant: str
    ags: str
    mode: str
    uncertainty: str
    title: str
    configs: tuple[Path, ...]

    @property
    def chapter(self) -> int:
        return int(self.figure.split(".")[0])

    @property
    def key(self) -> str:
        return f"fig-{self.figure}"

    @property
    def filename(self) -> str:
        chapter, number = self.figure.split(".")
        return f"fig_{chapter}_{number}.png"


@dataclass(frozen=True)
class TableSpec:
    table: str
    kind: str  # "metrics" | "plant" | "ags"
    plant: str
    configs: tuple[Path, ...]

    @property
    def chapter(self) -> int:
        return int(self.table.split(".")[0])

    @property
    def key(self) -> str:
        return f"table-{self.table}"

    @property
    def filename(self) -> str:
        chapter, number = self.table.split(".")
        return f"table_{chapter}_{number}.csv"


def _read(name: str) -> list[dict[str, str]]:
    with (DATA / name).open(newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@cache
def thesis_metrics() -> pd.DataFrame:
    """Tables 2.3-2.6, 3.2-3.5, 3.7-3.10, 4.2-4.5 in long form."""
    with (DATA / "pendulum_metrics.csv").open(newline="", encoding="utf-8") as fh:
        return pd.read_csv(fh, dtype={"table": str})


@cache
def gain_ranges() -> pd.DataFrame:
    """Tables 2.2, 3.1, 3.6, 4.1."""
    with (DATA / "ags_gain_ranges.csv").open(newline="", encoding="utf-8") as fh:
        return pd.read_csv(fh, dtype={"table": str})


def figure_config(root: Path, figure: str) -> Path:
    chapter, number = figure.split(".")
    return root / f"ch{chapter}" / f"fig_{chapter}_{int(number):02d}.yaml"


def _figure_number(plant: str, ags: str, mode: str, uncertainty: str) -> str:
    for row in _read("figures.csv"):
        if (row["plant"], row["ags"], row["mode"], row["uncertainty"]) == (plant, ags, mode, uncertainty):
            return row["figure"]
    raise KeyError((plant, ags, mode, uncertainty))


def figures(root: Path) -> list[FigureSpec]:
    """Every result figure of chapters 2-4."""
    specs = []
    for row in _read("figures.csv"):
        if row["kind"] != "result" or row["figure"].split(".")[0] not in ("2", "3", "4"):
            continue
        plant = row["plant"]
        if row["mode"] in ("stabilization", "tracking"):
            configs: tuple[Path, ...] = (figure_config(root, row["figure"]),)
            kind = "response"
        else:
            configs = tuple(
                figure_config(root, _figure_number(plant, ags, "stabilization", "none")) for ags in ("time", "error")
            )
            kind = "lyapunov"
        specs.append(
            FigureSpec(
                figure=row["figure"],
                kind=kind,
                plant=plant,
                ags=row["ags"],
                mode=row["mode"],
                uncertainty=row["uncertainty"],
                title=f"Figure {row['figure']} {row['title']}".replace("dot{V}", "V̇"),
                configs=configs,
            )
        )
    return specs


def tables(root: Path) -> list[TableSpec]:
    """The 16 metrics tables and the 5 parameter tables of chapters 2-4."""
    specs = []
    meta = thesis_metrics()[["table", "plant", "ags", "scenario"]].drop_duplicates()
    for row in meta.itertuples(index=False):
        uncertainty = "none" if row.scenario == "nominal" else row.scenario
        figure = _figure_number(row.plant, row.ags, "stabilization", uncertainty)
        specs.append(TableSpec(str(row.table), "metrics", row.plant, (figure_config(root, figure),)))
    for table, (kind, plant) in PARAMETER_TABLES.items():
        configs = tuple(
            figure_config(root, _figure_number(plant, ags, "stabilization", "none")) for ags in ("time", "error")
        )
        specs.append(TableSpec(table, kind, plant, configs))
    return sorted(specs, key=lambda s: tuple(int(p) for p in s.table.split(".")))

"""Which thesis figure and table comes from which experiment config.

The figure list and the thesis's numbers are the transcribed extracts in ``data/``. Every
result figure of chapters 2-4 is one config under ``configs/thesis/ch<c>/`` (written by
``scripts/make_thesis_configs.py``), except the Lyapunov figures, which plot the nominal
time-AGS and error-AGS runs of their pendulum. Each metrics table is the run of the
nominal or disturbed stabilisation figure it quantifies.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from functools import cache
from importlib.resources import files
from pathlib import Path

import pandas as pd

DATA = files("nlcx.thesis") / "data"
#: Plant of each chapter-2-4 pendulum as the extracts name it -> nlcx plant.
PLANTS = {"x": "x_pendulum", "xy": "xy_pendulum", "xz": "xz_pendulum", "xyz": "xyz_pendulum"}
#: Chapter-5 figures: figure -> (kind, config file, membership variable).
CSTR_FIGURES = {
    "5.2": ("response", "fig_5_02.yaml", ""),
    "5.4": ("membership", "fig_5_10.yaml", "e"),
    "5.5": ("membership", "fig_5_10.yaml", "de_dt"),
    "5.6": ("membership", "fig_5_10.yaml", "kp1"),
    "5.7": ("membership", "fig_5_10.yaml", "ki1"),
    "5.8": ("membership", "fig_5_10.yaml", "kd1"),
    "5.10": ("response", "fig_5_10.yaml", ""),
    "5.12": ("response", "fig_5_12.yaml", ""),
    "5.15": ("response", "fig_5_15.yaml", ""),
    "5.17": ("response", "fig_5_17.yaml", ""),
    "5.19": ("response", "fig_5_19.yaml", ""),
}
#: Table 5.8's methods -> (config file, controller label).
CSTR_METHODS = {
    "ZN": ("fig_5_02.yaml", "zn"),
    "Fuzzy": ("fig_5_10.yaml", "fuzzy"),
    "ANN": ("fig_5_12.yaml", "ann"),
    "ANFIS": ("fig_5_15.yaml", "anfis"),
    "GA": ("fig_5_17.yaml", "ga"),
}
#: Chapter-5 parameter tables: table -> (kind, config file, fuzzy variable).
CSTR_TABLES = {
    "5.1": ("zn_rules", "fig_5_02.yaml", ""),
    "5.2": ("fuzzy_universes", "fig_5_10.yaml", ""),
    "5.3": ("fuzzy_sets", "fig_5_10.yaml", "e"),
    "5.4": ("fuzzy_sets", "fig_5_10.yaml", "de_dt"),
    "5.5": ("fuzzy_sets", "fig_5_10.yaml", "kp1"),
    "5.6": ("fuzzy_sets", "fig_5_10.yaml", "ki1"),
    "5.7": ("fuzzy_sets", "fig_5_10.yaml", "kd1"),
    "5.8": ("cstr_metrics", "", ""),
}
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
    kind: str  # "response" | "lyapunov" | "membership"
    plant: str
    ags: str
    mode: str
    uncertainty: str
    title: str
    configs: tuple[Path, ...]
    variable: str = ""

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
    kind: str  # "metrics" | "plant" | "ags" | "cstr_metrics" | "zn_rules" | "fuzzy_universes" | "fuzzy_sets"
    plant: str
    configs: tuple[Path, ...]
    variable: str = ""

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


def clean_title(title: str) -> str:
    """The figure list's caption with its TeX remnants made readable (H_{∞} -> H∞, dot{V} -> V̇)."""
    title = title.replace("dot{V}", "V̇").replace("H_2", "H2")
    return re.sub(r"_\{([^}]*)\}", r"\1", title)


def _open(name: str) -> io.StringIO:
    """The data file ``name`` as text, its line ends as written (what ``open(newline="")`` gives
    the csv module)."""
    return io.StringIO((DATA / name).read_bytes().decode("utf-8"), newline="")


def _read(name: str) -> list[dict[str, str]]:
    with _open(name) as fh:
        return list(csv.DictReader(fh))


@cache
def thesis_metrics() -> pd.DataFrame:
    """Tables 2.3-2.6, 3.2-3.5, 3.7-3.10, 4.2-4.5 in long form."""
    with _open("pendulum_metrics.csv") as fh:
        return pd.read_csv(fh, dtype={"table": str})


@cache
def cstr_table() -> pd.DataFrame:
    """Table 5.8 and the inverse-response magnitudes of sections 5.3-5.4."""
    with _open("cstr_table_5_8.csv") as fh:
        return pd.read_csv(fh)


@cache
def fuzzy_sets() -> pd.DataFrame:
    """Tables 5.3-5.7."""
    with _open("cstr_fuzzy_sets.csv") as fh:
        return pd.read_csv(fh)


@cache
def fuzzy_universes() -> pd.DataFrame:
    """Table 5.2."""
    with _open("cstr_fuzzy_universes.csv") as fh:
        return pd.read_csv(fh)


@cache
def gain_ranges() -> pd.DataFrame:
    """Tables 2.2, 3.1, 3.6, 4.1: min and max of k_p, k_i, k_d of every AGS loop."""
    with _open("ags_gain_ranges.csv") as fh:
        return pd.read_csv(fh, dtype={"table": str})


@cache
def ags_rates() -> pd.DataFrame:
    """Section 2.3: the rates k of the AGS schedules (blank where the thesis prints none)."""
    with _open("ags_rates.csv") as fh:
        return pd.read_csv(fh)


def figure_config(root: Path, figure: str) -> Path:
    """The experiment config of a chapter-2-4 result figure, e.g. ``ch2/fig_2_04.yaml``."""
    chapter, number = figure.split(".")
    return root / f"ch{chapter}" / f"fig_{chapter}_{int(number):02d}.yaml"


def figure_number(plant: str, ags: str, mode: str, uncertainty: str) -> str:
    """The thesis figure showing one pendulum, schedule, mode and uncertainty (figures.csv)."""
    for row in _read("figures.csv"):
        if (row["plant"], row["ags"], row["mode"], row["uncertainty"]) == (plant, ags, mode, uncertainty):
            return row["figure"]
    raise KeyError((plant, ags, mode, uncertainty))


def figures(root: Path) -> list[FigureSpec]:
    """Every result figure of chapters 2-4."""
    specs = []
    for row in _read("figures.csv"):
        if row["kind"] == "result" and row["figure"] in CSTR_FIGURES:
            kind, file, variable = CSTR_FIGURES[row["figure"]]
            specs.append(
                FigureSpec(
                    figure=row["figure"],
                    kind=kind,
                    plant="cstr",
                    ags="",
                    mode="",
                    uncertainty="",
                    title=clean_title(f"Figure {row['figure']} {row['title']}"),
                    configs=(root / "ch5" / file,),
                    variable=variable,
                )
            )
            continue
        if row["kind"] != "result" or row["figure"].split(".")[0] not in ("2", "3", "4"):
            continue
        plant = row["plant"]
        if row["mode"] in ("stabilization", "tracking"):
            configs: tuple[Path, ...] = (figure_config(root, row["figure"]),)
            kind = "response"
        else:
            configs = tuple(
                figure_config(root, figure_number(plant, ags, "stabilization", "none")) for ags in ("time", "error")
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
                title=clean_title(f"Figure {row['figure']} {row['title']}"),
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
        figure = figure_number(row.plant, row.ags, "stabilization", uncertainty)
        specs.append(TableSpec(str(row.table), "metrics", row.plant, (figure_config(root, figure),)))
    for table, (kind, file, variable) in CSTR_TABLES.items():
        configs = (
            tuple(root / "ch5" / f for f, _ in CSTR_METHODS.values())
            if kind == "cstr_metrics"
            else (root / "ch5" / file,)
        )
        specs.append(TableSpec(table, kind, "cstr", configs, variable))
    for table, (kind, plant) in PARAMETER_TABLES.items():
        configs = tuple(
            figure_config(root, figure_number(plant, ags, "stabilization", "none")) for ags in ("time", "error")
        )
        specs.append(TableSpec(table, kind, plant, configs))
    return sorted(specs, key=lambda s: tuple(int(p) for p in s.table.split(".")))

"""The consistency study's spec and the printed columns it examines: each column's cells, the
interval each printed text covers, and the other tables that print the same column."""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path
from typing import Any, Literal

import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from nlcx import safe_yaml
from nlcx.thesis import catalog, hypotheses
from nlcx.thesis.fitting import DEFINITIONS, FLOORS
from nlcx.thesis.pages import tolerances
from nlcx.tuning.optimise import GASettings, check_search_box
from nlcx.validation import validate_model

#: The option families that change a conventional loop with free gains.
CONVENTIONAL_FAMILIES = ("derivative", "lag", "prefilter", "sampling", "saturation")
#: The families that change a column's reference, initial state, disturbance, integrators or
#: the measurement (either controller's).
SCENARIO_FAMILIES = ("theta_settling", "reference_amplitude", "step_time", "initial_angle", "z_loop",
                     "disturbance_phase", "disturbance_start", "disturbance_entry", "integrator_limit")  # fmt: skip
STUDY_FAMILIES = CONVENTIONAL_FAMILIES + SCENARIO_FAMILIES
NLCX_DEFINITION = next(iter(DEFINITIONS))
Box = dict[str, tuple[float, float]]
Column = tuple[str, str]  # (table, controller)
Family = list[hypotheses.Hypothesis]


class CloudSettings(BaseModel):
    """Random loops per column and definition: a random hypothesis of the family each, its
    gains uniform in ``box`` (default: the spec's ``free``), its own parameters in theirs."""

    model_config = ConfigDict(extra="forbid")
    n: int = Field(1500, ge=1)
    seed: int = Field(7, ge=0)
    box: Box | None = None


class ConsistencySpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    kind: Literal["consistency"]
    #: One table per printed column (the others that print it are found and reported).
    tables: list[str] = Field(min_length=1)
    #: The columns of each table: conventional (gains free), proposed (printed AGS gains).
    controllers: list[Literal["conventional", "proposed"]] = Field(["conventional"], min_length=1)
    #: Families whose options are combined, up to ``max_options`` of them.
    families: list[str] = Field(default_factory=lambda: list(CONVENTIONAL_FAMILIES))
    max_options: int = Field(2, ge=0, le=len(STUDY_FAMILIES))
    #: Families whose options are examined one at a time, never combined.
    alone: list[str] = Field(default_factory=list)
    #: The conventional gains (a column's fit frees those its experiment reads) and bounds.
    free: Box = Field(min_length=1)
    warm_start: GASettings = GASettings(pop_size=30, generations=10, seed=1)
    optimiser: GASettings = GASettings(pop_size=12, generations=8, seed=1)
    cloud: CloudSettings = CloudSettings()
    #: The decimals a printed "0" is read with (None: none, as any integer).
    zero_decimals: int | None = Field(None, ge=0)
    #: Definitions of t_r and t_s the clouds are measured under; the first is nlcx's, which
    #: the fits use.
    definitions: list[str] = Field(default_factory=lambda: list(DEFINITIONS))

    @field_validator("families", "alone")
    @classmethod
    def _known(cls, families: list[str]) -> list[str]:
        unknown = [f for f in families if f not in STUDY_FAMILIES or f not in hypotheses.FAMILIES]
        if unknown:
            raise ValueError(f"unknown option families {unknown}; allowed: {', '.join(STUDY_FAMILIES)}")
        return families

    @field_validator("free")
    @classmethod
    def _bounds(cls, free: Box) -> Box:
        return check_search_box(free, ("vars.conventional.",), "only the conventional gains (vars.conventional.*)")

    @field_validator("definitions")
    @classmethod
    def _definitions(cls, definitions: list[str]) -> list[str]:
        unknown = [d for d in definitions if d not in DEFINITIONS]
        if unknown:
            raise ValueError(f"unknown definitions {unknown}; allowed: {', '.join(DEFINITIONS)}")
        if not definitions or definitions[0] != NLCX_DEFINITION:
            raise ValueError(f"the first definition must be nlcx's ({NLCX_DEFINITION}): the fits are measured under it")
        return definitions

    @model_validator(mode="after")
    def _tables(self) -> ConsistencySpec:
        known = set(catalog.thesis_metrics().table)
        for table in self.tables:
            if table not in known:
                raise ValueError(f"table {table} is not a pendulum metrics table; allowed: {', '.join(sorted(known))}")
        if both := sorted(set(self.families) & set(self.alone)):
            raise ValueError(f"families {both} are in both families and alone; name each once")
        return self

    def family(self) -> Family:
        """The literal loop, every combination of up to ``max_options`` options of ``families``,
        and each option of ``alone`` by itself."""
        return hypotheses.family(self.families, self.max_options) + hypotheses.family(self.alone, 1)[1:]


def column_cells(table: str, controller: str = "conventional") -> pd.DataFrame:
    """The printed cells (M_p, t_r, t_s) of one controller's column of ``table``, with a
    ``cell`` label and the ``text`` printed (as transcribed: its decimals are the print's)."""
    text = (catalog.DATA / "pendulum_metrics.csv").read_text(encoding="utf-8")
    rows = catalog.thesis_metrics().assign(text=pd.read_csv(io.StringIO(text), dtype=str).value)
    rows = rows[(rows.table == table) & (rows.controller == controller) & rows.metric.isin(FLOORS)]
    rows = rows[["table", "signal", "controller", "metric", "value", "text"]].reset_index(drop=True)
    return rows.assign(cell=rows.signal + "." + rows.metric)


def printed_interval(text: str, rel: float, zero_decimals: int | None = None) -> tuple[float, float]:
    """The values a printed cell covers: v printed with d decimals stands for [v - 0.5 10^-d,
    v + 0.5 10^-d] (5.79: [5.785, 5.795]; 12: [11.5, 12.5]), widened on each side by ``rel`` |v|,
    the metric's relative tolerance. A bare "0" is read with ``zero_decimals`` decimals when
    given (the thesis prints a zero as "0" in columns it prints to 2 decimals)."""
    value, decimals = float(text), len(text.partition(".")[2])
    if value == 0 and decimals == 0 and zero_decimals is not None:
        decimals = zero_decimals
    half = 0.5 * 10.0**-decimals + rel * abs(value)
    return value - half, value + half


def with_intervals(
    cells: pd.DataFrame, rules: tolerances.ReproductionTolerances, zero_decimals: int | None
) -> pd.DataFrame:
    """``cells`` with the interval each printed text covers (``lower``, ``upper``;
    :func:`printed_interval`), widened by the relative tolerance of its metric in
    tolerances.yaml (``cells.by_metric``, a measured response's; its absolute tolerance is the
    print's resolution, which the rounding already gives)."""
    rel = [rules.for_metric(metric).rel for metric in cells.metric]
    bounds = [printed_interval(text, r, zero_decimals) for text, r in zip(cells.text, rel, strict=True)]
    return cells.assign(lower=[b[0] for b in bounds], upper=[b[1] for b in bounds])


def also_printed(table: str, controller: str = "conventional") -> list[str]:
    """The other tables that print the same column (same plant, scenario and cells; for the
    proposed controller also the same AGS)."""
    rows = catalog.thesis_metrics()
    rows = rows[(rows.controller == controller) & rows.metric.isin(FLOORS)]

    def column(t: str) -> tuple[Any, ...]:
        mine = rows[rows.table == t]
        cells = sorted(zip(mine.signal, mine.metric, mine.value, strict=True))
        ags = mine.ags.iloc[0] if controller == "proposed" else ""
        return (mine.plant.iloc[0], mine.scenario.iloc[0], ags, tuple(cells))

    return [t for t in dict.fromkeys(rows.table) if t != table and column(t) == column(table)]


def digest(spec: ConsistencySpec) -> str:
    """What a finished task depends on: the spec."""
    return hashlib.sha256(json.dumps(spec.model_dump(), sort_keys=True).encode()).hexdigest()[:16]


def load_spec(path: Path) -> ConsistencySpec:
    return validate_model(ConsistencySpec, safe_yaml.load_file(path) or {}, "")

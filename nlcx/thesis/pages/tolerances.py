"""The tolerances a reproduction report judges tables by (configs/thesis/tolerances.yaml).

A cell is within tolerance when |nlcx - thesis| <= max(rel |thesis|, abs); a table is
reproduced / partly / not by the share of its cells within tolerance. The file is declared
before any comparison, with the reason for each tolerance; the report prints them.
"""

from __future__ import annotations

import math
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from nlcx import safe_yaml
from nlcx.validation import validate_model


class Tolerance(BaseModel):
    model_config = ConfigDict(extra="forbid")
    rel: float = Field(0.0, ge=0)
    abs: float = Field(0.0, ge=0)
    reason: str

    def within(self, thesis: float, ours: float) -> bool:
        """|ours - thesis| <= max(rel |thesis|, abs); a value we could not measure is never within."""
        if not math.isfinite(ours):
            return False
        return abs(ours - thesis) <= max(self.rel * abs(thesis), self.abs)


class TableRule(BaseModel):
    model_config = ConfigDict(extra="forbid")
    reproduced: float = Field(gt=0, le=1)
    partly: float = Field(ge=0, le=1)


class CellRules(BaseModel):
    model_config = ConfigDict(extra="forbid")
    default: Tolerance
    by_metric: dict[str, Tolerance] = Field(default_factory=dict)


class ReproductionTolerances(BaseModel):
    model_config = ConfigDict(extra="forbid")
    table: TableRule
    cells: CellRules

    def for_metric(self, metric: str | None) -> Tolerance:
        return self.cells.by_metric.get(metric or "", self.cells.default)

    def verdict(self, within: int, cells: int) -> str:
        """reproduced / partly / not by the share of cells within tolerance ("n/a": no cells)."""
        if cells == 0:
            return "n/a"
        share = within / cells
        return "reproduced" if share >= self.table.reproduced else "partly" if share >= self.table.partly else "not"


def load(path: Path) -> ReproductionTolerances:
    return validate_model(ReproductionTolerances, safe_yaml.load_file(path) or {}, "tolerances")

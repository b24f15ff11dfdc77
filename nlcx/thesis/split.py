"""The train / validation / test split of the thesis's numbers (configs/identify/split.yaml).

The identification study reads the thesis's tables only through :func:`cells`, which hands
out one part at a time: a fit asks for ``"train"`` and cannot see anything else.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, model_validator

from nlcx import safe_yaml
from nlcx.errors import ConfigError
from nlcx.thesis import catalog
from nlcx.validation import validate_model

Part = Literal["train", "validation", "test"]
PARTS: tuple[Part, ...] = ("train", "validation", "test")
#: Table 5.8's columns for the split's metric names.
CSTR_COLUMNS = {"Mp": "Mp_percent", "tr": "tr_s", "ts": "ts_s"}


class Parts(BaseModel):
    model_config = ConfigDict(extra="forbid")
    train: list[str] = Field(min_length=1)
    validation: list[str] = Field(default_factory=list)
    test: list[str] = Field(default_factory=list)

    @model_validator(mode="after")
    def _disjoint(self) -> Parts:
        seen: dict[str, str] = {}
        for part in PARTS:
            for name in getattr(self, part):
                if name in seen:
                    raise ValueError(f"{name} is in both {seen[name]} and {part}")
                seen[name] = part
        return self


class Split(BaseModel):
    """Which thesis numbers each part holds."""

    model_config = ConfigDict(extra="forbid")
    metrics: list[Literal["Mp", "tr", "ts"]] = Field(min_length=1)
    pendulum: Parts
    cstr: Parts


def load(path: Path) -> Split:
    """The split in ``path``, validated; every named table or row must exist in the thesis."""
    split = validate_model(Split, safe_yaml.load_file(path) or {}, "")
    tables = set(catalog.thesis_metrics().table)
    methods = set(catalog.cstr_table().method)
    for kind, known in (("pendulum", tables), ("cstr", methods)):
        parts: Parts = getattr(split, kind)
        for part in PARTS:
            for name in getattr(parts, part):
                if name not in known:
                    raise ConfigError(f"{kind}.{part}", name, f"not in the thesis; allowed: {', '.join(sorted(known))}")
    return split


def cells(split: Split, part: Part) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(pendulum cells, Table 5.8 cells) of one part, long form with a ``value`` column."""
    pend = catalog.thesis_metrics()
    pend = pend[pend.table.isin(split.pendulum.model_dump()[part]) & pend.metric.isin(split.metrics)]
    cstr = catalog.cstr_table()
    cstr = cstr[cstr.method.isin(split.cstr.model_dump()[part])]
    rows = [
        {"method": r.method, "metric": m, "value": float(getattr(r, CSTR_COLUMNS[m]))}
        for r in cstr.itertuples(index=False)
        for m in split.metrics
    ]
    return pend.reset_index(drop=True), pd.DataFrame(rows, columns=["method", "metric", "value"])

"""What the report of a run directory (``nlcx run``) shows: its metrics table, its figures,
the resolved config and the manifest (versions, commit, seed, timings) in readable form."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import yaml


def metric_records(path: Path) -> list[dict[str, Any]]:
    """metrics.csv's rows: every field as written, ``value`` as a float (NaN where empty)."""
    with path.open(newline="", encoding="utf-8") as file:
        return [{**row, "value": float(row["value"]) if row["value"] else math.nan} for row in csv.DictReader(file)]


def context(directory: Path) -> dict[str, Any]:
    config = (directory / "config.yaml").read_text(encoding="utf-8") if (directory / "config.yaml").is_file() else ""
    manifest = json.loads((directory / "manifest.json").read_text()) if (directory / "manifest.json").is_file() else {}
    name = (yaml.load(config, Loader=yaml.CSafeLoader) or {}).get("name", directory.name) if config else directory.name
    return {
        "kind": "run",
        "title": f"nlcx run: {name}",
        "metrics": metric_records(directory / "metrics.csv"),
        "figures": sorted(p.name for p in directory.glob("*.png")),
        "config": config,
        "manifest": manifest,
    }

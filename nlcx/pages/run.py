"""What the report of a run directory (``nlcx run``) shows: its metrics table, its figures,
the resolved config and the manifest (versions, commit, seed, timings) in readable form."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd
import yaml


def context(directory: Path) -> dict[str, Any]:
    metrics = pd.read_csv(directory / "metrics.csv")
    for column in metrics.columns.drop("value"):
        metrics[column] = metrics[column].astype(object).where(metrics[column].notna(), "")
    config = (directory / "config.yaml").read_text(encoding="utf-8") if (directory / "config.yaml").is_file() else ""
    manifest = json.loads((directory / "manifest.json").read_text()) if (directory / "manifest.json").is_file() else {}
    name = (yaml.safe_load(config) or {}).get("name", directory.name) if config else directory.name
    return {
        "kind": "run",
        "title": f"nlcx run: {name}",
        "metrics": metrics.to_dict("records"),
        "figures": sorted(p.name for p in directory.glob("*.png")),
        "config": config,
        "manifest": manifest,
    }

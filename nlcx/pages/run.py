"""What the report of a run directory (``nlcx run``) shows, in this order: one line per signal
saying which controller is better on how many metrics, the comparison of its controllers (each
one's thesis metrics per signal, the change % of each later one against the first and the
better one, :mod:`nlcx.comparison`), its figures, the long metrics table, the resolved config
and the manifest (versions, commit, seed, timings) in readable form. Reads the files with the
standard library only: ``nlcx run`` writes its page without importing pandas."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from nlcx import safe_yaml
from nlcx.comparison import Row, SideBySide, comparison
from nlcx.pages.kinds import ReportPage
from nlcx.pages.render import TEMPLATES


def metric_records(path: Path) -> list[dict[str, object]]:
    """metrics.csv's rows: every field as written, ``value`` as a float (NaN where empty)."""
    with path.open(newline="", encoding="utf-8") as file:
        return [{**row, "value": float(row["value"]) if row["value"] else math.nan} for row in csv.DictReader(file)]


def by_signal(table: SideBySide) -> list[dict[str, object]]:
    """The comparison's rows grouped by signal: ``{"signal": s, "rows": [Row, ...]}`` in order."""
    groups: dict[str, list[Row]] = {}
    for row in table.rows:
        groups.setdefault(row.signal, []).append(row)
    return [{"signal": signal, "rows": rows} for signal, rows in groups.items()]


def _config(directory: Path) -> tuple[str, dict[str, object]]:
    """config.yaml's text and its mapping (both empty when the directory has none)."""
    path = directory / "config.yaml"
    text = path.read_text(encoding="utf-8") if path.is_file() else ""
    loaded = safe_yaml.load_text(text, str(path)) if text else None
    return text, loaded if isinstance(loaded, dict) else {}


def context(directory: Path) -> dict[str, object]:
    """Everything the run page shows."""
    config, raw = _config(directory)
    manifest = json.loads((directory / "manifest.json").read_text()) if (directory / "manifest.json").is_file() else {}
    metrics = metric_records(directory / "metrics.csv")
    table = comparison(metrics)
    return {
        "kind": "run",
        "title": f"nlcx run: {raw.get('name', directory.name)}",
        "caption": str(raw.get("title") or ""),
        "comparison": table,
        "verdicts": table.verdicts(),
        "signals": by_signal(table),
        "metrics": metrics,
        "figures": sorted(p.name for p in directory.glob("*.png")),
        "config": config,
        "manifest": manifest,
    }


def page_context(directory: Path, configs: Path | None, repo: Path | None) -> dict[str, object]:
    """The page's :func:`context` (it reads only the directory's own files)."""
    return context(directory)


#: The report page of a run directory (built in: :data:`nlcx.pages.kinds.BUILT_IN`).
PAGE = ReportPage(TEMPLATES, page_context)

"""Plot a robustness sweep: distributions of x overshoot and settling time per controller,
split by the first grid key (e.g. the friction model). Writes <run dir>/robustness.png.
Reads the sweep's tables in either form, Parquet or CSV (nlcx.results.read_output_table).

    python scripts/plot_sweep.py results/robustness
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from nlcx.results import read_output_table


def main(run_dir: Path) -> Path:
    index = read_output_table(run_dir, "sweep")
    metrics = read_output_table(run_dir, "metrics")
    groups = [c for c in index.columns if c.startswith("value:") and not pd.api.types.is_numeric_dtype(index[c])]
    by = groups[0] if groups else None
    data = metrics[(metrics.signal == "x") & metrics.metric.isin(["overshoot", "settling_time"])]
    data = data.merge(index[["variant", "status", *([by] if by else [])]], on="variant")
    controllers = list(dict.fromkeys(data.controller))
    levels = list(dict.fromkeys(index[by])) if by else ["all"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (metric, label) in zip(
        axes, (("overshoot", "x overshoot M_p (%)"), ("settling_time", "x settling time t_s (s)")), strict=True
    ):
        boxes, names = [], []
        for level in levels:
            for c in controllers:
                sel = data[(data.metric == metric) & (data.controller == c) & ((data[by] == level) if by else True)]
                boxes.append(sel.value.dropna().to_numpy())
                names.append(f"{c}\n{level}")
        ax.boxplot(boxes, tick_labels=names, showfliers=True)
        ax.set_ylabel(label)
        ax.tick_params(axis="x", labelsize=7)
        ax.grid(True, alpha=0.3)
    unstable = index.groupby(by).status.apply(lambda s: (s != "ok").mean() * 100) if by else None
    note = "; ".join(f"{k}: {v:.0f} % of variants with a diverged run" for k, v in unstable.items()) if by else ""
    fig.suptitle(f"{run_dir.name}: {len(index)} variants. {note}", fontsize=9)
    fig.tight_layout()
    out = run_dir / "robustness.png"
    fig.savefig(out, dpi=120)
    return out


if __name__ == "__main__":
    print(main(Path(sys.argv[1])))

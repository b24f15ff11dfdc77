"""The consistency study's figure (consistency.png): per column, every loop examined and the
printed pair."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from nlcx.thesis.consistency.spec import Column, column_cells


def figure(clouds: dict[Column, pd.DataFrame], path: Path) -> None:
    """Per column: x rise time against x overshoot of every loop examined, and the printed pair."""
    from nlcx.drawing import atomic_write, new_figure

    n = len(clouds)
    cols = min(4, n)
    n_rows = (n + cols - 1) // cols
    fig, axes = new_figure(n_rows, cols, (3.4 * cols, 3.0 * n_rows))
    for ax, (column, loops) in zip(axes.flat, clouds.items(), strict=False):
        cells = column_cells(*column).set_index("cell").value
        for source, rows in loops.groupby("source"):
            ax.scatter(rows["x.tr"], rows["x.Mp"], s=2, alpha=0.3, label=f"{source} loops")
        ax.scatter([cells["x.tr"]], [cells["x.Mp"]], marker="*", s=160, color="red", label="printed")
        ax.set(xlim=(0, max(5.0, 1.5 * cells["x.tr"])), ylim=(0, 1.2))
        ax.set_title(f"Table {column[0]}, {column[1]}", fontsize=9)
        ax.set_xlabel("x t_r (s)", fontsize=8)
        ax.set_ylabel("x M_p", fontsize=8)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    legend = axes.flat[0].legend(fontsize=7)
    for handle in legend.legend_handles:  # the same modest marker for the dots and the star
        handle.set_sizes([30.0])
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))

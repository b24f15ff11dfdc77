"""Figures 5.4-5.8: the membership functions of the fuzzy schedule's variables (section 5.4.1,
Tables 5.3-5.7), as ``nlcx reproduce`` draws them from the schedule a chapter 5 run built."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from nlcx.controllers.fuzzy_config import FuzzyConfig, as_config, membership, universe

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: Axis labels of Figures 5.4-5.8.
LABELS = {"e": "e", "de_dt": "de/dt", "kp1": "$k_{p1}$", "ki1": "$k_{i1}$", "kd1": "$k_{d1}$"}


def membership_figure(cfg: FuzzyConfig | dict[str, object], variable: str, points: int = 1001) -> Figure:
    """Figures 5.4-5.8: the five membership functions of ``variable`` over its universe."""
    from matplotlib.figure import Figure

    cfg = as_config(cfg)
    umin, umax = universe(cfg, variable)
    x = np.linspace(umin, umax, points)
    mus = membership(cfg, variable, x)
    fig = Figure(figsize=(6.4, 3.2))
    ax = fig.add_subplot()
    for name, mu in mus.items():
        ax.plot(x, mu, lw=1.4, label=name)
        k = int(np.argmax(mu))
        ax.annotate(name, (x[k], 1.0), xytext=(0, 3), textcoords="offset points", ha="center", fontsize=8)
    ax.set_xlim(umin, umax)
    ax.set_ylim(-0.02, 1.12)
    ax.set_xlabel(LABELS[variable])
    ax.set_ylabel("Degree of membership")
    ax.set_title(f"Fuzzy Membership functions for {LABELS[variable]}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="center right", fontsize=8)
    fig.tight_layout()
    return fig

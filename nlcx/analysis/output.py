"""The directory ``nlcx linearize`` writes, staged and replaced whole (:func:`nlcx.rundir.staged`).

- ``poles.csv``, ``margins.csv``, ``gains.csv``: the analysis at the frozen point;
- with a sweep, ``poles_along.csv``, ``margins_along.csv``, ``gains_along.csv`` and
  ``along.png`` (the slowest modes' real parts and damping, and the margins, against the
  swept argument);
- ``config.yaml``: the experiment with every default filled in, as a run directory holds it;
- ``manifest.json`` last: what was analysed (controller, frozen point, sweep), how and where
  (:func:`nlcx.report.provenance`, :func:`nlcx.report.environment`) and the files.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from nlcx import manifest as manifests
from nlcx import plugins, rundir
from nlcx.analysis.frozen import AXES, schedule_axes
from nlcx.analysis.linear import pole_counts
from nlcx.drawing import new_figure, write_figure
from nlcx.report import environment, provenance, write_csv, write_text

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.axes import Axes

    from nlcx.analysis.frozen_results import FrozenSweep, Linearization

#: The ``nlcx_output`` kind its manifest names.
KIND = "linearize"
#: The slowest modes (one per real pole or conjugate pair) ``nlcx linearize`` prints.
MODES = 6
#: The sweep's figure shows the modes up to this many rad/s per 1/T (:func:`fastest_shown`).
SHOWN_BANDWIDTH = 0.2
#: The swept argument as the figure's x axis names it.
AXIS_LABELS = {"t": "Frozen time t (s)", "e": "Frozen error e"}


def save_analysis(
    out: Path,
    result: Linearization,
    along: FrozenSweep | None = None,
    overrides: Sequence[str] = (),
    started: float | None = None,
) -> Path:
    """Write the analysis directory ``out`` (new, empty, or one nlcx wrote, which it replaces
    whole): the files of the module docstring; ``overrides`` and ``started`` (a
    ``time.perf_counter()`` instant) are recorded in the manifest."""
    with rundir.staged(out) as stage:
        written = _tables(stage, result, along)
        path = stage / "config.yaml"
        write_text(path, yaml.safe_dump(result.experiment.resolved(), sort_keys=False, allow_unicode=True))
        written.append(path)
        info = manifest(result, along, overrides, started)
        info["files"] = [p.name for p in written]
        manifests.write(stage, info)
    return out


def _tables(stage: Path, result: Linearization, along: FrozenSweep | None) -> list[Path]:
    """The CSV files (and, with a sweep, its figure) written into ``stage``."""
    tables: dict[str, pd.DataFrame] = {"poles": result.poles, "margins": result.margins, "gains": result.gains}
    if along is not None:
        tables |= {"poles_along": along.poles, "margins_along": along.margins, "gains_along": along.gains}
    written = []
    for name, table in tables.items():
        path = stage / f"{name}.csv"
        write_csv(path, table)
        written.append(path)
    if along is not None:
        path = stage / "along.png"
        draw_along(path, along, f"{result.experiment.name}: controller {result.label}")
        written.append(path)
    return written


def manifest(
    result: Linearization, along: FrozenSweep | None, overrides: Sequence[str] = (), started: float | None = None
) -> dict[str, object]:
    """manifest.json: the name, the kind (``nlcx_output``: linearize), the controller, the frozen
    point and the sweep, how and where it was made; ``files`` is filled in by :func:`save_analysis`."""
    sweep = None
    if along is not None:
        sweep = {"axis": along.axis, "from": float(along.values[0]), "to": float(along.values[-1]),
                 "points": int(along.values.size)}  # fmt: skip
    return {
        "name": result.experiment.name,
        "nlcx_output": KIND,
        "controller": result.label,
        "at": {"t": result.at.t, "e": result.at.e},
        "along": sweep,
        "notes": list(result.notes),
        "imports": plugins.loaded(),
        **provenance(overrides, started),
        **environment(),
        "files": [],
    }


def _modes(poles: pd.DataFrame) -> pd.DataFrame:
    """One pole per mode (real poles, and the upper one of each conjugate pair), the slowest
    (rightmost) first."""
    return poles[poles.imag >= 0]


def fastest_shown(period: float) -> float:
    """The largest |p| (rad/s) the sweep's figure shows, :data:`SHOWN_BANDWIDTH` / T: faster,
    the continuous model of a PID that updates every T no longer holds (a backward
    difference's realisation puts its poles near 2/T)."""
    return SHOWN_BANDWIDTH / period


def _pole_scatter(ax: Axes, along: FrozenSweep, column: str) -> None:
    """``column`` of every mode slower than :func:`fastest_shown` against the swept argument."""
    for value, point in zip(along.values, along.points, strict=True):
        modes = _modes(point.poles)
        shown = modes[modes.omega_n <= fastest_shown(point.period)]
        ax.scatter(np.full(len(shown), value), shown[column], s=6, color="C0")


def _margin_curves(ax: Axes, along: FrozenSweep, column: str, decibels: bool = False) -> None:
    """``column`` of the margins at each opening against the swept argument (inf: no point)."""
    margins = along.margins
    for i, (kind, name) in enumerate(dict.fromkeys(zip(margins.opening, margins.name, strict=True))):
        values = margins[(margins.opening == kind) & (margins.name == name)][column].to_numpy(dtype=float)
        if decibels:
            with np.errstate(divide="ignore", invalid="ignore"):
                values = 20.0 * np.log10(np.abs(values))
        ax.plot(along.values, np.where(np.isfinite(values), values, np.nan), color=f"C{i}", lw=1.2,
                label=f"{kind} {name}")  # fmt: skip
    ax.legend(loc="best", fontsize=7)


def draw_along(path: Path, along: FrozenSweep, title: str) -> None:
    """The sweep's figure at ``path``: (a) the real parts and (b) the damping ratios of the
    closed-loop modes slower than :func:`fastest_shown`, (c) the gain margins (dB) and (d)
    the phase margins (degrees) of every opening, against the swept argument."""
    fig, axes = new_figure(2, 2, (9.0, 6.0))
    (real, damping), (gain, phase) = axes
    _pole_scatter(real, along, "real")
    _pole_scatter(damping, along, "zeta")
    _margin_curves(gain, along, "gain_margin", decibels=True)
    _margin_curves(phase, along, "phase_margin")
    labels = (
        (real, "(a) Closed-loop poles: real part", "Re p"), (damping, "(b) Closed-loop poles: damping ratio", "ζ"),
        (gain, "(c) Gain margin", "GM (dB)"), (phase, "(d) Phase margin", "PM (deg)"),
    )  # fmt: skip
    for ax, heading, ylabel in labels:
        ax.set_title(heading)
        ax.set_xlabel(AXIS_LABELS[along.axis])
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    fastest = fastest_shown(along.points[0].period)
    fig.suptitle(f"{title}; poles with |p| <= {fastest:g} rad/s", fontsize=9)
    fig.tight_layout()
    write_figure(path, fig)


def summary(result: Linearization, rows: int = MODES) -> list[str]:
    """The lines ``nlcx linearize`` prints: the frozen point, each loop's gains, the slowest
    closed-loop poles and the margins."""
    varying = {axis for loop in result.loops for axis in schedule_axes(loop.schedule)}
    axes = tuple(axis for axis in AXES if axis in varying)
    where = f"frozen at {result.at.describe(axes)}" if axes else "constant gains"
    if result.law_gains is not None:
        lines = [f"{result.experiment.name}: controller {result.label}, a control law linearised numerically"]
        lines.append(f"  {'input':<8}{'of':<14}{'gain':>12}   (d u / d signal; an LQR's are -K)")
        lines += [f"  {row.input:<8}{row.of:<14}{row.gain:>12.5g}" for row in result.law_gains.itertuples()]
    else:
        lines = [f"{result.experiment.name}: controller {result.label}, {where}"]
        lines.append(f"  {'loop':<10}{'input':<8}{'kp':>10}{'ki':>10}{'kd':>10}  derivative")
    for loop in result.loops:
        derivative = f"{loop.derivative}, N = {loop.N:.4g} 1/s" if loop.kd else "none"
        lines.append(f"  {loop.name:<10}{loop.input:<8}{loop.kp:>10.4g}{loop.ki:>10.4g}{loop.kd:>10.4g}  {derivative}")
    poles = result.poles
    unstable, on_axis = pole_counts(poles)
    lines.append(
        f"  closed loop: {len(poles)} poles, {unstable} in the right half-plane, {on_axis} on the imaginary axis; "
        "the slowest:"
    )
    for _, pole in _modes(poles).head(rows).iterrows():
        lines.append(
            f"    {_pole_text(pole.real, pole.imag):<24} zeta {_number(pole.zeta):>8}  omega_n {pole.omega_n:.4g}"
        )
    lines.append("  margins, loop broken at the plant input:")
    for _, row in result.margins.iterrows():
        gain = f"GM {_number(row.gain_margin):>8} at {_number(row.gain_margin_frequency):>8}"
        phase = f"PM {_number(row.phase_margin):>8} deg at {_number(row.phase_margin_frequency):>8}"
        lines.append(f"    {row.opening:<6}{row['name']:<10} {gain}  {phase}")
    return lines + [f"  note: {note}" for note in result.notes]


def _pole_text(real: float, imag: float) -> str:
    """``-0.45 ± 0.58j`` for a pair (given its upper pole), ``-1.6`` for a real pole."""
    return f"{real:.4g} ± {imag:.4g}j" if imag > 0 else f"{real:.4g}"


def _number(value: float) -> str:
    return "—" if value is None or math.isnan(value) else f"{value:.4g}"

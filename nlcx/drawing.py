"""Figures as plain data (:class:`FigurePlan`), drawn by matplotlib here or in a painter process.

A run's figures are planned where the results are (:mod:`nlcx.figure_plans`: which lines,
labels and axes) and drawn from the plan alone. The plan holds numbers and strings only, so
another process can draw it: ``nlcx run`` starts a :class:`Painter` before it imports the
simulation code, the painter imports matplotlib on the second core meanwhile, and draws while
the run writes its CSV files. The same plan gives the same PNG bytes in either process.

This module imports neither pandas nor the simulation code; matplotlib only where it draws.
"""

from __future__ import annotations

import io
import os
import pickle
import secrets
import subprocess
import sys
import textwrap
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from nlcx.runtime import module_command

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

#: Resolution of every PNG written.
DPI = 120


def atomic_write(path: Path, writer: Callable[[Path], object]) -> None:
    """Call ``writer(tmp)`` on a temporary file beside ``path``, then rename it to ``path``.

    The file gets the permissions of a file the process creates (``0o666`` less its umask),
    not those of a private temporary file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _new_file_beside(path)
    try:
        writer(tmp)
        os.replace(tmp, path)
    finally:
        with suppress(FileNotFoundError):
            tmp.unlink()


def _new_file_beside(path: Path) -> Path:
    """A new empty file ``.<name>.<random>.tmp`` in ``path``'s folder, made with mode ``0o666``
    (which the process's umask reduces, as for any file it creates)."""
    while True:
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return tmp


@dataclass(frozen=True)
class Line:
    """One curve of a panel: samples and matplotlib's colour, line style, width and legend entry."""

    t: np.ndarray
    y: np.ndarray
    color: str
    ls: str
    lw: float
    label: str


@dataclass(frozen=True)
class Panel:
    """One axes: its curves, title and labels; a legend when ``legend_size`` is set."""

    lines: tuple[Line, ...]
    title: str
    xlabel: str = ""
    ylabel: str = ""
    title_size: float | None = None
    tick_size: float | None = None
    legend_size: float | None = None


@dataclass(frozen=True)
class FigurePlan:
    """A grid of panels (row by row; cells without a panel are hidden), a title and a layout:
    ``column`` fixed margins in inches for a one-column figure, ``tight`` matplotlib's
    ``tight_layout``."""

    n_rows: int
    n_cols: int
    size: tuple[float, float]
    panels: tuple[Panel, ...]
    title: str | None = None
    layout: Literal["column", "tight"] = "column"


def new_figure(n_rows: int, n_cols: int, figsize: tuple[float, float]) -> tuple[Figure, np.ndarray]:
    """A figure and its (n_rows, n_cols) axes, rendered by Agg without pyplot's global state."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    axes = fig.subplots(n_rows, n_cols, squeeze=False)
    return fig, axes


def write_figure(path: Path, fig: Figure) -> None:
    """``fig`` as a PNG of :data:`DPI`, written atomically."""
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI))


def _draw_panel(ax: Axes, panel: Panel) -> None:
    for line in panel.lines:
        ax.plot(line.t, line.y, color=line.color, ls=line.ls, lw=line.lw, label=line.label)
    if panel.title_size:
        ax.set_title(panel.title, fontsize=panel.title_size)
    else:
        ax.set_title(panel.title)  # matplotlib's title size
    if panel.xlabel:
        ax.set_xlabel(panel.xlabel)
    if panel.ylabel:
        ax.set_ylabel(panel.ylabel)
    if panel.tick_size:
        ax.tick_params(labelsize=panel.tick_size)
    ax.grid(True, alpha=0.3)
    if panel.legend_size:
        ax.legend(loc="best", fontsize=panel.legend_size)


def _column_layout(fig: Figure, n_axes: int, title_lines: int) -> None:
    """Margins of a one-column figure in inches (the axes' labels, titles and the figure
    title fit); fixed margins cost nothing, ``tight_layout`` draws the whole figure once more."""
    width, height = fig.get_size_inches()
    top = 0.5 + 0.2 * title_lines
    bottom = 0.55
    gap = 0.85  # x label of one axes + title of the next
    axes_height = (height - top - bottom - gap * (n_axes - 1)) / n_axes
    fig.subplots_adjust(
        left=0.85 / width, right=1 - 0.25 / width, bottom=bottom / height, top=1 - top / height,
        hspace=gap / axes_height,
    )  # fmt: skip


def draw(plan: FigurePlan) -> Figure:
    """The matplotlib figure of ``plan``."""
    fig, axes = new_figure(plan.n_rows, plan.n_cols, plan.size)
    cells = list(axes.flat)
    for ax, panel in zip(cells, plan.panels, strict=False):
        _draw_panel(ax, panel)
    for ax in cells[len(plan.panels) :]:
        ax.set_visible(False)
    title = textwrap.fill(plan.title, 90) if plan.title else None
    if title:
        fig.suptitle(title, fontsize=9)
    if plan.layout == "tight":
        fig.tight_layout()
    else:
        _column_layout(fig, len(plan.panels), title.count("\n") + 1 if title else 0)
    return fig


def draw_all(jobs: list[tuple[Path, FigurePlan]]) -> None:
    """Draw every plan and write it to its path."""
    for path, plan in jobs:
        write_figure(path, draw(plan))


class Painter:
    """A process that imports matplotlib as soon as it starts and then draws the figures it is
    handed (:meth:`paint`, once). If it cannot start or fails, :meth:`paint` draws in this
    process instead, so a figure is never lost."""

    def __init__(self, command: list[str] | None = None) -> None:
        try:
            self._process: subprocess.Popen[bytes] | None = subprocess.Popen(
                command or module_command("nlcx.drawing"), stdin=subprocess.PIPE, stdout=subprocess.PIPE
            )
        except OSError:
            self._process = None

    def paint(self, jobs: list[tuple[Path, FigurePlan]]) -> bool:
        """Draw and write ``jobs``: in the painter process, or here if that one fails. Whether
        the painter process drew them."""
        process, self._process = self._process, None
        drawn = False
        if process is not None:
            with suppress(OSError, EOFError, pickle.UnpicklingError):
                reply, _ = process.communicate(pickle.dumps(jobs, protocol=pickle.HIGHEST_PROTOCOL))
                drawn = process.returncode == 0 and pickle.loads(reply) == "ok"
        if not drawn:
            draw_all(jobs)
        return drawn

    def close(self) -> None:
        """Stop the painter without drawing (a run that wrote no figure, or failed), at once."""
        process, self._process = self._process, None
        if process is not None:
            process.kill()
            process.communicate()


def _warm_up() -> None:
    """Draw a small figure with a title, labels and a legend into memory: the fonts, glyphs
    and renderer are loaded while the run is still simulating, not when its figure arrives."""
    t = np.linspace(0.0, 1.0, 50)
    panel = Panel((Line(t, t, "C0", "-", 1.0, "warm-up"),), "(a) x vs time", "Time (s)", "x (m)", legend_size=8)
    fig = draw(FigurePlan(1, 1, (3.0, 2.0), (panel,), title="warm-up"))
    fig.savefig(io.BytesIO(), format="png", dpi=DPI)


def _serve() -> None:
    """The painter process: import matplotlib, then draw the jobs read from stdin; reply "ok"
    and leave at once. Every file is written and closed by then; the interpreter's teardown of
    matplotlib's modules would only keep the run waiting."""
    import matplotlib.figure  # noqa: F401

    _warm_up()
    try:
        jobs = pickle.load(sys.stdin.buffer)
    except EOFError:  # the run ended without handing figures over (it failed or was interrupted)
        os._exit(0)
    draw_all(jobs)
    sys.stdout.buffer.write(pickle.dumps("ok"))
    sys.stdout.buffer.flush()
    os._exit(0)


if __name__ == "__main__":
    _serve()

"""The table :meth:`nlcx.Result.compare` returns: :class:`Comparison`, a pandas DataFrame that
prints as a block per signal fitting an 80-column terminal and shows as a compact table in a
notebook.

It is a DataFrame in every other respect (``.loc``, slicing, ``to_csv``): a table that an
operation on it gives (selecting rows or columns, ``round``, ``reset_index``) is a
:class:`Comparison` too, and prints as one while it still is one (indexed by (signal, metric),
with the columns of a comparison only), as pandas prints any other table; a column or a row is
a plain pandas Series.
"""

from __future__ import annotations

import html
import math
import textwrap
from collections.abc import Hashable, Sequence
from typing import Any, ClassVar, cast

import pandas as pd

from nlcx.comparison import SideBySide, check_columns, comparison, verdict

#: The width the printed table fits.
WIDTH = 80
#: The columns between the data columns of the printed table, and its indentation.
GAP, INDENT = "  ", "  "
#: What the printed and HTML tables show for a missing value.
MISSING = "—"


def change_column(controller: str) -> str:
    """The name of the change % column of ``controller``: ``change_<controller>_pct``."""
    return f"change_{controller}_pct"


class Comparison(pd.DataFrame):
    """Controllers side by side: indexed by (signal, metric); columns ``unit``, one per
    controller, ``change_<controller>_pct`` for each controller after the first (the baseline)
    and ``better`` (:func:`compare` defines each).

    Printed (``print``, ``repr``), it is a block per signal, each opened by the line that says
    which controller is better on how many of its metrics, with every controller side by side
    and every line at most 80 characters: columns that do not fit go into a second table
    under the first, never elided. Values show 4 significant digits, change % one decimal
    (the table holds every digit); ``to_string()`` is pandas' whole table. In a notebook it is
    a compact HTML table, the better value in bold. A table an operation on it gives is a
    :class:`Comparison` too (it keeps :attr:`statuses`).

    Examples
    --------
    >>> import nlcx
    >>> table = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=10"]).compare(["overshoot", "ise"])
    >>> type(table.round(2)).__name__, type(table.loc[("x", "overshoot")]).__name__
    ('Comparison', 'Series')
    >>> table.controllers
    ['conventional', 'proposed']
    >>> max(len(line) for line in repr(table).splitlines()) <= 80
    True
    """

    _metadata: ClassVar[list[str]] = ["statuses"]

    def __init__(self, data: Any = None, *args: Any, statuses: dict[str, str] | None = None, **kwargs: Any) -> None:
        super().__init__(data, *args, **kwargs)  # type: ignore[call-arg]  # pandas-stubs type DataFrame(...) as __new__
        #: Controller -> the status of its run (``ok``, or why its values are missing).
        self.statuses: dict[str, str] = dict(statuses) if statuses is not None else {}

    @property
    def _constructor(self) -> type[Comparison]:
        """What pandas builds the result of an operation with: a :class:`Comparison` (it keeps
        :attr:`statuses`; printed as blocks while it is still a comparison, :meth:`__repr__`)."""
        return Comparison

    @property
    def controllers(self) -> list[str]:
        """The controllers whose columns the table has, in its order; the first of the
        comparison is the baseline."""
        columns = [str(c) for c in self.columns]
        if self.statuses:
            return [c for c in self.statuses if c in columns]
        return [c for c in columns if c not in ("unit", "better") and not c.startswith("change_")]

    def _is_comparison(self) -> bool:
        """Whether the table is still a comparison: indexed by (signal, metric), with no column
        but the unit, controllers, change % and better."""
        known = {"unit", "better", *self.statuses}
        return (
            isinstance(self.index, pd.MultiIndex)
            and list(self.index.names) == ["signal", "metric"]
            and bool(self.statuses)
            and all(str(c) in known or str(c).startswith("change_") for c in self.columns)
        )

    def verdicts(self) -> list[str]:
        """One line per signal: which controller is better on how many of its metrics
        (:func:`nlcx.comparison.verdict`); none for fewer than two controllers."""
        if len(self.controllers) < 2 or "better" not in self:
            return []
        stopped = {c: s for c, s in self.statuses.items() if s != "ok"}
        return [verdict(str(s), self.controllers, [str(m) for m in rows.better], stopped) for s, rows in self._blocks()]

    def _blocks(self) -> list[tuple[Hashable, pd.DataFrame]]:
        """(signal, its rows) in the order of the rows."""
        signals = list(dict.fromkeys(self.index.get_level_values(0)))
        level = self.index.get_level_values(0)
        return [(s, pd.DataFrame(self[level == s])) for s in signals]

    def __repr__(self) -> str:
        if not self._is_comparison():
            return pd.DataFrame(self).__repr__()
        return "\n".join(self._lines(WIDTH))

    def __str__(self) -> str:
        return self.__repr__()

    def _lines(self, width: int) -> list[str]:
        controllers = self.controllers
        lines: list[str] = []
        if any(str(c).startswith("change_") for c in self.columns):
            lines += textwrap.wrap(f"Baseline {controllers[0]}; change % = 100 (other - baseline) / |baseline|", width)
        for c, status in self.statuses.items():
            if status != "ok":
                lines += textwrap.wrap(f"{c}: {status}, no value compared", width)
        if self.empty:
            return [*lines, "(no metric compared)"]
        blocks = self._blocks()
        verdicts = dict(zip([s for s, _ in blocks], self.verdicts(), strict=False))
        for signal, rows in blocks:
            if lines:
                lines.append("")
            said = verdicts.get(signal)
            lines += textwrap.wrap(said, width, subsequent_indent=INDENT) if said else [str(signal)]
            lines += _table(rows, controllers, self.statuses, width)
        return lines

    def _repr_html_(self) -> str | None:
        """A compact HTML table for notebooks: a row group per signal, the better value in bold."""
        if not self._is_comparison():
            return pd.DataFrame(self)._repr_html_()
        controllers = self.controllers
        changes = [c for c in self.columns if str(c).startswith("change_")]
        head = ["signal", "metric", "unit", *controllers, *(_change_header(str(c), changes) for c in changes)]
        has_better = "better" in self
        head += ["better"] if has_better else []
        cells = "".join(f"<th>{html.escape(str(h))}</th>" for h in head)
        parts = [f'<table class="nlcx-comparison" style="font-size:12px"><thead><tr>{cells}</tr></thead><tbody>']
        for signal, rows in self._blocks():
            for k, (key, row) in enumerate(rows.iterrows()):
                metric = cast("tuple[object, object]", key)[1]
                first = f'<th rowspan="{len(rows)}" style="text-align:left">{html.escape(str(signal))}</th>'
                tds = [first] if k == 0 else []
                tds += [
                    f"<td style='text-align:left'>{html.escape(str(v))}</td>" for v in (metric, row.get("unit", ""))
                ]
                best = str(row.get("better", "")) if has_better else ""
                for c in controllers:
                    text = html.escape(_value(row.get(c), self.statuses.get(c, "ok")))
                    tds.append(f"<td><b>{text}</b></td>" if c == best else f"<td>{text}</td>")
                tds += [f"<td>{html.escape(_percent(row.get(c)))}</td>" for c in changes]
                tds += [f"<td style='text-align:left'>{html.escape(best)}</td>"] if has_better else []
                parts.append("<tr>" + "".join(tds) + "</tr>")
        parts.append("</tbody></table>")
        notes = [*([f"Baseline {controllers[0]}: change % = 100 (other − baseline) / |baseline|"] if changes else []),
                 *self.verdicts()]  # fmt: skip
        return "".join(f"<p style='margin:2px 0'>{html.escape(n)}</p>" for n in notes) + "".join(parts)


def _value(value: object, status: str) -> str:
    """A controller's value as printed: 4 significant digits, its run's status where it stopped."""
    if isinstance(value, float) and math.isnan(value):
        return status if status != "ok" else MISSING
    if isinstance(value, float):
        return f"{value:.4g}"
    return MISSING if value is None else str(value)


def _percent(value: object) -> str:
    """A change % as printed: signed, one decimal."""
    if isinstance(value, float):
        return MISSING if math.isnan(value) else f"{value:+.1f}"
    return MISSING if value is None else str(value)


def _change_header(column: str, changes: Sequence[object]) -> str:
    """``change %``, or ``change % <controller>`` where several controllers are compared."""
    return "change %" if len(changes) == 1 else f"change % {column.removeprefix('change_').removesuffix('_pct')}"


def _table(rows: pd.DataFrame, controllers: list[str], statuses: dict[str, str], width: int) -> list[str]:
    """One signal's rows: metric and unit, then the values, the change % and the better
    controller; where these do not fit ``width``, a table of the values and the better
    controller, and the change % in as many tables under it as it takes (each repeats metric
    and unit)."""
    metrics = [str(m) for _, m in rows.index]
    fixed = [_column("metric", metrics, left=True)]
    if "unit" in rows:
        fixed.append(_column("unit", [str(u) for u in rows.unit], left=True))
    values = [_column(c, [_value(v, statuses.get(c, "ok")) for v in rows[c]]) for c in controllers if c in rows]
    names = [c for c in rows.columns if str(c).startswith("change_")]
    changes = [_column(_change_header(str(c), names), [_percent(v) for v in rows[c]]) for c in names]
    marks = [_column("better", [str(b) for b in rows.better], left=True)] if "better" in rows else []
    room = width - len(INDENT) - sum(len(c[0]) + len(GAP) for c in fixed)
    chunks = _packed([*values, *changes, *marks], room)
    if len(chunks) > 1:
        chunks = _packed([*values, *marks], room) + _packed(changes, room)
    lines = []
    for chunk in chunks:
        columns = [*fixed, *chunk]
        lines += [(INDENT + GAP.join(c[i] for c in columns)).rstrip() for i in range(len(metrics) + 1)]
    return lines


def _packed(columns: list[list[str]], room: int) -> list[list[list[str]]]:
    """The columns in order, in as few tables as keep each within ``room`` characters (a column
    wider than ``room`` alone in its table)."""
    chunks: list[list[list[str]]] = []
    used = room + 1
    for column in columns:
        size = len(column[0]) + len(GAP)
        if chunks and used + size <= room + len(GAP):
            chunks[-1].append(column)
            used += size
        else:
            chunks.append([column])
            used = size
    return chunks


def _column(header: str, cells: list[str], *, left: bool = False) -> list[str]:
    """A column's header and cells padded to one width (text to the left, numbers to the right)."""
    size = max(len(header), *(len(c) for c in cells)) if cells else len(header)
    return [(t.ljust(size) if left else t.rjust(size)) for t in (header, *cells)]


def frame_of(table: SideBySide) -> Comparison:
    """The :class:`Comparison` of a :class:`~nlcx.comparison.SideBySide`."""
    index = pd.MultiIndex.from_tuples([(r.signal, r.metric) for r in table.rows], names=["signal", "metric"])
    columns: dict[str, list[object]] = {"unit": [r.unit for r in table.rows]}
    for k, controller in enumerate(table.controllers):
        columns[controller] = [float(r.values[k]) for r in table.rows]
    for k, controller in enumerate(table.controllers[1:]):
        columns[change_column(controller)] = [float(r.changes[k]) for r in table.rows]
    columns["better"] = [r.better for r in table.rows]
    frame = pd.DataFrame(columns, index=index)
    numbers = {c: float for c in columns if c not in ("unit", "better")}
    return Comparison(frame.astype(numbers), statuses=table.status)


def compare(metrics: pd.DataFrame, names: Sequence[str] | None = None) -> Comparison:
    """Controllers side by side, per signal and metric, with the change % of each later
    controller against the first and the better controller of each metric.

    Parameters
    ----------
    metrics
        A long-form metrics frame as ``metrics.csv`` holds it: columns ``controller``,
        ``signal``, ``metric``, ``value``, ``unit``, ``status``, ``note`` (the last three
        optional), one run's rows.
    names
        The metrics to compare, exactly these; None: those of :data:`THESIS_METRICS` present.

    Returns
    -------
    Comparison
        A pandas DataFrame indexed by (signal, metric): signals in order of first appearance,
        each signal's metrics in order of first appearance. Columns: ``unit``; one float
        column per controller (in order of first appearance; NaN where it has no value or its
        run's status is not ``ok``); ``change_<controller>_pct`` for each controller after the
        first (the baseline): ``100 (controller - baseline) / |baseline|`` (:func:`change`),
        negative where that controller has the smaller value; ``better``: the controller with
        the better value (:func:`better`), ``tie``, or "" for a metric without a direction.
        Printed, it is a block per signal that fits 80 columns
        (:class:`~nlcx.comparison_frame.Comparison`).

    Raises
    ------
    NlcxError
        A required column is missing, ``names`` holds a metric the frame lacks, or a
        (controller, signal, metric) appears twice.

    Examples
    --------
    >>> import pandas as pd
    >>> from nlcx.comparison_frame import compare
    >>> metrics = pd.DataFrame({
    ...     "controller": ["conventional", "conventional", "proposed", "proposed"],
    ...     "signal": ["x", "x", "x", "x"],
    ...     "metric": ["rise_time", "ise", "rise_time", "ise"],
    ...     "value": [2.0, 0.5, 1.6, 0.6],
    ...     "unit": ["s", "m^2*s", "s", "m^2*s"],
    ...     "status": ["ok"] * 4,
    ...     "note": [""] * 4,
    ... })
    >>> table = compare(metrics)
    >>> print(table)  # doctest: +NORMALIZE_WHITESPACE
    Baseline conventional; change % = 100 (other - baseline) / |baseline|
    <BLANKLINE>
    x: conventional better on 1 of 2 metrics, proposed on 1
      metric     unit   conventional  proposed  change %  better
      rise_time  s                 2       1.6     -20.0  proposed
      ise        m^2*s           0.5       0.6     +20.0  conventional

    The proposed controller rises in 1.6 s instead of 2.0 s: 100 (1.6 - 2.0) / 2.0 = -20 %.

    >>> table["change_proposed_pct"].round(6).tolist()
    [-20.0, 20.0]
    >>> table.better.tolist()
    ['proposed', 'conventional']
    """
    check_columns(metrics.columns)
    records = cast("list[dict[str, object]]", metrics.to_dict("records"))  # its columns are named by strings
    return frame_of(comparison(records, names))

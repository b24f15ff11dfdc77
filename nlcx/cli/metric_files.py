"""What ``nlcx metrics`` reads from a file and measures in it.

The CSV or Parquet file is read and checked (:func:`read_frame`), its signals chosen
(:func:`signals_of`) and split per controller when it has a ``controller`` column, as nlcx's
time series do (:func:`blocks_of`); each signal is measured against its target (a step, a
constant it is regulated to, or a reference it tracks) by :mod:`nlcx.metrics`
(:func:`measure_block`). Every problem is one line naming the option, the value and what is
allowed (:func:`metrics_error`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from nlcx.errors import NlcxError, did_you_mean

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd


def metrics_error(key: str, value: object, problem: str, allowed: str) -> NlcxError:
    """The one-line error of ``nlcx metrics``: ``metrics error: KEY = VALUE: PROBLEM; allowed: ALLOWED``."""
    text = f"metrics error: {key} = {value}: {problem}; allowed: {allowed}"
    return NlcxError(" ".join(text.split()))  # one line, whatever a parser's message held


def name_list(names: list[str], limit: int = 20) -> str:
    """The first ``limit`` names, comma-separated, and how many more there are; "(none)" for none."""
    more = f", ... ({len(names) - limit} more)" if len(names) > limit else ""
    return (", ".join(names[:limit]) + more) or "(none)"


#: The column of nlcx's time series that names the controller of each sample.
CONTROLLER = "controller"
#: Suffix of the column holding a signal's reference in nlcx's time series (``x`` -> ``x_ref``).
REF_SUFFIX = "_ref"


@dataclass(frozen=True)
class Settings:
    """The metric definitions (nlcx's ``metrics:`` section, docs/metrics.md)."""

    settling_band: float
    rise_limits: tuple[float, float]
    ss_window: float


@dataclass(frozen=True)
class Block:
    """The samples of one controller (``name``), or of the whole file (``name`` None)."""

    name: str | None
    frame: pd.DataFrame
    t: np.ndarray

    def where(self) -> str:
        """How a message names the block: ``controller NAME, `` (empty for the whole file)."""
        return "" if self.name is None else f"controller {self.name}, "


@dataclass(frozen=True)
class SignalTarget:
    """What a signal is measured against, and how.

    ``step``: :func:`nlcx.metrics.step_info` from ``t_step`` to ``final`` (None: the signal's
    last sample); ``regulated``: :func:`nlcx.metrics.regulation_metrics` about the constant
    ``final``; ``tracked``: :func:`nlcx.metrics.error_integrals` of the reference column minus
    the signal. ``column``: the reference column; ``reason``: why a signal is measured so."""

    kind: Literal["step", "regulated", "tracked"]
    final: float | None
    t_step: float
    column: str | None = None
    reason: str = ""

    def describe(self, separator: str = "; final value: ") -> str:
        """E.g. ``step at 0 s; final value: x_ref = 1`` (``separator`` between the step time and
        the final value), ``regulated to theta_ref = 0``, ``tracking x_ref from 0 s``."""
        if self.kind == "regulated":
            return f"regulated to {self.column} = {self.final:g}"
        if self.kind == "tracked":
            return f"tracking {self.column} from {self.t_step:g} s"
        if self.final is None:
            final = "last sample"
        else:
            final = f"{self.final:g}" if self.column is None else f"{self.column} = {self.final:g}"
        return f"step at {self.t_step:g} s{separator}{final}"


def _csv_column(frame: pd.DataFrame, column: str, key: str, file: Path, where: str = "") -> np.ndarray:
    """Column ``column`` of ``frame`` as finite floats; a one-line error naming ``key`` if it is
    not (``where``: the controller whose rows ``frame`` holds, as the message names it)."""
    import numpy as np
    import pandas as pd

    raw = frame[column]
    values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64)
    text = np.isnan(values) & raw.notna().to_numpy()
    if text.any():
        k = int(np.argmax(text))
        numeric = [str(c) for c in frame.columns if pd.api.types.is_numeric_dtype(frame[c])]
        problem = f"not numeric in {file.name} ({where}data row {raw.index[k] + 1}: {raw.iloc[k]!r})"
        raise metrics_error(key, column, problem, f"a column of numbers: {name_list(numeric)}")
    bad = ~np.isfinite(values)
    if bad.any():
        k = int(np.argmax(bad))
        problem = f"empty or non-finite in {file.name} ({where}data row {raw.index[k] + 1}: {raw.iloc[k]})"
        raise metrics_error(key, column, problem, "a finite number in every row")
    return values


def read_frame(file: Path) -> pd.DataFrame:
    """The CSV (or Parquet) ``file`` with text column names; a one-line error if unreadable."""
    import pandas as pd

    allowed = "a CSV file with a header row, or a Parquet file"
    if not file.is_file():
        problem = "not a file" if file.exists() else "no such file"
        raise metrics_error("FILE", file, problem, allowed)
    parquet = file.suffix == ".parquet"
    try:
        frame = pd.read_parquet(file) if parquet else pd.read_csv(file)
    except (OSError, ValueError) as exc:  # pandas' and pyarrow's parser errors are ValueErrors or OSErrors
        raise metrics_error(
            "FILE", file, f"not readable as {'Parquet' if parquet else 'CSV'} ({exc})", allowed
        ) from None
    frame.columns = [str(c) for c in frame.columns]
    return frame


def reference_option(text: str | None, frame: pd.DataFrame, file: Path, time_column: str) -> float | str | None:
    """``--reference``: a number (what parses as one; it must be finite) or a column of numbers."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is not None:
        if not math.isfinite(value):
            raise metrics_error("--reference", text, "not finite", "a finite number, or a column")
        return value
    columns = [str(c) for c in frame.columns if c not in (time_column, CONTROLLER)]
    if text not in columns:
        hint = did_you_mean(text, columns)
        raise metrics_error(
            "--reference",
            text,
            f"neither a number nor a column of {file.name}{hint}",
            f"a number, or {name_list(columns)}",
        )
    return text


def _default_signals(frame: pd.DataFrame, time_column: str, reference: float | str | None) -> list[str]:
    """With no ``--signal``: every signal ``s`` with a reference column ``s_ref`` (the plant
    outputs of nlcx's time series), else every numeric column but time (and the reference)."""
    import pandas as pd

    columns = [c for c in frame.columns if c not in (time_column, CONTROLLER)]
    followed = [c for c in columns if c + REF_SUFFIX in columns]
    if followed:
        return followed
    return [c for c in columns if c != reference and pd.api.types.is_numeric_dtype(frame[c])]


def signals_of(
    frame: pd.DataFrame, file: Path, time_column: str, signals: list[str], reference: float | str | None
) -> list[str]:
    """The columns to measure: ``--signal`` (each once), or :func:`_default_signals`."""
    others = [c for c in frame.columns if c != time_column]
    names = list(dict.fromkeys(signals)) or _default_signals(frame, time_column, reference)
    if not names:
        problem = f"no column of numbers besides {time_column} in {file.name}"
        raise metrics_error("--signal", "(missing)", problem, f"a column of numbers: {name_list(others)}")
    for name in names:
        if name not in others:
            problem = "is the --time column" if name == time_column else f"not a column of {file.name}"
            problem += did_you_mean(name, others) if name != time_column else ""
            raise metrics_error("--signal", name, problem, name_list(others))
    return names


def blocks_of(frame: pd.DataFrame, file: Path, time_column: str) -> list[Block]:
    """The file's samples per controller (in the order they first appear) when it has a
    ``controller`` column (nlcx's time series stack its controllers' runs), else all of them;
    each block's times checked (at least 3, numbers, strictly increasing)."""
    import numpy as np

    if CONTROLLER in frame.columns:
        labels = frame[CONTROLLER].fillna("").astype(str).to_numpy()
        parts = [(name, frame[labels == name]) for name in dict.fromkeys(labels)]
    else:
        parts = [(None, frame)]
    blocks = []
    for name, part in parts:
        where = "" if name is None else f"controller {name}, "
        if len(part) < 3:
            samples = f"{len(part)} sample(s)" + ("" if name is None else f" of controller {name}")
            raise metrics_error("FILE", file, samples, "at least 3 samples")
        t = _csv_column(part, time_column, "--time", file, where)
        back = np.flatnonzero(np.diff(t) <= 0)
        if back.size:
            k = int(back[0]) + 1
            row = int(part.index[k]) + 1
            problem = f"not strictly increasing in {file.name} ({where}data row {row}: {t[k]:g} after {t[k - 1]:g})"
            raise metrics_error("--time", time_column, problem, "strictly increasing times")
        blocks.append(Block(name, part, t))
    return blocks


def source_of(name: str, reference: float | str | None, columns: list[str]) -> float | str | None:
    """What ``name`` is measured against: ``--reference`` if given, else its column ``name_ref``
    if the file has one, else (None) its last sample."""
    if reference is not None:
        return reference
    return name + REF_SUFFIX if name + REF_SUFFIX in columns else None


def _target(t: np.ndarray, y: np.ndarray, r: np.ndarray | None, source: Any, t_step: float | None) -> SignalTarget:
    """How a signal with samples ``y`` is measured against ``source`` (a number, None: its last
    sample, or the name of a column whose samples are ``r``; :func:`source_of`); ``t_step``: ``--t-step`` if given.

    A reference column that holds one value is a step to it, unless that value is 0 or the
    one the signal starts at: then there is no step, and the signal is regulated (nlcx's
    metrics for a constant reference). A column that changes once is a step at that change
    (its ``t_step`` unless ``--t-step`` is given); any other is tracked."""
    import numpy as np

    start = 0.0 if t_step is None else t_step
    if r is None:
        return SignalTarget("step", source, start)
    changes = np.flatnonzero(r[1:] != r[:-1])
    final = float(r[-1])
    if changes.size == 0:
        at_start = float(np.interp(start, t, y))
        if final == 0.0 or final == at_start:
            why = "is constant 0" if final == 0.0 else f"is constant {final:g}, the value the signal starts at"
            return SignalTarget("regulated", final, start, source, f"{source} {why}")
        return SignalTarget("step", final, start, source)
    if changes.size == 1:
        return SignalTarget("step", final, float(t[changes[0] + 1]) if t_step is None else t_step, source)
    return SignalTarget("tracked", None, start, source, f"{source} varies and is not one step")


def _check_t_step(block: Block, file: Path, target: SignalTarget) -> None:
    t = block.t
    if not t[0] <= target.t_step <= t[-3]:
        allowed = f"{t[0]:g} <= t_step <= {t[-3]:g} (at least 3 samples from the step on)"
        problem = f"outside the record of {file.name}" + ("" if block.name is None else f" (controller {block.name})")
        raise metrics_error("--t-step", f"{target.t_step:g}", problem, allowed)


def _measure(t: np.ndarray, y: np.ndarray, r: np.ndarray | None, target: SignalTarget, s: Settings) -> dict[str, float]:
    """The metrics of one signal by its target's kind (see :class:`SignalTarget`)."""
    import numpy as np

    from nlcx.metrics import error_integrals, regulation_metrics, step_info

    if target.kind == "step":
        info = step_info(
            t, y, reference=target.final, t_step=target.t_step, settling_band=s.settling_band, rise_limits=s.rise_limits
        )
        return {key: float(value) for key, value in info.items()}
    if target.kind == "regulated":
        assert target.final is not None  # a regulated target holds its constant
        i0 = int(np.searchsorted(t, target.t_step, side="left"))
        values = regulation_metrics(t[i0:], y[i0:], reference=target.final, band=s.settling_band, ss_window=s.ss_window)
    else:
        assert r is not None
        values = error_integrals(t, r - y, t0=target.t_step)
    return {key: float(value) for key, value in values.items()}


@dataclass(frozen=True)
class Measured:
    """One controller's (or the file's) metrics: per signal, its target and values."""

    block: Block
    targets: dict[str, SignalTarget]
    values: dict[str, dict[str, float]]


def measure_block(
    block: Block,
    file: Path,
    names: list[str],
    sources: dict[str, float | str | None],
    t_step: float | None,
    s: Settings,
) -> Measured:
    """Each signal ``names`` of ``block`` measured against its target, from its source in ``sources``
    (:func:`source_of`); ``t_step``: ``--t-step`` if given."""
    where = block.where()
    targets, values = {}, {}
    for name in names:
        y = _csv_column(block.frame, name, "--signal", file, where)
        source = sources[name]
        r = _csv_column(block.frame, source, "--reference", file, where) if isinstance(source, str) else None
        targets[name] = _target(block.t, y, r, source, t_step)
        _check_t_step(block, file, targets[name])
        values[name] = _measure(block.t, y, r, targets[name], s)
    return Measured(block, targets, values)


def checked_settings(settling_band: float, rise_limits: tuple[float, float], ss_window: float) -> Settings:
    """The metric options, checked as nlcx's ``metrics:`` section checks them."""
    if not 0 < settling_band < 1:
        raise metrics_error("--settling-band", f"{settling_band:g}", "outside (0, 1)", "0 < band < 1")
    lo, hi = rise_limits
    if not 0 <= lo < hi <= 1:
        raise metrics_error("--rise-limits", f"{lo:g} {hi:g}", "not ordered within [0, 1]", "0 <= LOW < HIGH <= 1")
    if not (math.isfinite(ss_window) and ss_window > 0):
        raise metrics_error("--ss-window", f"{ss_window:g}", "not a positive number of seconds", "a time > 0 s")
    return Settings(settling_band, (lo, hi), ss_window)

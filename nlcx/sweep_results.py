"""What a sweep gives back in Python: :class:`SweepResult`, its variants and metrics, with the
share of stable variants per controller, their distributions and the runs of chosen variants."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nlcx.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from nlcx.results import Result

__all__ = ["SweepResult"]


class SweepResult:
    """A sweep's variants and metrics.

    Attributes
    ----------
    variants : pandas.DataFrame
        The table ``sweep`` (sweep.parquet, or sweep.csv): one row a variant: its index, the
        varied values (``value:<key>``), seed, config hash, status (ok, unstable or failed)
        and message ("" for none), as :func:`~nlcx.results.read_output_table` reads it.
    metrics : pandas.DataFrame
        The table ``metrics`` (metrics.parquet, or metrics.csv): the metrics of every
        variant's runs (a ``variant`` column in front), as :func:`~nlcx.results.read_output_table` reads it.
    directory : pathlib.Path or None
        Where the sweep was written, if ``out`` was given.
    """

    def __init__(self, variants: pd.DataFrame, metrics: pd.DataFrame, directory: Path | None) -> None:
        self.variants = variants
        self.metrics = metrics
        self.directory = directory

    def summary(self) -> pd.DataFrame:
        """Per controller, signal and metric over the variants: n, median, quartiles, IQR, min,
        max and the counts of undefined, unstable and failed (summary.csv of the sweep report).

        Returns
        -------
        pandas.DataFrame
            One row per (controller, signal, metric).

        Examples
        --------
        >>> import nlcx
        >>> swept = nlcx.sweep("configs/sweeps/robustness.yaml",
        ...                    ["sweep.random.n=2", "simulation.t_end=2"], executor="serial")
        >>> row = swept.summary().set_index(["controller", "signal", "metric"]).loc[("proposed", "x", "peak")]
        >>> int(row.n + row.unstable + row.undefined)
        6
        """
        from nlcx.pages.sweep import summary

        return summary(self.metrics, self.variants)

    def stability(self) -> pd.DataFrame:
        """Per controller: in how many variants its run was ok, unstable or failed, and the
        share of stable variants.

        Returns
        -------
        pandas.DataFrame
            Indexed by controller (in the order the metrics first name them), columns ``ok``
            (variants its run was ok in), ``unstable`` (the variant ran and this controller's
            run stopped), ``failed`` (the variant did not run: a bad config), ``variants``
            (their sum: every variant of the sweep) and ``stable_share`` = ok / variants.

        Examples
        --------
        >>> import nlcx
        >>> swept = nlcx.sweep("configs/sweeps/robustness.yaml",
        ...                    ["sweep.random.n=2", "simulation.t_end=2"], executor="serial")
        >>> table = swept.stability()
        >>> table.columns.tolist()
        ['ok', 'unstable', 'failed', 'variants', 'stable_share']
        >>> bool((table.ok + table.unstable + table.failed == len(swept.variants)).all())
        True
        """
        from nlcx.pages.sweep import stability

        return stability(self.metrics, self.variants)

    def plot(self, metric: str, signal: str | None = None) -> Figure:
        """The distribution of ``metric`` over the variants: a box per controller, one axes per
        signal that has the metric.

        Parameters
        ----------
        metric : str
            A metric of the sweep's metrics table (e.g. ``overshoot``, ``ise``).
        signal : str, optional
            The signal; default: every signal that has ``metric``, one axes each.

        Returns
        -------
        matplotlib.figure.Figure
            Per axes, one box per controller over the variants whose run was ok and measured
            the metric (quartiles, median, whiskers to 1.5 IQR, outliers as points); each
            controller's tick label says that n and how many of its runs were unstable
            (:meth:`stability`). Not
            shown or saved; in a notebook it displays as the cell's value.

        Raises
        ------
        nlcx.errors.ConfigError
            For a metric, or a signal, the sweep has no values of.

        Examples
        --------
        >>> import nlcx
        >>> swept = nlcx.sweep("configs/sweeps/robustness.yaml",
        ...                    ["sweep.random.n=2", "simulation.t_end=2"], executor="serial")
        >>> fig = swept.plot("ise")
        >>> [ax.get_title() for ax in fig.axes]
        ['x: ise over 6 variants', 'theta: ise over 6 variants']
        """
        from nlcx.drawing import new_figure
        from nlcx.figure_plans import line_style

        rows = self.metrics[self.metrics.metric == metric]
        if rows.empty:
            known = ", ".join(str(m) for m in dict.fromkeys(self.metrics.metric)) or "(none)"
            raise ConfigError("metric", metric, f"not a metric of this sweep; allowed: {known}")
        signals = [str(s) for s in dict.fromkeys(rows.signal)]
        if signal is not None and signal not in signals:
            raise ConfigError("signal", signal, f"no {metric} in this sweep; allowed: {', '.join(signals)}")
        chosen = signals if signal is None else [signal]
        controllers = [str(c) for c in dict.fromkeys(self.metrics.controller)]
        unstable = self.stability().unstable
        fig, axes = new_figure(len(chosen), 1, (max(4.5, 1.6 * len(controllers) + 1.5), 3.0 * len(chosen)))
        for ax, name in zip(axes[:, 0], chosen, strict=True):
            here = rows[rows.signal == name]
            data, labels = [], []
            for c in controllers:
                mine = here[here.controller == c]
                values = mine[mine.status == "ok"].value.to_numpy(dtype=float)
                values = values[np.isfinite(values)]
                data.append(values)
                labels.append(f"{c}\nn = {values.size}, unstable {int(unstable.get(c, 0))}")
            boxes = ax.boxplot(data, tick_labels=labels, patch_artist=True, widths=0.5)
            for k, box in enumerate(boxes["boxes"]):
                box.set_facecolor(line_style(k)[0])
                box.set_alpha(0.6)
                box.set_label(controllers[k])
            unit = str(here.unit.iloc[0]) if "unit" in here and len(here) else ""
            ax.set_ylabel(f"{metric} ({unit})" if unit else metric)
            ax.set_title(f"{name}: {metric} over {len(self.variants)} variants", fontsize=10)
            ax.grid(True, axis="y", alpha=0.3)
        fig.tight_layout()
        return fig

    def trajectories(self, variants: int | Sequence[int], controller: str | None = None) -> dict[int, Result]:
        """The chosen variants' runs, time series included: read from the sweep directory where
        the sweep recorded them (``sweep.timeseries: true``), else run again from the
        variant's config, which the sweep directory's config.yaml and the variant's index
        determine.

        A variant run again is the run the sweep made: its config is rebuilt as the sweep
        built it (its values and seed set on the base config), and its metrics are checked
        against the sweep's rows of that variant, value for value (the same bits; NaN where
        the sweep has NaN), before it is returned.

        Parameters
        ----------
        variants : int or sequence of int
            Variant indices (the ``variant`` column of :attr:`variants`).
        controller : str, optional
            Keep this controller's run only; default: every controller's.

        Returns
        -------
        dict of int to Result
            Variant -> its :class:`Result` (``trajectory(controller)``, ``plot()``,
            ``compare()``), in the order asked. Its metrics are the sweep's rows of the variant
            when read from the directory, every metric of the run when run again.

        Raises
        ------
        nlcx.errors.ConfigError
            A sweep without a directory (``nlcx.sweep`` without ``out``), an index that is not
            a variant of the sweep, a variant that failed (it has no run), or an unknown
            controller.
        nlcx.errors.NlcxError
            A variant run again whose metrics differ from the sweep's (the sweep directory's
            config.yaml does not determine it: e.g. a varied key that another key referred to
            before interpolation).

        Examples
        --------
        >>> import tempfile, nlcx
        >>> with tempfile.TemporaryDirectory() as tmp:
        ...     swept = nlcx.sweep("configs/sweeps/robustness.yaml", ["sweep.random.n=2",
        ...                        "simulation.t_end=2"], executor="serial", out=f"{tmp}/sweep")
        ...     runs = swept.trajectories([0, 4])
        >>> sorted(runs), runs[4].controllers
        ([0, 4], ['conventional', 'proposed'])
        >>> float(runs[4].trajectory("proposed").t.iloc[-1])
        2.0
        """
        from nlcx.sweeps.variant_runs import variant_results

        chosen = [int(variants)] if isinstance(variants, int | np.integer) else [int(v) for v in variants]
        return variant_results(self, chosen, controller)

    def __repr__(self) -> str:
        counts = self.variants.status.value_counts().to_dict() if "status" in self.variants else {}
        shown = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
        return f"<nlcx.SweepResult {len(self.variants)} variants: {shown}>"

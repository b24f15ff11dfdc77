"""What a run gives back in Python: :class:`Result`, :func:`load_run`, which reads a run
directory into a :class:`Result`, and :func:`read_output_table`, which reads a sweep's tables
(``sweep`` and ``metrics``) in either of the forms a sweep writes them: Parquet (the default) or
CSV (``sweep.format: csv``). A sweep's is :class:`nlcx.sweep_results.SweepResult`.

A :class:`Result` holds one experiment's metrics, trajectories and figure by name, whether it
comes from the simulation (:func:`nlcx.run`) or from a run directory (:func:`load_run`): both give
the same metrics, column for column.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from nlcx import compiled_cache, manifest, safe_yaml
from nlcx.errors import ConfigError
from nlcx.pages.output_tables import read_output_table
from nlcx.run_files import (
    METRIC_COLUMNS,
    RECORDED_SIGNALS,
    copy_run,
    metrics_frame,
    outputs_of,
    read_metrics,
    read_timeseries,
    recorded_outputs,
    timeseries_file,
)

if TYPE_CHECKING:
    import control as ct
    import pandas as pd
    from matplotlib.figure import Figure

    from nlcx import engine
    from nlcx.comparison_frame import Comparison
    from nlcx.drawing import FigurePlan

__all__ = ["METRIC_COLUMNS", "Result", "load_run", "read_output_table"]


class Result:
    """The runs of one experiment: its metrics, trajectories and figure, by name.

    Built by :func:`nlcx.run` (from the simulation) or :func:`load_run` (from a run directory);
    both give the same metrics, column for column.

    Attributes
    ----------
    name : str
        The experiment's name.
    config : dict
        The resolved config: every default filled in, as config.yaml holds it.
    metrics : pandas.DataFrame
        Long form, the columns of metrics.csv: controller, signal, metric, value, unit,
        status, note (docs/metrics.md defines each metric).
    controllers : list of str
        The controllers' labels, in the config's order.
    directory : pathlib.Path or None
        The run directory it was read from or last saved to.
    """

    def __init__(
        self,
        name: str,
        config: dict[str, Any],
        metrics: pd.DataFrame,
        statuses: dict[str, str],
        trajectories: dict[str, pd.DataFrame] | None,
        outputs: list[tuple[str, str, str]],
        *,
        source: engine.ExperimentResult | None = None,
        directory: Path | None = None,
        signals: Mapping[str, Sequence[Any]] | None = None,
    ) -> None:
        self.name = name
        self.config = config
        self.metrics = metrics
        self._statuses = statuses
        self._trajectories = trajectories
        self._outputs = outputs
        self._source = source
        self.directory = directory
        #: The plant's ``states`` and ``inputs`` by name, in its order, and its ``output_matrix`` C.
        self._signals = {kind: list(values) for kind, values in (signals or {}).items()}

    @classmethod
    def from_engine(cls, result: engine.ExperimentResult) -> Result:
        """The :class:`Result` of a run the engine returned (:func:`nlcx.engine.run_experiment`)."""
        from nlcx import report

        plant = result.prepared.plant
        trajectories = {run.label: _frame(report._run_columns(run, plant)) for run in result.runs}
        return cls(
            name=result.prepared.experiment.name,
            config=result.prepared.experiment.resolved(),
            metrics=metrics_frame(result.metrics),
            statuses={run.label: run.status for run in result.runs},
            trajectories=trajectories,
            outputs=[(s.name, s.unit, s.label) for s in plant.outputs],
            source=result,
            signals={"states": plant.state_names, "inputs": plant.input_names, "output_matrix": plant.C.tolist()},
        )

    @property
    def controllers(self) -> list[str]:
        return list(self._statuses)

    def status(self, controller: str) -> str:
        """``ok``, or ``unstable`` for a run stopped where it diverged (a result, not an error)."""
        return self._statuses[self._known(controller)]

    def _known(self, controller: str) -> str:
        if controller not in self._statuses:
            raise ConfigError(
                "controller", controller, f"not a controller of this run; allowed: {', '.join(self._statuses)}"
            )
        return controller

    def compare(self, metrics: Sequence[str] | None = None) -> Comparison:
        """Controllers side by side: per (signal, metric), one column per controller, the change
        % of each controller against the first (the baseline) and which one is better.

        Parameters
        ----------
        metrics : sequence of str, optional
            Metric names; default: rise and settling time, overshoot, peak (peak deviation for
            a regulated signal), ISE, IAE and ITAE.

        Returns
        -------
        nlcx.Comparison
            A pandas DataFrame indexed by (signal, metric), with columns ``unit``, one per
            controller, ``change_<controller>_pct`` = 100 (controller - baseline) / |baseline|
            per controller after the first, and ``better`` (the controller with the better
            value by the metric's direction, ``tie``, or "" for a metric without one;
            :data:`nlcx.comparison.DIRECTIONS`). Printed, a block per signal within 80 columns.

        Examples
        --------
        >>> import nlcx
        >>> result = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=10"])
        >>> row = result.compare(["overshoot"]).loc[("x", "overshoot")]
        >>> expected = 100 * (row.proposed - row.conventional) / abs(row.conventional)
        >>> bool(abs(row.change_proposed_pct - expected) < 1e-9)
        True
        >>> row.better == ("proposed" if row.proposed < row.conventional else "conventional")
        True
        """
        from nlcx.comparison_frame import compare

        return compare(self.metrics, metrics)

    def trajectory(self, controller: str) -> pd.DataFrame:
        """One controller's samples: ``t`` and every state, input, reference (``<output>_ref``)
        and logged loop quantity (gains ``<loop>.kp``, ..., loop outputs) by name; the outputs
        are states and appear under their names.

        Parameters
        ----------
        controller : str
            A label of :attr:`controllers`.

        Returns
        -------
        pandas.DataFrame
            One row a sample, SI units, angles in rad. A run that diverged ends where it stopped.

        Raises
        ------
        nlcx.errors.ConfigError
            For an unknown controller, or a run directory written without time series.

        Examples
        --------
        >>> import nlcx
        >>> result = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=2"])
        >>> frame = result.trajectory("proposed")
        >>> list(frame.columns[:6])
        ['t', 'x', 'x_dot', 'theta', 'theta_dot', 'F_x']
        >>> float(frame.t.iloc[-1])
        2.0
        """
        self._known(controller)
        if self._trajectories is None:
            raise ConfigError(
                "trajectory", controller, "this run was written without time series (outputs.timeseries: false)"
            )
        return self._trajectories[controller].copy()

    def response(self, controller: str) -> ct.TimeResponseData:
        """One controller's run as python-control's ``TimeResponseData``: its outputs, inputs and
        states over time, named as the plant names them, so that python-control's plotting
        (``.plot()``) and ``step_info`` (of ``.outputs[i]`` over ``.time``) work on it.

        Parameters
        ----------
        controller : str
            A label of :attr:`controllers`.

        Returns
        -------
        control.TimeResponseData
            ``time``; ``outputs`` (one row per plant output), ``inputs`` and ``states`` likewise;
            a run that diverged ends where it stopped.

        Examples
        --------
        >>> import control, nlcx
        >>> response = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=20"]).response("proposed")
        >>> response.output_labels, response.input_labels
        (['x', 'theta'], ['F_x'])
        >>> info = control.step_info(response.y[0], response.time, final_output=1.0)
        >>> round(info["Overshoot"], 2)
        28.31
        """
        import control as ct

        frame = self.trajectory(controller)
        outputs = [name for name, _, _ in self._outputs]
        states, inputs = list(self._signals.get("states", [])), list(self._signals.get("inputs", []))
        missing = [name for name in (*states, *inputs) if name not in frame.columns]
        if missing or not states:
            wanted = "a run whose plant's states and inputs nlcx recorded (an output of this nlcx)"
            raise ConfigError("controller", controller, f"{wanted}; missing: {', '.join(missing) or 'its signals'}")
        x = frame[states].to_numpy().T
        y = np.asarray(self._signals["output_matrix"], dtype=float) @ x
        return ct.TimeResponseData(
            frame.t.to_numpy(), y, states=x,
            inputs=frame[inputs].to_numpy().T, output_labels=outputs, state_labels=states, input_labels=inputs,
            title=f"{self.name}: {controller}", sysname=controller,
        )  # fmt: skip

    def plot(self, signals: Sequence[str] | None = None, *, title: str | None = None) -> Figure:
        """The thesis's figure layout: one axes per output, every controller overlaid, the
        reference dotted.

        Parameters
        ----------
        signals : sequence of str, optional
            Outputs to draw; default: every output.
        title : str, optional
            Figure title; default: the config's title.

        Returns
        -------
        matplotlib.figure.Figure
            Not shown or saved; in a notebook it displays as the cell's value.

        Examples
        --------
        >>> import nlcx
        >>> fig = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=2"]).plot()
        >>> [ax.get_title() for ax in fig.axes]
        ['(a) Position x vs time', '(b) Angle θ vs time']
        """
        from nlcx.drawing import draw

        return draw(self._plan(signals, title))

    def _plan(self, signals: Sequence[str] | None, title: str | None) -> FigurePlan:
        """The figure's plan (:class:`nlcx.drawing.FigurePlan`) from the trajectories."""
        from nlcx.drawing import FigurePlan, Line, Panel
        from nlcx.figure_plans import finite_for_plot, line_style, thinned

        names = [o[0] for o in self._outputs]
        chosen = list(signals) if signals is not None else names
        for name in chosen:
            if name not in names:
                raise ConfigError("signals", name, f"not an output of the plant; allowed: {', '.join(names)}")
        panels = []
        for k, name in enumerate(chosen):
            _, unit, label = self._outputs[names.index(name)]
            lines = []
            for i, controller in enumerate(self.controllers):
                frame = self.trajectory(controller)
                color, ls = line_style(i)
                legend = controller if self.status(controller) == "ok" else f"{controller} ({self.status(controller)})"
                t, y = thinned(frame.t.to_numpy(), finite_for_plot(frame[name].to_numpy()))
                lines.append(Line(t, y, color=color, ls=ls, lw=1.3, label=legend))
            first = self.trajectory(self.controllers[0])
            if f"{name}_ref" in first:
                t, r = thinned(first.t.to_numpy(), first[f"{name}_ref"].to_numpy())
                lines.append(Line(t, r, color="k", ls=":", lw=1.0, label="reference"))
            ylabel = f"{label or name} ({unit})" if unit else (label or name)
            panels.append(Panel(tuple(lines), f"({chr(ord('a') + k)}) {label or name} vs time",
                                xlabel="Time (s)", ylabel=ylabel, legend_size=8))  # fmt: skip
        heading = title if title is not None else self.config.get("title")
        return FigurePlan(
            len(panels), 1, (7.5, 2.9 * len(panels)), tuple(panels), title=heading or None, layout="column"
        )

    def save(self, directory: str | os.PathLike[str], *, report: bool = True) -> Path:
        """Write the run directory, exactly as ``nlcx run --out DIRECTORY`` does: metrics.csv,
        timeseries, figures, config.yaml, manifest.json and (``report=True``) report.html and
        report.md. A directory that nlcx wrote before is replaced whole.

        Parameters
        ----------
        directory : str or path
            The run directory.
        report : bool
            Also write the report page.

        Returns
        -------
        pathlib.Path
            The run directory.
        """
        target = Path(directory)
        if self._source is not None:
            from nlcx.rundir import save_run

            save_run(self._source, target, with_report=report)
        elif self.directory is not None:
            copy_run(self.directory, target)
        else:  # pragma: no cover - a Result is built from a run or a directory
            raise ConfigError("directory", str(target), "a result of nlcx.run or nlcx.load_run")
        self.directory = target
        return target

    def __repr__(self) -> str:
        runs = ", ".join(f"{c} ({s})" for c, s in self._statuses.items())
        return f"<nlcx.Result {self.name}: {runs}; {len(self.metrics)} metric rows>"

    def _repr_html_(self) -> str:
        """In a notebook: the comparison table under the experiment's name (escaped by pandas)."""
        import html

        return f"<p><b>{html.escape(self.name)}</b>: {html.escape(repr(self))}</p>" + (
            self.compare()._repr_html_() or ""
        )


def _frame(columns: Mapping[str, np.ndarray]) -> pd.DataFrame:
    import pandas as pd

    return pd.DataFrame({name: np.asarray(values) for name, values in columns.items()})


def load_run(directory: str | os.PathLike[str]) -> Result:
    """Read a run directory (written by ``nlcx run`` or :meth:`Result.save`) back.

    Parameters
    ----------
    directory : str or path
        The run directory: metrics.csv, config.yaml and manifest.json; timeseries.csv or
        .parquet if the run wrote them. Each file read is checked against the SHA-256 the
        manifest records first.

    Returns
    -------
    Result
        The metrics equal those :func:`nlcx.run` returned; trajectories when the directory has
        time series.

    Raises
    ------
    nlcx.errors.ConfigError
        If ``directory`` is not a directory.
    nlcx.manifest.IntegrityError
        If its manifest cannot be read or is not a run's, a file it reads does not match
        the checksum the manifest recorded (truncated or altered): nothing is read in part;
        or the time series its config wrote is missing (the line says how to write it again).

    Examples
    --------
    >>> import tempfile, nlcx
    >>> result = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=2"])
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     again = nlcx.load_run(result.save(f"{tmp}/run", report=False))
    >>> again.metrics.equals(result.metrics)
    True
    """
    compiled_cache.ready()  # before the plant's model (and its compiled functions) is loaded
    path = Path(directory)
    if not path.is_dir():
        raise ConfigError("directory", str(path), "a run directory (nlcx run --out DIR, Result.save)")
    record = manifest.load(path)
    listed: dict[str, dict[str, object]] = record.get("checksums", {})  # validated by manifest.load
    if record.get(manifest.MARKER) != "run" or "metrics.csv" not in listed or "config.yaml" not in listed:
        raise manifest.IntegrityError(
            path / manifest.MANIFEST, "not the manifest of a run with checksums of its files (an output of "
            "another kind, or of an nlcx that recorded none)", "a run directory: write it again with nlcx run",
        )  # fmt: skip
    manifest.verify(path, ["config.yaml", "metrics.csv"])
    config = safe_yaml.load_file(path / "config.yaml")
    if not isinstance(config, dict):
        raise manifest.IntegrityError(path / "config.yaml", "not a mapping of sections", "the config nlcx wrote")
    outputs = config.get("outputs")
    series = timeseries_file(path, listed, written=isinstance(outputs, dict) and outputs.get("timeseries") is True)
    if series is not None:
        manifest.verify(path, [series.name])
    metrics = read_metrics(path / "metrics.csv")
    statuses = {r["controller"]: r["status"] for r in record.get("runs", [])}
    if not statuses:
        statuses = dict(metrics.groupby("controller", sort=False).status.first())
    return Result(
        name=str(config.get("name", path.name)),
        config=config,
        metrics=metrics,
        statuses=statuses,
        trajectories=read_timeseries(series),
        outputs=recorded_outputs(record) or outputs_of(config),
        directory=path,
        signals={kind: record[kind] for kind in RECORDED_SIGNALS if isinstance(record.get(kind), list)},
    )

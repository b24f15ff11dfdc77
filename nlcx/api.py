"""nlcx from Python: run and sweep experiments.

:func:`run` simulates every controller of a config on its plant and returns a
:class:`~nlcx.results.Result` (metrics, comparison, trajectories, figure) without writing
anything unless asked; :func:`sweep` runs a config's ``sweep:`` section and returns a
:class:`~nlcx.sweep_results.SweepResult`; :func:`nlcx.results.load_run` reads a run directory back into
a ``Result``. The command line (``nlcx run``, ``nlcx sweep``) runs the same code.
"""

from __future__ import annotations

import copy
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Union

from nlcx import compiled_cache, runtime
from nlcx._numba_compat import quiet_first_class_functions
from nlcx.errors import ConfigError
from nlcx.limits import MAX_JOBS, check_count
from nlcx.plugins import load_config_imports
from nlcx.results import Result, load_run, read_output_table
from nlcx.sweep_results import SweepResult

if TYPE_CHECKING:
    from nlcx.config import Experiment

__all__ = ["Result", "SweepResult", "experiment", "load_run", "run", "sweep"]

#: A config: a YAML file's path, a mapping of sections, or a validated experiment.
ConfigLike = Union[str, "os.PathLike[str]", Mapping[str, object], "Experiment"]
#: Overrides: ``["key=value", "+key=value", "~key"]`` strings, or a nested mapping merged on top.
OverridesLike = Union[Sequence[str], Mapping[str, object], None]  # noqa: UP007 - a runtime alias, as ConfigLike


def _raw(config: ConfigLike) -> dict[str, object]:
    """The raw (not yet interpolated) mapping of ``config``."""
    from nlcx import config as cfg
    from nlcx.config import Experiment

    if isinstance(config, Experiment):
        return copy.deepcopy(config.raw)
    if isinstance(config, Mapping):
        return copy.deepcopy(dict(config))
    if isinstance(config, (str, os.PathLike)):
        return cfg.read_config(os.fspath(config))
    raise ConfigError("config", type(config).__name__, "a YAML path, a mapping of sections or an Experiment")


def _with_overrides(raw: dict[str, object], overrides: OverridesLike) -> dict[str, object]:
    """``raw`` with ``overrides`` applied: strings in the command line's grammar, or a nested
    mapping merged on top as an ``extends:`` child is (a section whose ``kind`` changes is replaced)."""
    from nlcx import config as cfg

    if overrides is None:
        return raw
    if isinstance(overrides, Mapping):
        return cfg.deep_merge(raw, dict(overrides))
    if isinstance(overrides, str):
        raise ConfigError("overrides", overrides, "a list of key=value strings (not one string) or a mapping")
    return cfg.apply_overrides(raw, list(overrides))


def experiment(config: ConfigLike, overrides: OverridesLike = None, *, allow_env: bool = False) -> Experiment:
    """The validated experiment of ``config`` with ``overrides``.

    Parameters
    ----------
    config : str, path, mapping or Experiment
        A YAML file (its ``extends:`` are merged), a mapping of sections as such a file holds,
        or an experiment validated before.
    overrides : list of str or mapping, optional
        ``["simulation.t_end=5", "+simulation.bounds.x=5", "~uncertainty.disturbance"]``, or a
        nested mapping merged on top.
    allow_env : bool
        Let the config's ``${...}`` call every resolver OmegaConf knows, ``oc.env`` (the
        process's environment) included; off, a config reads only its own values.

    Returns
    -------
    nlcx.config.Experiment
        Every key validated, every default filled in.

    Raises
    ------
    nlcx.errors.ConfigError
        One line naming the key, the bad value and what is allowed.

    Examples
    --------
    >>> import nlcx
    >>> exp = nlcx.experiment("configs/x_error_ags.yaml", ["simulation.t_end=5"])
    >>> exp.section.simulation.t_end, [c.label for c in exp.controllers]
    (5.0, ['conventional', 'proposed'])
    """
    compiled_cache.ready()  # before a plugin's compiled functions are loaded
    from nlcx import config as cfg

    with runtime.cache_access():  # a plugin's compiled functions may load from numba's cache
        raw = load_config_imports(_with_overrides(_raw(config), overrides))
        if "sweep" in raw:
            raise ConfigError("sweep", "...", "a config with a sweep section runs with nlcx.sweep, not nlcx.run")
        return cfg.build(cfg.interpolate(raw, allow_env=allow_env), allow_env=allow_env)


def run(
    config: ConfigLike,
    overrides: OverridesLike = None,
    *,
    out: str | os.PathLike[str] | None = None,
    allow_env: bool = False,
) -> Result:
    """Simulate every controller of ``config`` on its plant and measure the runs.

    The same pipeline as ``nlcx run``: the controllers see the same plant, references and
    uncertainties, and the same config and seed give the same numbers bit for bit.

    Parameters
    ----------
    config : str, path, mapping or Experiment
        What :func:`experiment` takes.
    overrides : list of str or mapping, optional
        What :func:`experiment` takes.
    out : str or path, optional
        Also write the run directory there, exactly as ``nlcx run --out`` does (see
        :meth:`Result.save`). Without it nothing is written.
    allow_env : bool
        What :func:`experiment` takes; recorded in the run's manifest.

    Returns
    -------
    Result
        Metrics, comparison, trajectories and figure of the runs.

    Examples
    --------
    >>> import nlcx
    >>> result = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=10"])
    >>> result.controllers
    ['conventional', 'proposed']
    >>> table = result.compare(["overshoot", "rise_time"])
    >>> list(table.columns)
    ['unit', 'conventional', 'proposed', 'change_proposed_pct', 'better']
    """
    exp = experiment(config, overrides, allow_env=allow_env)  # checks numba's cache before anything compiled is loaded
    from nlcx import engine

    # numba's note on compiling the kernel's function values not shown; its cache read and
    # written one function at a time with every other process (nlcx.runtime.cache_access)
    with quiet_first_class_functions(), runtime.cache_access():
        result = Result.from_engine(engine.run_experiment(exp))
    if out is not None:
        result.save(out)
    return result


def sweep(
    config: ConfigLike,
    overrides: OverridesLike = None,
    *,
    jobs: int | None = None,
    executor: str = "process",
    out: str | os.PathLike[str] | None = None,
    allow_env: bool = False,
) -> SweepResult:
    """Run the ``sweep:`` section of ``config``: every variant, in batches, on ``jobs`` workers.

    Parameters
    ----------
    config : str, path or mapping
        A config with a ``sweep:`` section (see the sweep tutorial).
    overrides : list of str or mapping, optional
        As for :func:`run`; ``sweep.random.n=20`` changes the sweep itself.
    jobs : int, optional
        Worker processes; default: 2.
    executor : {"process", "serial", "dask"}
        Where the batches run; every executor gives the same bits.
    out : str or path, optional
        The sweep directory (resumable: a rerun skips finished variants). Without it the
        sweep runs in a temporary directory that is removed afterwards.
    allow_env : bool
        What :func:`experiment` takes; recorded in the sweep's manifest.

    Returns
    -------
    SweepResult
        The variants and their metrics, read back from the sweep's tables in whichever form
        it wrote them (:func:`nlcx.results.read_output_table`).

    Examples
    --------
    >>> import nlcx
    >>> swept = nlcx.sweep("configs/sweeps/robustness.yaml",
    ...                    ["sweep.random.n=2", "simulation.t_end=2"], executor="serial")
    >>> len(swept.variants), sorted(swept.metrics.controller.unique())
    (6, ['conventional', 'proposed'])
    """
    compiled_cache.ready()  # before the kernel is loaded; the workers fork from here
    from nlcx import sweeps

    if executor not in ("process", "serial", "dask"):
        raise ConfigError("executor", executor, "allowed: process, serial, dask")
    if jobs is not None:
        check_count("jobs", jobs, 1, MAX_JOBS, "worker processes")
    raw = _with_overrides(_raw(config), overrides)
    with tempfile.TemporaryDirectory(prefix="nlcx-sweep-") as scratch:
        target = Path(out) if out is not None else Path(scratch) / "sweep"
        with quiet_first_class_functions(), runtime.cache_access():
            sweeps.run(raw, [], target, executor, jobs or 2, with_report=out is not None, allow_env=allow_env)
        variants, metrics = read_output_table(target, "sweep"), read_output_table(target, "metrics")
        return SweepResult(variants, metrics, target if out is not None else None)

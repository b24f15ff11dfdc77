"""The Python API (nlcx.run, Result, nlcx.load_run, nlcx.sweep): the same numbers as the CLI."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import nlcx
from nlcx.cli import app
from nlcx.errors import ConfigError
from nlcx.manifest import IntegrityError
from nlcx.results import read_output_table

ROOT = Path(__file__).resolve().parent.parent
X_CONFIG = ROOT / "configs" / "x_error_ags.yaml"
SHORT = ["simulation.t_end=4"]


@pytest.fixture(scope="module")
def result() -> nlcx.Result:
    return nlcx.run(X_CONFIG, SHORT)


def test_import_nlcx_loads_no_numerical_library() -> None:
    """``import nlcx`` is light: numpy, pandas, numba and matplotlib load on first use."""
    heavy = "('numpy', 'pandas', 'numba', 'matplotlib', 'scipy')"
    code = f"import sys, nlcx; print(sorted(m for m in {heavy} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def test_every_public_name_resolves() -> None:
    for name in nlcx.__all__:
        assert getattr(nlcx, name) is not None
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        nlcx.nonexistent  # noqa: B018


def test_run_writes_nothing_without_out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    nlcx.run(X_CONFIG, SHORT)
    assert list(tmp_path.iterdir()) == []


def test_metrics_equal_the_cli_run_directory(result: nlcx.Result, tmp_path: Path) -> None:
    """The API's metrics are metrics.csv of `nlcx run` with the same config, cell for cell."""
    out = CliRunner().invoke(app, ["run", str(X_CONFIG), *SHORT, "--out", str(tmp_path / "cli"), "-q", "--no-report"])
    assert out.exit_code == 0, out.output
    cli = pd.read_csv(tmp_path / "cli" / "metrics.csv", keep_default_na=False, na_values={"value": [""]})
    pd.testing.assert_frame_equal(result.metrics, cli, check_dtype=False)


def test_load_run_gives_the_metrics_run_returned(result: nlcx.Result, tmp_path: Path) -> None:
    directory = result.save(tmp_path / "run")
    again = nlcx.load_run(directory)
    pd.testing.assert_frame_equal(again.metrics, result.metrics)
    assert again.controllers == result.controllers
    for controller in result.controllers:
        pd.testing.assert_frame_equal(again.trajectory(controller), result.trajectory(controller))
    assert again.config == result.config
    assert (directory / "report.html").is_file() and (directory / "figure.png").is_file()


def test_load_run_reads_parquet_and_directories_without_time_series(tmp_path: Path) -> None:
    parquet = nlcx.run(X_CONFIG, [*SHORT, "outputs.timeseries_format=parquet"], out=tmp_path / "p")
    pd.testing.assert_frame_equal(nlcx.load_run(tmp_path / "p").trajectory("proposed"), parquet.trajectory("proposed"))
    nlcx.run(X_CONFIG, [*SHORT, "outputs.timeseries=false"], out=tmp_path / "none")
    with pytest.raises(ConfigError, match=r"trajectory = 'proposed': this run was written without time series"):
        nlcx.load_run(tmp_path / "none").trajectory("proposed")


def test_load_run_refuses_what_is_not_a_run_directory(tmp_path: Path) -> None:
    with pytest.raises(IntegrityError, match=r"manifest.json: missing; allowed: an output directory nlcx wrote"):
        nlcx.load_run(tmp_path)
    with pytest.raises(ConfigError, match=r"directory = .*: a run directory"):
        nlcx.load_run(tmp_path / "nothing")


def test_compare_is_the_change_against_the_first_controller_on_the_metrics(result: nlcx.Result) -> None:
    table = result.compare()
    long = result.metrics.set_index(["controller", "signal", "metric"]).value
    for (signal, metric), row in table.iterrows():
        conventional, proposed = long[("conventional", signal, metric)], long[("proposed", signal, metric)]
        assert row.conventional == conventional or (math.isnan(row.conventional) and math.isnan(conventional))
        expected = 100 * (proposed - conventional) / abs(conventional) if conventional != 0 else math.nan
        assert row.change_proposed_pct == pytest.approx(expected, nan_ok=True, rel=1e-12)
    assert ("x", "overshoot") in table.index and ("theta", "peak_deviation") in table.index
    assert ("theta", "overshoot") not in table.index  # a regulated signal has no step metrics


def test_trajectory_names_every_signal(result: nlcx.Result) -> None:
    frame = result.trajectory("conventional")
    for name in ("t", "x", "x_dot", "theta", "theta_dot", "F_x", "x_ref", "theta_ref"):
        assert name in frame.columns
    assert frame.t.iloc[-1] == pytest.approx(4.0) and np.all(np.diff(frame.t) > 0)
    assert (frame["x.kp"] == -2.7).all()  # the loop logs its gain: the constant schedule's k_p
    with pytest.raises(ConfigError, match=r"controller = 'nope': not a controller of this run; allowed: conventional"):
        result.trajectory("nope")


def test_plot_has_one_axes_per_output_with_every_controller(result: nlcx.Result) -> None:
    fig = result.plot()
    assert len(fig.axes) == 2
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels == ["conventional", "proposed", "reference"]
    x = fig.axes[0].get_lines()[1].get_ydata()
    assert np.nanmax(x) == pytest.approx(result.trajectory("proposed").x.max())
    with pytest.raises(ConfigError, match=r"signals = 'F_x': not an output of the plant; allowed: x, theta"):
        result.plot(["F_x"])


def test_overrides_as_a_mapping_and_as_strings_agree() -> None:
    by_strings = nlcx.run(X_CONFIG, ["simulation.t_end=2", "controllers.proposed.loops.x.schedule.kp.min=-2.9"])
    by_mapping = nlcx.run(
        X_CONFIG,
        {
            "simulation": {"t_end": 2},
            "controllers": {"proposed": {"loops": {"x": {"schedule": {"kp": {"min": -2.9}}}}}},
        },
    )
    pd.testing.assert_frame_equal(by_strings.metrics, by_mapping.metrics)


def test_a_mapping_config_and_an_experiment_run_as_the_file() -> None:
    import yaml

    raw = yaml.safe_load(X_CONFIG.read_text())
    from_mapping = nlcx.run(raw, SHORT)
    from_experiment = nlcx.run(nlcx.experiment(X_CONFIG, SHORT))
    from_file = nlcx.run(X_CONFIG, SHORT)
    pd.testing.assert_frame_equal(from_mapping.metrics, from_file.metrics)
    pd.testing.assert_frame_equal(from_experiment.metrics, from_file.metrics)


def test_bad_input_is_one_line() -> None:
    with pytest.raises(ConfigError, match=r"simulation.t_edn = 5: unknown key") as info:
        nlcx.run(X_CONFIG, ["simulation.t_edn=5"])
    assert "\n" not in str(info.value)
    with pytest.raises(ConfigError, match=r"config = 'int': a YAML path, a mapping of sections or an Experiment"):
        nlcx.run(3)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"overrides = 'a=1': a list of key=value strings"):
        nlcx.run(X_CONFIG, "a=1")


@pytest.mark.slow
def test_sweep_returns_variants_and_metrics_as_the_cli_writes_them(tmp_path: Path) -> None:
    overrides = ["sweep.random.n=2", "simulation.t_end=2"]
    config = ROOT / "configs" / "sweeps" / "robustness.yaml"
    swept = nlcx.sweep(config, overrides, executor="serial", out=tmp_path / "api")
    out = CliRunner().invoke(app, ["sweep", str(config), *overrides, "--out", str(tmp_path / "cli"), "--no-report"])
    assert out.exit_code == 0, out.output
    for stem, frame in (("metrics", swept.metrics), ("sweep", swept.variants)):
        pd.testing.assert_frame_equal(frame, read_output_table(tmp_path / "cli", stem), check_exact=True)
        pd.testing.assert_frame_equal(frame, read_output_table(tmp_path / "api", stem), check_exact=True)
    assert len(swept.variants) == 6 and set(swept.metrics.variant) == set(range(6))
    summary = swept.summary()
    row = summary.set_index(["controller", "signal", "metric"]).loc[("proposed", "x", "overshoot")]
    values = swept.metrics.query(
        "controller == 'proposed' and signal == 'x' and metric == 'overshoot' and status == 'ok'"
    )
    assert row["median"] == pytest.approx(values.value.dropna().median())


def test_sweep_without_out_leaves_nothing_behind(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    swept = nlcx.sweep(ROOT / "configs" / "sweeps" / "robustness.yaml", ["sweep.random.n=1", "simulation.t_end=1"],
                       executor="serial")  # fmt: skip
    assert swept.directory is None and list(tmp_path.iterdir()) == []
    assert len(swept.variants) == 3


def test_the_type_stub_names_what_the_package_exports_lazily() -> None:
    """``nlcx/__init__.pyi`` (what type checkers and editors read) names exactly ``__all__``,
    each from the module the package loads it from."""
    import ast
    from pathlib import Path

    import nlcx

    stub = ast.parse((Path(nlcx.__file__).with_suffix(".pyi")).read_text())
    imported = {a.asname or a.name: node.module for node in stub.body if isinstance(node, ast.ImportFrom)
                for a in node.names}  # fmt: skip
    assert set(imported) == set(nlcx.__all__)
    for name, home in imported.items():
        assert getattr(nlcx, name) is getattr(__import__(home, fromlist=[name]), name)

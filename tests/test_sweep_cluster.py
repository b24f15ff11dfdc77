"""From a laptop to a cluster by one flag: a cluster file renders its batch job (checked
here as SLURM and PBS scripts), and a local cluster stands in for the queue with the same
results as the serial executor."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from nlcx.cli import app
from nlcx.results import read_output_table
from nlcx.sweeps import cluster

ROOT = Path(__file__).resolve().parent.parent
CLUSTERS = ROOT / "configs" / "clusters"
runner = CliRunner()


def test_the_slurm_file_renders_its_job_script() -> None:
    spec = cluster.load(CLUSTERS / "slurm.yaml")
    script = cluster.job_script(spec)
    lines = script.splitlines()
    for directive in ("#SBATCH -p compute", "#SBATCH -n 1", "#SBATCH --cpus-per-task=16", "#SBATCH -t 02:00:00"):
        assert directive in lines
    assert any(line.startswith("#SBATCH --mem=") for line in lines)
    assert "source ~/venvs/nlcx/bin/activate" in lines
    worker = next(line for line in lines if "dask_worker" in line)
    assert "--nthreads 1" in worker and "--nworkers 16" in worker  # single-threaded worker processes
    assert lines.index("source ~/venvs/nlcx/bin/activate") < lines.index(worker)


def test_the_pbs_file_renders_its_job_script(tmp_path: Path) -> None:
    raw = yaml.safe_load((CLUSTERS / "pbs.yaml").read_text())
    path = tmp_path / "pbs.yaml"
    path.write_text(yaml.safe_dump({**raw, "account": "ctrl42", "python": "/shared/nlcx/bin/python"}))
    script = cluster.job_script(cluster.load(path))
    assert "#PBS -q workq" in script and "#PBS -A ctrl42" in script
    assert "#PBS -l walltime=02:00:00" in script and "ncpus=16" in script
    assert "/shared/nlcx/bin/python -m distributed.cli.dask_worker" in script


def test_the_dry_run_prints_the_job_script() -> None:
    cfg = str(ROOT / "configs" / "sweeps" / "robustness.yaml")
    result = runner.invoke(app, ["sweep", cfg, "--cluster", str(CLUSTERS / "slurm.yaml"), "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "slurm cluster: 4 job(s) of 16 worker(s)" in result.output and "#SBATCH -p compute" in result.output


def test_a_bad_cluster_file_is_one_line_naming_the_key(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({"kind": "slurm", "walltime": "2h"}))
    cfg = str(ROOT / "configs" / "sweeps" / "robustness.yaml")
    result = runner.invoke(app, ["sweep", cfg, "--cluster", str(path), "--dry-run"])
    assert result.exit_code == 2
    (line,) = result.output.strip().splitlines()
    assert line.startswith("config error: cluster.walltime = '2h'")
    result = runner.invoke(app, ["sweep", cfg, "--cluster", str(path), "--scheduler", "tcp://x:1"])
    assert result.exit_code != 0 and "leave out --scheduler" in result.output


@pytest.mark.slow
def test_a_local_cluster_stands_in_for_the_queue_with_the_serial_results(tmp_path: Path) -> None:
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    params = {"plant.params.M": {"dist": "uniform", "relative": 0.2}}
    raw.update(name="on_cluster", outputs={"figure": False, "timeseries": False},
               sweep={"seed": 3, "random": {"n": 6, "params": params}, "batch_size": 2})  # fmt: skip
    raw["simulation"]["t_end"] = 1.0
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(raw))
    outs = {}
    for name, extra in (("serial", ["--executor", "serial"]), ("cluster", ["--cluster", str(CLUSTERS / "local.yaml")])):
        outs[name] = tmp_path / name
        result = runner.invoke(app, ["sweep", str(path), "--out", str(outs[name]), "--no-report", *extra])
        assert result.exit_code == 0, result.output
    for stem in ("metrics", "sweep"):
        serial, cluster = read_output_table(outs["serial"], stem), read_output_table(outs["cluster"], stem)
        pd.testing.assert_frame_equal(serial, cluster, check_exact=True)
    manifest = yaml.safe_load((outs["cluster"] / "manifest.json").read_text())
    assert manifest["executor"] == "dask" and manifest["jobs"] == 2

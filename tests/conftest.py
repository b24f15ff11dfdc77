"""Shared helpers: build and run experiments from in-memory configs."""

from __future__ import annotations

import copy
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from nlcx import _numba_compat, compiled_cache

compiled_cache.ready()  # before any module with compiled functions loads them from numba's cache
# the test process compiles and loads the package's functions as a command would: their cache
# files read and written one function at a time with every other process sharing the cache
_numba_compat.serialize_cache_access()

from nlcx import config, engine  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs"


def reproduce_only(only: str, out: Path) -> Any:
    """``nlcx reproduce --only ONLY --profile literal`` on the committed thesis configs, two
    jobs, into ``out`` (the CLI runner's result): the loop as printed, whatever profile the
    identification study made the default."""
    from typer.testing import CliRunner

    from nlcx.cli import app

    args = ["reproduce", "--only", only, "--profile", "literal", "--jobs", "2", "--out", str(out),
            "--configs", str(CONFIGS / "thesis")]  # fmt: skip
    return CliRunner().invoke(app, args)


def load_yaml(name: str) -> dict[str, Any]:
    return yaml.safe_load((CONFIGS / name).read_text())


def run_raw(raw: dict[str, Any]) -> engine.ExperimentResult:
    return engine.run_experiment(config.build(copy.deepcopy(raw)))


def open_loop_pendulum(
    force: dict[str, Any] | None,
    x0: dict[str, float],
    t_end: float,
    dt: float = 1e-3,
    bounds: dict[str, float] | None = None,
) -> engine.Run:
    """The x pendulum driven by F_x = reference (open loop)."""
    raw = {
        "name": "open_loop_test",
        "plant": {"name": "x_pendulum", "x0": x0},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {"F_x": force or {"kind": "constant", "value": 0.0}},
        "simulation": {"t_end": t_end, "dt": dt, "bounds": bounds or {"theta": 1e9}},
    }
    (run,) = run_raw(raw).runs
    return run


@pytest.fixture(scope="module", autouse=True)
def registries_restored() -> Iterator[None]:
    """Whatever a test module registers (a plant of a docstring example, a test's
    ``@nlcx.plant``) is taken out of the process's plugin registries after the module (a registry
    has no unregister: its entries are restored as they were), so that another file's tests,
    under pytest-xdist in any order, see only the plugins they registered themselves."""
    from nlcx import registry

    saved = {kind: (dict(reg._entries), dict(reg._loaded), reg._scanned) for kind, reg in registry.ALL.items()}
    yield
    for kind, (entries, loaded, scanned) in saved.items():
        reg = registry.ALL[kind]
        reg._entries, reg._loaded, reg._scanned = entries, loaded, scanned


@pytest.fixture
def x_time_raw() -> dict[str, Any]:
    return load_yaml("x_time_ags.yaml")


@pytest.fixture
def x_error_raw() -> dict[str, Any]:
    return load_yaml("x_error_ags.yaml")


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


@pytest.fixture(scope="session")
def reproduction(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One full ``nlcx reproduce --profile literal`` (every figure, table and claim, with its
    report), shared by the report tests."""
    from typer.testing import CliRunner

    from nlcx.cli import app

    out = tmp_path_factory.mktemp("reproduction")
    args = ["reproduce", "--profile", "literal", "--jobs", "2", "--out", str(out), "--configs", str(CONFIGS / "thesis")]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    return out

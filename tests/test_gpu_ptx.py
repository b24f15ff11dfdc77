"""The GPU kernels of the shipped loop structures compile for a real GPU (PTX, with NVVM).

numba's simulator (``tests/test_gpu.py``) runs the kernels as Python, so it cannot see what
CUDA's compiler refuses. Here each config goes through nlcx's GPU path with every kernel launch
replaced by a compilation to PTX for compute capability 9.0 (``tests/ptx_compile.py``): no GPU
is needed; CUDA's compilers NVVM and NVRTC (in the ``test`` extra) are.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.gpu  # compiles the GPU kernels to PTX with NVVM

ROOT = Path(__file__).resolve().parent.parent
SHORT = "++simulation.t_end=0.2"

RUNS = {
    # the conventional and error-AGS PID of the x pendulum (one kernel: a call per PID structure)
    "x-error-ags": ("configs/x_error_ags.yaml", []),
    "x-time-ags": ("configs/x_time_ags.yaml", []),
    "xyz": ("configs/xyz_error_ags.yaml", []),
    "cstr": ("configs/cstr_nonlinear.yaml", ["++reference.C_B.time=0.1"]),  # a step within the short run
    # the intelligent controllers of chapter 5: fuzzy, single-neuron and ANFIS schedules, preview
    "fuzzy": ("configs/thesis/ch5/fig_5_10.yaml", []),
    "single-neuron": ("configs/thesis/ch5/fig_5_12.yaml", []),
    "anfis": ("configs/thesis/ch5/fig_5_15.yaml", []),
    "preview": ("configs/thesis/ch5/fig_5_19.yaml", ["++reference.C_B.time=0.1"]),
    # simple friction on both axes of the x-y pendulum
    "friction": ("configs/thesis/ch3/fig_3_07.yaml", []),
    # loop elements at both hooks, a disturbance, Heun's tableau
    "elements-heun": ("configs/x_error_ags.yaml", [
        "++simulation.integrator=heun",
        "+uncertainty={noise: {kind: noise, power: 1.0e-7, sample_time: 0.01, injection: measurement}, "
        "disturbance: {kind: disturbance, amplitude: 20.0, frequency: 10.0}, "
        "lag: {kind: actuator_lag, tau: 0.02}, sat: {kind: actuator_saturation, limit: 3.0}}",
    ]),
}  # fmt: skip


def _compile(config: Path, *overrides: str) -> dict[str, int]:
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""}
    done = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "ptx_compile.py"), str(config), *overrides],
        capture_output=True, text=True, env=env, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.parametrize("case", list(RUNS))
def test_loop_kernels_compile_for_a_gpu(case: str) -> None:
    config, overrides = RUNS[case]
    compiled = _compile(ROOT / config, SHORT, *overrides)
    loops = [size for name, size in compiled.items() if name.startswith("loop")]
    assert loops and all(size > 10_000 for size in loops), compiled


def _sweep(tmp_path: Path, raw: dict) -> Path:
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


SWEEPS = {
    # step, regulation and input metrics, with friction in the loop and a bound that stops runs
    "friction-bounds": lambda base: {
        **base,
        "uncertainty": {"friction": {"kind": "friction", "model": "exponential", "mu_s": 0.2, "mu_c": 0.15,
                                     "viscous": 0.1, "stribeck_velocity": 0.105, "form_factor": 2.0}},
        "sweep": {"seed": 1, "random": {"n": 2, "params": {
            "uncertainty.friction.mu_s": {"dist": "uniform", "low": 0.18, "high": 0.4},
            "simulation.bounds.theta": {"dist": "uniform", "low": 0.004, "high": 0.02}}}},
    },
    # tracking metrics (a sine reference on x)
    "tracking": lambda base: {
        **base,
        "reference": {"x": {"kind": "sine", "amplitude": 0.3, "frequency": 0.025}},
        "sweep": {"seed": 1, "random": {"n": 2, "params": {"plant.params.l": {"dist": "uniform", "relative": 0.2}}}},
    },
    # step characteristics of outputs no loop follows, after a step on the plant's input
    "open-loop-step": lambda base: {
        "name": "open_loop_step",
        "plant": {"name": "x_pendulum", "params": {"M": 1.0, "m": 0.1, "l": 0.3, "g": 9.8}},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {"F_x": {"kind": "step", "initial": 0.0, "final": 1.0, "time": 0.01}},
        "simulation": {"t_end": 0.05, "dt": 1e-3, "bounds": {"theta": 1e9}},
        "sweep": {"seed": 1, "random": {"n": 2, "params": {"plant.params.M": {"dist": "uniform", "relative": 0.2}}}},
    },
}  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("case", list(SWEEPS))
def test_sweep_and_metric_kernels_compile_for_a_gpu(tmp_path: Path, case: str) -> None:
    """A columnar sweep's launches: the closed loop, then each loop's metric kernel."""
    base = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    base["outputs"] = {"figure": False, "timeseries": False, "gains_figure": False}
    compiled = _compile(_sweep(tmp_path, SWEEPS[case](base)), SHORT)
    assert any(name.startswith("loop") for name in compiled), compiled
    assert any(name.startswith("metrics") for name in compiled), compiled
    assert all(size > 10_000 for size in compiled.values()), compiled


#: A third-party loop element that allocates an array in its step: fine on the CPU, refused
#: by numba-cuda (a device function cannot allocate).
ALLOCATING = """
import numpy as np
from typing import Literal
from numba import njit
from nlcx.kernel.abi import ELEMENT_SIG
from nlcx.uncertainty.base import Element, UncertaintyConfig, UncertaintyModel


@njit(ELEMENT_SIG, cache=False)
def scratchpad(t, dt, k, signal, vid, ep, es, data, p_off, s_off, d_off):
    work = np.empty(signal.shape[1])
    for b in range(signal.shape[0]):
        for j in range(signal.shape[1]):
            work[j] = signal[b, j]
            signal[b, j] = work[j]


class ScratchConfig(UncertaintyConfig):
    kind: Literal["scratch"] = "scratch"


class Scratch(UncertaintyModel):
    Config = ScratchConfig

    def apply(self, cfg, hooks, path):
        hooks.add_element(Element("sensor", scratchpad, name="scratchpad"))
"""


def test_a_plugin_numba_cuda_refuses_fails_the_check(tmp_path: Path) -> None:
    """Where CUDA's compiler refuses a plugin, the check fails as a GPU launch would: with the
    one-line refusal naming the loop's plugins and numba's reason."""
    (tmp_path / "scratchparts.py").write_text(ALLOCATING)
    dist = tmp_path / "scratchparts-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: scratchparts\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[nlcx.uncertainties]\nscratch = scratchparts:Scratch\n")
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    raw["uncertainty"] = {"pad": {"kind": "scratch"}}
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": "", "PYTHONPATH": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "ptx_compile.py"), str(_sweep(tmp_path, raw)), SHORT],
        capture_output=True, text=True, env=env, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode != 0
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("config error: simulation.device = 'cuda': the plant, controller and elements"), line
    assert "'scratchpad'" in line and "do not compile for the GPU" in line and "use device: cpu" in line, line


#: a[0] * b[0] + c[0] compiled to PTX with numba-cuda's options, then with nlcx's.
CONTRACTION = """
from numba import cuda, types
from nlcx._numba_compat import cuda_without_fma


def kernel(a, b, c, out):
    out[0] = a[0] * b[0] + c[0]


signature = (types.float64[::1],) * 4
default, _ = cuda.compile_ptx(kernel, signature, cc=(9, 0))
cuda_without_fma()
strict, _ = cuda.compile_ptx(kernel, signature, cc=(9, 0))
print(default.count("fma.rn.f64"), strict.count("fma.rn.f64"), strict.count("mul.rn.f64"), strict.count("add.rn.f64"))
"""


def test_gpu_code_rounds_every_product_and_sum() -> None:
    """numba-cuda fuses a * b + c into one rounding (FMA); nlcx's GPU code is compiled without
    that contraction, so the product and the sum round apart, as on the CPU."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""}
    done = subprocess.run([sys.executable, "-c", CONTRACTION], capture_output=True, text=True, env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    fused_by_default, fused, products, sums = map(int, done.stdout.split())
    assert fused_by_default == 1 and fused == 0 and products == 1 and sums == 1

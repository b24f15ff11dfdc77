"""The GPU path (``simulation.device: cuda``) on numba-cuda's simulator, against the CPU path.

Each test runs nlcx in a child process with ``NUMBA_ENABLE_CUDASIM=1``, where numba-cuda runs
the GPU kernels as Python on the CPU: the same kernel code, the same retargeted plugin source,
the CPU's metric kernels. Runs are short (the simulator steps a thread in Python). What must
hold: the same statuses, and every metric equal to the CPU's, bit for bit (the simulator's
math functions are the CPU's; on a GPU, libdevice's sin, cos and exp may differ from the CPU's
in the last bit, docs/guide/gpu.md).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from nlcx.results import read_output_table

pytestmark = pytest.mark.gpu  # numba-cuda's simulator, in child processes

ROOT = Path(__file__).resolve().parent.parent
RTOL = 0.0  # bit for bit: assert_allclose with rtol = atol = 0 is equality


def _nlcx(
    *args: str, simulator: bool = True, cwd: Path | None = None, prelude: str = ""
) -> subprocess.CompletedProcess[str]:
    """The CLI in a child process (``prelude``: Python run in it first, e.g. to shrink a size)."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1" if simulator else "0", "CUDA_VISIBLE_DEVICES": ""}
    command = ["-c", f"{prelude}\nfrom nlcx.cli import main; main()"] if prelude else ["-m", "nlcx.cli"]
    return subprocess.run([sys.executable, *command, *args], capture_output=True, text=True, env=env, cwd=cwd)


def _close(cpu: pd.DataFrame, gpu: pd.DataFrame) -> None:
    """The same rows (every column but ``value`` equal) and values within RTOL (NaN where NaN)."""
    assert len(cpu) == len(gpu) > 0
    text = [c for c in cpu.columns if c != "value"]
    pd.testing.assert_frame_equal(cpu[text].fillna(""), gpu[text].fillna(""))
    a, b = cpu["value"].to_numpy(float), gpu["value"].to_numpy(float)
    assert np.array_equal(np.isnan(a), np.isnan(b))
    finite = ~np.isnan(a)
    np.testing.assert_allclose(b[finite], a[finite], rtol=RTOL, atol=0.0)


def _bounded_sweep(seed: int, n: int) -> dict[str, object]:
    """A CSV sweep of n variants over the pendulum's length and a bound on theta that stops some."""
    params = {"plant.params.l": {"dist": "uniform", "relative": 0.3},
              "simulation.bounds.theta": {"dist": "uniform", "low": 0.004, "high": 0.02}}  # fmt: skip
    return {"seed": seed, "random": {"n": n, "params": params}, "format": "csv"}


def _config(tmp_path: Path, t_end: float, **extra: object) -> Path:
    raw = yaml.safe_load((ROOT / "configs" / "x_error_ags.yaml").read_text())
    raw["simulation"]["t_end"] = t_end
    raw["outputs"] = {"figure": False, "timeseries": False, "gains_figure": False}
    raw.update(extra)
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def test_run_on_gpu_matches_cpu(tmp_path: Path) -> None:
    """`nlcx run --device cuda`: both controllers, every metric of the run, as on the CPU."""
    config = _config(tmp_path, 0.06)
    for device in ("cpu", "cuda"):
        done = _nlcx("run", str(config), "--device", device, "--out", str(tmp_path / device), "--no-report")
        assert done.returncode == 0, done.stderr
    _close(pd.read_csv(tmp_path / "cpu" / "metrics.csv"), pd.read_csv(tmp_path / "cuda" / "metrics.csv"))
    resolved = yaml.safe_load((tmp_path / "cuda" / "config.yaml").read_text())
    assert resolved["simulation"]["device"] == "cuda"


def test_sweep_on_gpu_matches_cpu(tmp_path: Path) -> None:
    """A columnar sweep measured on the device: step (x), regulation (theta) and input (F)
    metrics, with a bound on theta that stops some variants, as on the CPU."""
    config = _config(tmp_path, 0.05, sweep=_bounded_sweep(seed=3, n=4))
    for device in ("cpu", "cuda"):
        done = _nlcx("sweep", str(config), "--device", device, "--out", str(tmp_path / device), "--no-report")
        assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "cuda" / "manifest.json").read_text())["path"] == "columnar"  # measured there
    cpu_index, gpu_index = (read_output_table(tmp_path / d, "sweep") for d in ("cpu", "cuda"))
    assert list(cpu_index.status) == list(gpu_index.status)
    assert {"ok", "unstable"} <= set(cpu_index.status)  # both kinds of run are compared
    _close(read_output_table(tmp_path / "cpu", "metrics"), read_output_table(tmp_path / "cuda", "metrics"))


def test_no_gpu_is_one_line(tmp_path: Path) -> None:
    """Without a GPU (and without the simulator), --device cuda is refused in one line, before any work."""
    config = _config(tmp_path, 0.05)
    done = _nlcx("run", str(config), "--device", "cuda", "--out", str(tmp_path / "out"), simulator=False)
    assert done.returncode != 0
    lines = [line for line in (done.stdout + done.stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("config error: simulation.device = 'cuda':"), lines
    assert not (tmp_path / "out").exists()


def test_nvvm_is_checked_in_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """CUDA's compiler of the kernels (NVVM, in the test extra) loads here; where it does not,
    --device cuda says so in one line saying what to install."""
    from numba.cuda.cudadrv import nvvm

    from nlcx.errors import ConfigError
    from nlcx.kernel import device

    device._check_nvvm()  # installed with the test extra: no error

    def missing() -> None:
        raise nvvm.NvvmSupportError("libNVVM cannot be found.\nlibnvvm.so: cannot open shared object file")

    monkeypatch.setattr(nvvm, "NVVM", missing)
    with pytest.raises(ConfigError) as err:
        device._check_nvvm()
    text = str(err.value)
    assert "\n" not in text and text.startswith("config error: simulation.device = 'cuda': CUDA's NVVM"), text
    assert "libNVVM cannot be found." in text and "nlcx[cuda]" in text and "nlcx[cuda12]" in text


def test_unknown_device_is_one_line(tmp_path: Path) -> None:
    done = _nlcx("run", str(_config(tmp_path, 0.05)), "--device", "tpu")
    assert done.returncode != 0
    assert "--device = 'tpu': allowed values: cpu, cuda" in done.stdout + done.stderr


#: Each loop of a config on the CPU and on the GPU, through the Python API: the largest relative
#: difference of the states, inputs and friction forces, the statuses, and how often an axis
#: sticks (its velocity exactly zero after t_0) and breaks away again.
FRICTION_RUNS = """
import json, sys
import numpy as np
from nlcx import config, engine
from nlcx.engine.simulate import simulate_items
from nlcx.kernel.friction import FA
exp = config.load(sys.argv[1], sys.argv[2:])
p = engine.prepare(exp)
items = engine.items_of(p)
runs = {d: simulate_items(items, p.grid, exp.section.simulation.integrator, device=d) for d in ("cpu", "cuda")}
def rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), 1e-300))
out = []
for cpu, gpu in zip(runs["cpu"], runs["cuda"]):
    axes = items[0].friction
    v = cpu.x[1:, [int(i) for i in axes[:, FA.velocity_index]]]
    stuck = v == 0.0
    out.append({"status": [cpu.status, gpu.status], "samples": [len(cpu.t), len(gpu.t)],
                "rel": [rel(cpu.x, gpu.x), rel(cpu.u, gpu.u), rel(cpu.friction, gpu.friction)],
                "stuck": int(stuck.sum()), "breakaway": int((stuck[:-1] & ~stuck[1:]).sum())})
print(json.dumps(out))
"""


@pytest.mark.parametrize(
    ("config", "overrides"),
    [
        # simple friction on both axes of the x-y pendulum (Figure 3.7): the AGS loop sticks and breaks away
        ("configs/thesis/ch3/fig_3_07.yaml", ["simulation.t_end=0.5"]),
        # the exponential (Stribeck) model with a disturbance (interpolated inside a split step)
        # and measurement noise, under Heun's tableau
        ("configs/x_error_ags.yaml", [
            "simulation.t_end=0.4", "simulation.integrator=heun",
            "+uncertainty={friction: {kind: friction, model: exponential, mu_s: 0.2, mu_c: 0.15, viscous: 0.1, "
            "stribeck_velocity: 0.105, form_factor: 2.0}, disturbance: {kind: disturbance, amplitude: 20.0, "
            "frequency: 10.0}, noise: {kind: noise, power: 1.0e-7, sample_time: 0.01, injection: measurement}}",
        ]),
    ],
)  # fmt: skip
def test_friction_on_gpu_matches_cpu(config: str, overrides: list[str]) -> None:
    """Stick-slip friction (Appendix A) on the GPU: the CPU's friction path compiled for each
    thread. States, inputs and the friction forces at each sample as on the CPU, through
    sticking (the step split where an axis stops) and breakaway."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1", "CUDA_VISIBLE_DEVICES": ""}
    done = subprocess.run(
        [sys.executable, "-c", FRICTION_RUNS, str(ROOT / config), *overrides],
        capture_output=True, text=True, env=env, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    loops = json.loads(done.stdout)
    assert len(loops) == 2
    for loop in loops:
        assert loop["status"][0] == loop["status"][1] and loop["samples"][0] == loop["samples"][1]
        assert max(loop["rel"]) <= RTOL, loop
    assert sum(loop["stuck"] for loop in loops) > 0 and sum(loop["breakaway"] for loop in loops) > 0, loops


def test_friction_sweep_on_gpu_matches_cpu(tmp_path: Path) -> None:
    """A columnar sweep of the friction coefficients, measured on the device as on the CPU."""
    friction = {"friction": {"kind": "friction", "model": "exponential", "mu_s": 0.2, "mu_c": 0.15, "viscous": 0.1,
                             "stribeck_velocity": 0.105, "form_factor": 2.0}}  # fmt: skip
    params = {"uncertainty.friction.mu_s": {"dist": "uniform", "low": 0.18, "high": 0.4},
              "uncertainty.friction.viscous": {"dist": "uniform", "low": 0.0, "high": 2.0}}  # fmt: skip
    config = _config(tmp_path, 0.3, uncertainty=friction, sweep={"seed": 2, "format": "csv",
                                                                  "random": {"n": 3, "params": params}})  # fmt: skip
    for device in ("cpu", "cuda"):
        done = _nlcx("sweep", str(config), "--device", device, "--out", str(tmp_path / device), "--no-report")
        assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "cuda" / "manifest.json").read_text())["path"] == "columnar"  # measured there
    _close(read_output_table(tmp_path / "cpu", "metrics"), read_output_table(tmp_path / "cuda", "metrics"))


CASES = {
    # loop elements at both hooks (noise on the measurement, lag and saturation on the input),
    # a disturbance at the stage times, and Heun's tableau instead of the written-out RK4
    "elements-heun": ("configs/x_error_ags.yaml", [
        "++simulation.integrator=heun",
        "+uncertainty={noise: {kind: noise, power: 1.0e-7, sample_time: 0.01, injection: measurement}, "
        "disturbance: {kind: disturbance, amplitude: 20.0, frequency: 10.0}, "
        "lag: {kind: actuator_lag, tau: 0.02}, sat: {kind: actuator_saturation, limit: 3.0}}",
    ]),
    # the transfer-function plant under a fuzzy schedule (a registered schedule, through the
    # GPU's branch over the callback slots in use)
    "fuzzy-tf": ("configs/thesis/ch5/fig_5_10.yaml", []),
    # four states per axis and three loops (time-AGS PID of the x-y-z pendulum)
    "xyz": ("configs/xyz_error_ags.yaml", []),
    # chapter 5's H2 and H-infinity preview controllers (sampled at 0.1 s, previewing a step)
    "preview": ("configs/thesis/ch5/fig_5_19.yaml", ["reference.C_B.time=0.3", "++simulation.t_end=1.0"]),
    # the GA tuner of Figure 5.17: each generation's candidates simulated on the GPU, the tuned
    # PID then run there (a small population: what is compared is the path, not the optimum)
    "ga-tuner": ("configs/thesis/ch5/fig_5_17.yaml", [
        "controllers.ga.tune=[{kind: ga, objective: ise, bounds: {kp: [0.0, 5.0], ki: [0.0, 5.0], kd: [0.0, 2.0]}, "
        "optimiser: {pop_size: 4, generations: 2, seed: 1}}]", "++simulation.t_end=0.5",
    ]),
}  # fmt: skip


@pytest.mark.parametrize("case", list(CASES))
def test_plugins_on_gpu_match_cpu(tmp_path: Path, case: str) -> None:
    """Plants, schedules, loop elements and integrators, retargeted from their source, as on the CPU."""
    config, overrides = CASES[case]
    for device in ("cpu", "cuda"):
        out = tmp_path / device
        args = ["run", str(ROOT / config), "++simulation.t_end=0.1", *overrides, "--device", device, "--no-report"]
        done = _nlcx(*args, "--out", str(out))
        assert done.returncode == 0, done.stderr
    _close(pd.read_csv(tmp_path / "cpu" / "metrics.csv"), pd.read_csv(tmp_path / "cuda" / "metrics.csv"))


def test_identify_puts_its_loops_on_the_device() -> None:
    """`nlcx identify --device cuda`: every table's experiment runs on the GPU; a CPU study's
    resume digest is the one of the spec without the setting (its earlier fits stay valid)."""
    import hashlib

    from nlcx.thesis import fitting, identify, split

    root = ROOT / "configs" / "thesis"
    assert all(
        raw["simulation"]["device"] == "cuda" for raw in fitting.TableRuns(root, ["2.3"], device="cuda").raw.values()
    )
    assert "device" not in fitting.TableRuns(root, ["2.3"]).raw["2.3"].get("simulation", {})
    spec = identify.load_spec(ROOT / "configs" / "identify" / "pendulum_all.yaml")
    spec_split = split.load(ROOT / "configs" / "identify" / "split.yaml")
    before = json.dumps(
        [spec.model_dump(exclude={"only", "claims_top", "device"}), spec_split.model_dump()], sort_keys=True
    )
    assert identify.spec_digest(spec, spec_split) == hashlib.sha256(before.encode()).hexdigest()[:16]
    on_gpu = spec.model_copy(update={"device": "cuda"})
    assert identify.spec_digest(on_gpu, spec_split) != identify.spec_digest(spec, spec_split)


#: Metric rows (:class:`nlcx.engine.metric_rows.MetricColumns`) as JSON, in a child script.
ROWS_AS_JSON = """
def rows(m):
    text = {k: [m.categories[k][c] if c >= 0 else "" for c in m.codes[k]] for k in m.codes}
    return {"variant": m.variant.tolist(), "value": m.value.tolist(), **text}
"""

#: A population packed into a prepared experiment (the identification's objective,
#: nlcx.thesis.packed_cells) measured on the CPU and on the GPU: their metric rows as JSON.
PACKED_POPULATION = (
    ROWS_AS_JSON
    + """
import json
import numpy as np
from nlcx import config
from nlcx.engine import gpu
from nlcx.thesis.packed_cells import measured, packed_table

launched = []
on_device = gpu.simulate_measure
gpu.simulate_measure = lambda *args: launched.append(args[-1]) or on_device(*args)
box = {"controllers.conventional.loops.theta.schedule.kp": (12.0, 40.0), "simulation.bounds.theta": (0.004, 0.03)}
X = np.random.default_rng(4).uniform([b[0] for b in box.values()], [b[1] for b in box.values()], size=(5, 2))
out = {}
for device in ("cpu", "cuda"):
    def experiment(values):
        settings = [f"{k}={v!r}" for k, v in values.items()]
        short = ["simulation.t_end=0.06", f"simulation.device={device}"]
        return config.load("configs/x_error_ags.yaml", [*settings, *short])
    packed = packed_table(experiment, box)
    out[device] = rows(measured(packed, {k: X[:, j] for j, k in enumerate(box)}, len(X)))
print(json.dumps({**out, "launched": launched}))
"""
)


def test_a_packed_population_is_measured_on_the_gpu_as_on_the_cpu() -> None:
    """The identification's packed populations take the columnar path onto the device: the
    same metric rows (runs that stop at a bound among them), values within 1e-9 relative."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1", "CUDA_VISIBLE_DEVICES": ""}
    done = subprocess.run([sys.executable, "-c", PACKED_POPULATION], capture_output=True, text=True, env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout)
    assert out["launched"] == [5]  # the GPU's population: the five candidates, once
    cpu, gpu = (pd.DataFrame(out[d]) for d in ("cpu", "cuda"))
    assert {"ok", "unstable"} <= set(cpu.status)
    _close(cpu, gpu)


def _key_in_a_process(code: str) -> str:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    return done.stdout.strip()


def test_kept_kernels_are_keyed_by_their_source() -> None:
    """A kept GPU kernel's key is the same in every process and changes with any code or
    constant the kernel reaches (here: the PID step of a structure, through its schedules)."""
    code = (
        "import yaml\nfrom nlcx import config, engine\nfrom nlcx.kernel import cuda_loop\n"
        "from nlcx.kernel.device import source_key\n"
        "raw = yaml.safe_load(open('configs/x_error_ags.yaml'))\n"
        "p = engine.prepare(config.build(config.Interpolated.of(raw).resolved))\n"
        "print(*(source_key(cuda_loop.loop_kernel, i.controller.step, i.plant.rhs) for i in engine.items_of(p)))\n"
    )
    first, second = _key_in_a_process(code).split(), _key_in_a_process(code).split()
    assert first == second  # the same in another process
    assert first[0] != first[1]  # the conventional and the AGS PID differ


def test_source_key_follows_constants_and_callees() -> None:
    from numba import njit

    from nlcx.kernel.device import source_key

    def make(scale: float):
        @njit
        def inner(x):  # pragma: no cover - compiled
            return scale * x

        @njit
        def outer(x):  # pragma: no cover - compiled
            return inner(x) + 1.0

        return outer

    assert source_key(make(2.0)) == source_key(make(2.0))
    assert source_key(make(2.0)) != source_key(make(3.0))  # a constant of a function it calls


def test_kept_kernel_files_round_trip(tmp_path: Path) -> None:
    """What numba-cuda's cache keeps of a kernel (its reduced state) is written atomically and
    read back as a kernel; a missing or damaged file means a compilation (None)."""
    from numba.cuda.dispatcher import _Kernel

    from nlcx._numba_compat import _KernelFiles

    class Reduced:
        def _reduce_states(self) -> dict[str, object]:
            return dict(cooperative=False, name="loop", signature=None, codelibrary=None, debug=False,
                        lineinfo=False, call_helper=None, extensions=[], shared_memory_carveout=None,
                        launch_config_sensitive=False)  # fmt: skip

    class Context:
        def refresh(self) -> None:
            return None

    files = _KernelFiles(tmp_path / "kernels", "key")
    assert files.load_overload("(float64,)", Context()) is None
    files.save_overload("(float64,)", Reduced())
    loaded = files.load_overload("(float64,)", Context())
    assert isinstance(loaded, _Kernel) and loaded.entry_name == "loop"
    assert files.load_overload("(int64,)", Context()) is None  # another signature, another file
    (kept,) = (tmp_path / "kernels").iterdir()
    kept.write_bytes(b"damaged")
    assert files.load_overload("(float64,)", Context()) is None


def test_kept_kernels_go_with_numbas_cache(tmp_path: Path) -> None:
    from nlcx import compiled_cache

    kept = tmp_path / "__pycache__" / "cuda-kernels" / "abc.kernel"
    kept.parent.mkdir(parents=True)
    kept.write_bytes(b"x")
    assert kept in compiled_cache.cache_files(tmp_path)


def test_open_loop_step_sweep_on_gpu_matches_cpu(tmp_path: Path) -> None:
    """A step on the plant's input (open loop): the outputs no loop follows get their step
    characteristics against their own last sample (nlcx.metrics.step_info), measured on the
    device as on the CPU."""
    raw = {
        "name": "open_loop_step",
        "plant": {"name": "x_pendulum", "params": {"M": 1.0, "m": 0.1, "l": 0.3, "g": 9.8}},
        "controllers": {"open": {"kind": "open_loop"}},
        "reference": {"F_x": {"kind": "step", "initial": 0.0, "final": 1.0, "time": 0.01}},
        "simulation": {"t_end": 0.05, "dt": 1e-3, "bounds": {"theta": 1e9}},
        "outputs": {"figure": False, "timeseries": False, "gains_figure": False},
        "sweep": {"seed": 1, "format": "csv", "random": {"n": 3, "params": {"plant.params.M": {"dist": "uniform",
                                                                                           "relative": 0.2}}}},
    }  # fmt: skip
    config = tmp_path / "open.yaml"
    config.write_text(yaml.safe_dump(raw))
    for device in ("cpu", "cuda"):
        done = _nlcx("sweep", str(config), "--device", device, "--out", str(tmp_path / device), "--no-report")
        assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "cuda" / "manifest.json").read_text())["path"] == "columnar"  # measured there
    cpu = read_output_table(tmp_path / "cpu", "metrics")
    assert {"steady_state_value", "settling_min", "peak"} <= set(cpu.metric)  # step_info's rows are compared
    _close(cpu, read_output_table(tmp_path / "cuda", "metrics"))


def test_identify_refuses_the_gpu_where_it_does_not_use_it(tmp_path: Path) -> None:
    """--device cuda on a study that runs on the CPU only is one line, not silently ignored."""
    for spec in ("cstr.yaml", "targeted.yaml"):
        done = _nlcx("identify", str(ROOT / "configs" / "identify" / spec), "--device", "cuda", "--out",
                     str(tmp_path / "o"))  # fmt: skip
        assert done.returncode != 0
        text = (done.stdout + done.stderr).strip()
        assert text == "--device = 'cuda': a consistency, targeted or chapter 5 study runs on the cpu only", text
        assert not (tmp_path / "o").exists()


def test_overlapped_batches_in_chunks_match_cpu(tmp_path: Path) -> None:
    """A sweep in three batches of two variants, each cut into chunks of three rows, two batches
    in flight at once (one on the device while the one before it is written): statuses and
    metrics as on the CPU."""
    config = _config(tmp_path, 0.05, sweep=_bounded_sweep(seed=5, n=6))
    small = (
        "import nlcx.sweeps.columnar as c, nlcx.engine.gpu as g; c.GPU_BATCH_VARIANTS = 2; "
        "g.chunk_rows = lambda n_rows, bytes_per_row: min(n_rows, 3)"
    )
    done = _nlcx("sweep", str(config), "--device", "cuda", "--out", str(tmp_path / "cuda"), "--no-report",
                 prelude=small)  # fmt: skip
    assert done.returncode == 0, done.stderr
    done = _nlcx("sweep", str(config), "--device", "cpu", "--out", str(tmp_path / "cpu"), "--no-report")
    assert done.returncode == 0, done.stderr
    assert len(list((tmp_path / "cuda" / "parts").glob("*.index.*"))) == 3
    cpu_index, gpu_index = (read_output_table(tmp_path / d, "sweep") for d in ("cpu", "cuda"))
    assert list(cpu_index.status) == list(gpu_index.status)
    assert {"ok", "unstable"} <= set(cpu_index.status)
    _close(read_output_table(tmp_path / "cpu", "metrics"), read_output_table(tmp_path / "cuda", "metrics"))


def test_one_ensemble_at_a_time_on_the_gpu(monkeypatch: pytest.MonkeyPatch) -> None:
    """simulate_measure called from four threads at once: one call at a time on the GPU."""
    import threading
    import time

    from nlcx.engine import gpu

    inside, most, calls = [0], [0], []
    count = threading.Lock()

    def fake(ensembles: list[gpu.Ensemble]) -> list[tuple[list[object], None]]:
        with count:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        time.sleep(0.02)
        calls.extend(e.n_variants for e in ensembles)
        with count:
            inside[0] -= 1
        return [([], None)]

    monkeypatch.setattr(gpu, "_simulate_measure_all", fake)
    threads = [threading.Thread(target=gpu.simulate_measure, args=(None, {}, {}, n)) for n in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(calls) == [0, 1, 2, 3] and most[0] == 1


#: A generation of three hypotheses' populations on three train tables (short horizons): their
#: packed tables' metric rows on the CPU, on the GPU one hypothesis at a time, and on the GPU all
#: together (nlcx.thesis.lockstep), with the closed-loop launches each way took.
LOCKSTEP_GENERATION = (
    ROWS_AS_JSON
    + """
import json
from pathlib import Path
import numpy as np
from nlcx.engine.gpu import ensembles_metrics
from nlcx.kernel import cuda_loop
from nlcx.thesis import fitting, hypotheses, identify, lockstep, split

launches = []
on_device = cuda_loop.launch
cuda_loop.launch = lambda *args: launches.append(args[1].x0.shape[0]) or on_device(*args)
root = Path("configs/thesis")
spec = identify.load_spec(Path("configs/identify/pendulum_all.yaml"))
cells = identify.all_cells(split.load(Path("configs/identify/split.yaml")))
names = ["literal", "saturation=clamping", "z_loop=printed"]
hyps = [h for h in hypotheses.family(spec.families, 1) if h.name in names]
train = list(dict.fromkeys(cells[cells.part == "train"].table))

def searches(device):
    runs = fitting.TableRuns(root, train, device=device)
    for raw in runs.raw.values():
        raw["simulation"] = {**raw.get("simulation", {}), "t_end": 0.03}
    return [fitting.search(root, h, spec.free, cells, device, None, runs) for h in hyps]

out = {}
for way, device in (("cpu", "cpu"), ("alone", "cuda"), ("together", "cuda")):
    found = searches(device)
    pops = [np.random.default_rng(k).uniform(s.lower, s.upper, size=(2, len(s.lower))) for k, s in enumerate(found)]
    ensembles = [e for s, X in zip(found, pops) for e in s.objective.ensembles(X).values()]
    launches.clear()
    if way == "together":
        measured = ensembles_metrics(ensembles)
        used = list(launches)
        losses = lockstep.generation_losses([s.objective for s in found], pops)
    else:
        measured = [m for e in ensembles for m in ensembles_metrics([e])]
        used = list(launches)
        losses = [s.objective(X) for s, X in zip(found, pops)]
    out[way] = {"rows": [rows(m) for m in measured], "losses": [f.tolist() for f in losses],
                "launches": used, "ensembles": len(ensembles)}
print(json.dumps(out))
"""
)


def test_a_generation_of_many_hypotheses_runs_in_shared_launches() -> None:
    """The identification's lockstep on the GPU: the populations of several hypotheses go to the
    GPU in one call, whose loops of the same kernel share a launch. Their metric rows are those
    of each ensemble alone on the GPU, bit for bit, and within 1e-9 of the CPU's."""
    done = subprocess.run(
        [sys.executable, "-c", LOCKSTEP_GENERATION], capture_output=True, text=True, cwd=ROOT,
        env={**os.environ, "NUMBA_ENABLE_CUDASIM": "1", "CUDA_VISIBLE_DEVICES": ""},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout)
    alone, together = out["alone"], out["together"]
    assert alone["ensembles"] == together["ensembles"] == 9  # three hypotheses, three packed tables each
    # the same loops (rows of the launches), in fewer launches
    assert len(together["launches"]) < len(alone["launches"])
    assert sum(together["launches"]) == sum(alone["launches"])
    assert together["rows"] == alone["rows"] and together["losses"] == alone["losses"]
    for cpu, gpu in zip(out["cpu"]["rows"], together["rows"], strict=True):
        _close(pd.DataFrame(cpu), pd.DataFrame(gpu))
    np.testing.assert_allclose(np.array(together["losses"]), np.array(out["cpu"]["losses"]), rtol=RTOL, atol=0.0)

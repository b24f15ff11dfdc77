"""Compile a config's GPU kernels to PTX for a real GPU, on a machine without one.

Run as ``python tests/ptx_compile.py CONFIG [OVERRIDES...]`` (by ``tests/test_gpu_ptx.py``):
the config's loops go through nlcx's GPU path exactly as they would on a GPU, the kernel calls
of ``nlcx run`` (:func:`nlcx.engine.simulate_items`) and, where the config has a ``sweep``
section, of a columnar sweep with its metric kernels (:func:`nlcx.engine.gpu.simulate_measure`),
except that each kernel launch compiles the kernel with NVVM for compute capability
:data:`CC` instead of running it. numba's simulator, which the other GPU tests use, runs the
kernels as Python and so cannot see what NVVM refuses (a device function returning a view of
an array, say); this does. Prints one JSON object: the kernels compiled, by name, with their
PTX sizes.

What it replaces, in this process only: ``numba.cuda.dispatcher.get_current_device`` (a device
function is compiled for the current GPU's compute capability), ``to_device`` and
``device_array`` (host arrays stand for device arrays), and nlcx's check for a GPU. The kernels
are compiled with nlcx's NVVM options, as on a GPU (no fused multiply-add contraction).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

#: The compute capability compiled for: an H100's.
CC = (9, 0)


class _Device:
    compute_capability = CC


class _HostArray(np.ndarray):
    """A host array standing for a device array."""

    def copy_to_host(self) -> np.ndarray:
        return np.asarray(self)


def _typed(value: Any) -> Any:
    from numba import typeof

    return typeof(np.ascontiguousarray(value) if isinstance(value, np.ndarray) else value)


class _Compiling:
    """A kernel whose launch compiles it to PTX (``kernel[blocks, threads](*args)``)."""

    def __init__(self, kernel: Any, name: str, compiled: dict[str, int]) -> None:
        self.kernel, self.name, self.compiled = kernel, name, compiled

    def __getitem__(self, _launch: Any) -> _Compiling:
        return self

    def __call__(self, *args: Any) -> None:
        from numba import cuda

        ptx, _ = cuda.compile_ptx(self.kernel.py_func, tuple(_typed(a) for a in args), cc=CC)
        self.compiled[f"{self.name} {len(self.compiled)}"] = len(ptx)


def _without_a_gpu(compiled: dict[str, int]) -> None:
    """Replace, in this process, what needs a GPU (the module docstring)."""
    from numba import cuda
    from numba.cuda import dispatcher

    from nlcx.engine import gpu
    from nlcx.kernel import cuda_friction, cuda_loop, cuda_metrics, cuda_shape, device

    loop, metrics = cuda_loop.loop_kernel, cuda_metrics.metrics_kernel
    replaced: list[tuple[Any, str, Any]] = [
        (dispatcher, "get_current_device", lambda: _Device()),
        (cuda, "to_device", lambda a: np.ascontiguousarray(a).view(_HostArray)),
        (cuda, "device_array", lambda shape, dtype=np.float64: np.zeros(shape, dtype).view(_HostArray)),
        *((module, "cuda", lambda: cuda) for module in (device, cuda_loop, cuda_shape, cuda_friction, cuda_metrics)),
        *((module, "kept", lambda kernel, *parts: kernel) for module in (cuda_loop, cuda_metrics)),
        (gpu, "chunk_rows", lambda n_rows, bytes_per_row: n_rows),
        (cuda_loop, "loop_kernel", lambda shape: _Compiling(loop(shape), "loop", compiled)),
        (cuda_metrics, "metrics_kernel", lambda blocks, t: _Compiling(metrics(blocks, t), "metrics", compiled)),
    ]
    for owner, name, value in replaced:
        setattr(owner, name, value)
    from nlcx._numba_compat import cuda_without_fma

    cuda_without_fma()  # as nlcx compiles for a GPU


def _run_calls(path: str, overrides: list[str]) -> None:
    """The kernel calls of ``nlcx run``: every loop of the config."""
    from nlcx import config, engine
    from nlcx.engine.simulate import simulate_items

    experiment = config.load(path, overrides)
    prepared = engine.prepare(experiment)
    simulate_items(engine.items_of(prepared), prepared.grid, experiment.section.simulation.integrator, device="cuda")


def _sweep_calls(path: str, overrides: list[str]) -> None:
    """The kernel calls of a columnar sweep of the config's ``sweep`` section, with its metric kernels."""
    from nlcx import config
    from nlcx.engine.gpu import simulate_measure
    from nlcx.sweeps import columnar, planning

    base_raw, spec, _ = planning.load(path, overrides)
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    found = columnar.packing(base_raw, spec, plan)
    if plan is None or isinstance(found, str):
        raise SystemExit(f"not a columnar sweep: {found}")
    (batch,) = columnar.column_batches(base_raw, plan, found, "ptx", Path("unused"), plan.n, None)
    simulate_measure(columnar._template(batch), found.slots, batch.columns, batch.n)


def main(path: str, overrides: list[str]) -> None:
    from nlcx.config import read_config

    compiled: dict[str, int] = {}
    _without_a_gpu(compiled)
    if "sweep" in read_config(path):
        _sweep_calls(path, overrides)
    else:
        _run_calls(path, overrides)
    print(json.dumps(compiled))


if __name__ == "__main__":
    from nlcx.errors import NlcxError

    try:
        main(sys.argv[1], sys.argv[2:])
    except NlcxError as exc:  # a kernel CUDA's compiler refused: nlcx's one line, as on a GPU
        sys.exit(str(exc))

"""The PTX of benchmark (b)'s loop: nlcx's closed-loop kernel beside the hand-written reference of
``benchmarks/gpu.py``, compiled by NVVM for an H100 (compute capability 9.0) on a machine
without a GPU. Run from the repository root (needs nlcx[cuda] and the test extra's NVVM):

    python benchmarks/gpu_ptx.py | tee benchmarks/gpu_ptx.txt

For each kernel: its size, its instructions (static counts, not executed ones), the thread's
local memory (``__local_depot``: arrays a thread keeps outside registers) and its loads and
stores, global loads and stores, calls (libdevice's slow trigonometric reduction) and
branches. nlcx's kernel is the one :func:`nlcx.kernel.cuda_loop.launch` builds for (b)'s
variants with nothing recorded, as ``benchmarks/gpu.py`` times it; it is compiled through
``tests/ptx_compile.py``, which stands host arrays for device arrays.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT / "tests"), str(ROOT / "benchmarks")]

import gpu as bench  # noqa: E402
import ptx_compile  # noqa: E402

VARIANTS = 256


def counts(ptx: str) -> dict[str, Any]:
    """Size, instructions and the classes above, counted in the PTX text."""
    lines = [line.strip() for line in ptx.splitlines()]
    instructions = [
        line for line in lines
        if line and not line.startswith(("//", ".", "{", "}", "$")) and not line.endswith(":")
    ]  # fmt: skip
    ops: dict[str, int] = {}
    for line in instructions:
        op = line.split()[0].rstrip(";")
        ops[op] = ops.get(op, 0) + 1

    def count(prefix: str) -> int:
        return sum(v for k, v in ops.items() if k.startswith(prefix))

    depot = [int(b) for b in re.findall(r"__local_depot\d+\[(\d+)\]", ptx)]
    return {
        "KB": len(ptx) // 1024, "instructions": len(instructions), "local bytes": depot,
        "ld.local": count("ld.local"), "st.local": count("st.local"), "ld.global": count("ld.global"),
        "st.global": count("st.global"), "call": count("call"), "branches": count("bra"),
    }  # fmt: skip


def nlcx_ptx() -> str:
    """PTX of nlcx's loop kernel for (b)'s variants, nothing recorded."""
    from numba import cuda

    from nlcx.engine.prepared import TABLEAUS
    from nlcx.kernel import cuda_loop
    from nlcx.kernel.structures import Integration, method_of

    saved: dict[str, str] = {}
    ptx_compile._without_a_gpu({})
    building = cuda_loop.loop_kernel  # now a factory of kernels whose launch compiles them

    class Saving(ptx_compile._Compiling):
        def __call__(self, *args: Any) -> None:
            saved["ptx"], _ = cuda.compile_ptx(self.kernel.py_func, tuple(map(ptx_compile._typed, args)),
                                               cc=ptx_compile.CC)  # fmt: skip

    cuda_loop.loop_kernel = lambda shape: Saving(building(shape).kernel, "loop", {})
    template, slots, columns, _ = bench._variants(VARIANTS)
    plant, controller, elements, forces = bench._kernel_arguments(template, slots, columns, VARIANTS)
    tableau, grid = TABLEAUS["rk4"], template.prepared.grid
    integration = Integration(method=method_of("rk4"), rk_a=tableau.a, rk_b=tableau.b, dt=grid.dt)
    n_log = len(template.items[0].controller.log_names)
    none = np.zeros((0, 2), dtype=np.int64)
    cuda_loop.launch(integration, plant, controller, elements, forces, 1, n_log, grid.t.size, none, False)
    return saved["ptx"]


def reference_ptx() -> str:
    """PTX of the hand-written reference kernel."""
    from numba import cuda

    kernel = bench.reference_kernel(cuda)
    n = VARIANTS
    args = (np.zeros((n, 4)), np.zeros(18), 0.001, 20000, 1.0, np.zeros(n), np.zeros(n), np.zeros(n))
    ptx, _ = cuda.compile_ptx(kernel.py_func, tuple(map(ptx_compile._typed, args)), cc=ptx_compile.CC)
    return ptx


def main() -> None:
    ours = counts(nlcx_ptx())  # first: it sets NVVM's options as nlcx compiles for a GPU
    reference = counts(reference_ptx())
    print(f"PTX of benchmark (b)'s loop for compute capability {'.'.join(map(str, ptx_compile.CC))} (static counts)")
    for name, row in (("nlcx loop kernel", ours), ("hand-written reference", reference)):
        print(f"  {name:<24} " + ", ".join(f"{k} {v}" for k, v in row.items()))


if __name__ == "__main__":
    main()

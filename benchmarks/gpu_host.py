"""The host's share of one GPU sweep batch, stage by stage, measured without a GPU. Run from the
repository root:

    python benchmarks/gpu_host.py | tee benchmarks/gpu_host.txt

A GPU sweep (``nlcx sweep --device cuda``) runs its batches of
:data:`nlcx.sweeps.columnar.GPU_BATCH_VARIANTS` variants in the one process that holds the GPU.
Around the kernel and the metric kernels, that process packs the columns, writes the rows of
the runs that stopped, lays out the metric rows, and writes the two Parquet parts. This script
times those host stages for one batch of benchmark (b)'s sweep (the x pendulum under the
error-AGS PID, M, m and l within +-20 %, 20 s): the outcomes and metric values the GPU would
return are those of 2 000 variants simulated here on the CPU, repeated to fill the batch (the
same share of runs stop, about 28 %). Each stage is timed as the sweep calls it; the best of
three batches is shown.
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from run import sweep_config  # noqa: E402

SIMULATED = 2000


def host_stages(n: int, out: Path) -> dict[str, float]:
    """Seconds of each host stage of one GPU batch of ``n`` variants (parts written under ``out``)."""
    from nlcx import config
    from nlcx import sweeps as sweep
    from nlcx.engine import ensembles
    from nlcx.sweeps import columnar, planning

    raw = sweep_config(n)
    base_raw = {k: v for k, v in raw.items() if k != "sweep"}
    spec = sweep.SweepSection.model_validate(raw["sweep"])
    plan = planning.expand_columns(spec, config.interpolate(base_raw))
    found = columnar.packing(base_raw, spec, plan)
    assert plan is not None and not isinstance(found, str)
    batch = columnar.column_batches(base_raw, plan, found, "0" * 64, out, n, None)[0]
    template = columnar._template(batch)
    few = {key: column[:SIMULATED] for key, column in batch.columns.items()}
    simulated = ensembles.loop_rows(ensembles.simulate_ensemble(template, found.slots, few, SIMULATED), template)

    def filled(a: np.ndarray) -> np.ndarray:
        return np.tile(a, (-(-n // SIMULATED),) + (1,) * (a.ndim - 1))[:n]

    returned = []  # each loop's metric values as the GPU returns them: a row per variant
    for i, loop in enumerate(simulated):
        ok = loop.status == 0
        labels, values = ensembles._ok_values(template, i, loop, ok)
        table = np.full((SIMULATED, len(labels)), np.nan)
        table[ok] = values
        returned.append((labels, filled(table)))

    def ok_values(template: Any, i: int, loop: Any, ok: np.ndarray) -> tuple[list[tuple[str, str]], np.ndarray]:
        return returned[i][0], returned[i][1][ok]

    times: dict[str, float] = {}

    def timed(stage: str, fn: Callable[..., Any], *args: Any) -> Any:
        start = time.perf_counter()
        result = fn(*args)
        times[stage] = time.perf_counter() - start
        return result

    pattern, step = ensembles.ensemble_calls(template.items, n)[0]
    timed("pack the columns", ensembles._call_arguments, template, pattern, step, n, found.slots, batch.columns)
    rows = timed("rows of the runs that stopped", lambda: [
        ensembles.failure_rows(template, filled(loop.status), filled(loop.n_valid), filled(loop.fail_index),
                               filled(np.asarray(loop.bounds))) for loop in simulated])  # fmt: skip
    measured = timed("metric rows", ensembles.measure_ensemble, template, rows, n, ok_values)
    status, message = timed("statuses", columnar._statuses, template, rows, n)
    table = timed("metrics table", columnar._metrics_table, batch, measured)
    timed("metrics part (Parquet)", columnar.write_parquet_table, out / "metrics.parquet", table)
    index = timed("index table (config hashes)", columnar._index_table, batch, status, message)
    timed("index part (Parquet)", columnar.write_parquet_table, out / "index.parquet", index)
    times["rows"] = float(table.num_rows)
    times["stopped"] = float((status == "unstable").sum())
    return times


def main() -> None:
    from nlcx.sweeps.columnar import GPU_BATCH_VARIANTS

    n = GPU_BATCH_VARIANTS
    runs = []
    for _ in range(3):
        with tempfile.TemporaryDirectory() as work:
            runs.append(host_stages(n, Path(work)))
    stages = [k for k in runs[0] if k not in ("rows", "stopped")]
    best = min(runs, key=lambda r: sum(r[k] for k in stages))
    print(f"nlcx host share of a GPU sweep batch, {datetime.date.today()}, {platform.machine()}, "
          f"{os.cpu_count()} cores, Python {platform.python_version()}")  # fmt: skip
    print(f"one batch of {n:,} variants of (b) (20 s), {int(best['stopped']):,} stopped, "
          f"{int(best['rows']):,} metric rows; seconds, the best of 3 batches:")  # fmt: skip
    for k in stages:
        print(f"  {k:<32} {best[k]:.3f}")
    print(f"  {'total':<32} {sum(best[k] for k in stages):.3f}")


if __name__ == "__main__":
    main()

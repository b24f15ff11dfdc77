"""A sweep plan's size, known before it is expanded: how many variants, the memory the
expanded plan takes in the parent, and the bytes its outputs take on disk.

:func:`check` refuses, in one line that gives the estimate, a plan that would not fit in the
memory available or on the disk that would hold its outputs, before any variant is expanded
or computed. The estimates are upper bounds of what nlcx allocates and writes per variant
(``tests/test_sweep_sizing.py`` measures both against them).
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from nlcx import preflight
from nlcx.errors import ConfigError
from nlcx.sweeps.planning import SweepSection

if TYPE_CHECKING:
    from nlcx.config import Experiment

#: Bytes the parent holds per planned variant (the variant, its seed and hash, its row of
#: sweep.csv's index), and per value it sets.
PLAN_BYTES_PER_VARIANT = 600
PLAN_BYTES_PER_VALUE = 200
#: metrics.csv's rows per measured output and per input of a controller (step or regulation
#: metrics with the error integrals; the input's metrics), and the bytes of one row.
ROWS_PER_OUTPUT, ROWS_PER_INPUT, BYTES_PER_ROW = 12, 3, 80
#: Bytes of one variant's row of sweep.csv, and per value it sets.
INDEX_BYTES, INDEX_BYTES_PER_VALUE = 160, 32
#: Bytes the parent's expansion of a plan as columns takes at its peak per variant (its seed,
#: and the words of the seeds' hashing), and per value (a column and a draw).
COLUMN_BYTES_PER_VARIANT, COLUMN_BYTES_PER_VALUE = 64, 16


@dataclass(frozen=True)
class PlanSize:
    """A plan's variants, the bytes of memory its expansion takes and the bytes its outputs
    take on disk (the per-batch parts and the joined files)."""

    variants: int
    values: int
    memory: int
    disk: int


def variant_count(spec: SweepSection) -> int:
    """grid × zip × random, without expanding anything."""
    grid = math.prod(len(v) for v in spec.grid.values())
    zipped = len(next(iter(spec.zip.values()))) if spec.zip else 1
    return grid * zipped * (spec.random.n if spec.random is not None else 1)


def estimate(spec: SweepSection, base: Experiment, columnar: bool = False) -> PlanSize:
    """The size of ``spec``'s plan over the validated base experiment ``base``, expanded as
    columns (``columnar``: :func:`nlcx.sweeps.planning.expand_columns`) or as variants."""
    n = variant_count(spec)
    values = len(spec.grid) + len(spec.zip) + (len(spec.random.params) if spec.random is not None else 0)
    plant = base.plant_model
    rows = len(base.controllers) * (ROWS_PER_OUTPUT * len(plant.outputs) + ROWS_PER_INPUT * len(plant.inputs))
    per_variant_disk = 2 * rows * BYTES_PER_ROW + INDEX_BYTES + INDEX_BYTES_PER_VALUE * values
    if columnar:
        memory = n * (COLUMN_BYTES_PER_VARIANT + COLUMN_BYTES_PER_VALUE * values)
    else:
        memory = n * (PLAN_BYTES_PER_VARIANT + PLAN_BYTES_PER_VALUE * values)
    return PlanSize(n, values, memory, n * per_variant_disk)


def _largest_factor(spec: SweepSection) -> tuple[str, object]:
    """The key whose value makes the plan largest, and that value (for the error line)."""
    factors: list[tuple[int, str, object]] = [
        (len(v), f"sweep.grid.{k}", f"{len(v)} values") for k, v in spec.grid.items()
    ]
    if spec.zip:
        n_zip = len(next(iter(spec.zip.values())))
        factors.append((n_zip, "sweep.zip", f"{n_zip} values"))
    if spec.random is not None:
        factors.append((spec.random.n, "sweep.random.n", spec.random.n))
    _, key, value = max(factors, key=lambda f: f[0])
    return key, value


def _free_disk(out_dir: Path) -> int | None:
    """Free bytes on the file system that would hold ``out_dir`` (its nearest existing parent)."""
    path = out_dir.resolve()
    while not path.exists() and path != path.parent:
        path = path.parent
    try:
        return shutil.disk_usage(path).free
    except OSError:
        return None


def _size(n_bytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 1e3:.3g} kB"


def check(
    spec: SweepSection,
    base: Experiment,
    out_dir: Path | None,
    memory: int | None = None,
    disk: int | None = None,
    columnar: bool = False,
) -> PlanSize:
    """The plan's size, or a one-line :class:`~nlcx.errors.ConfigError` when its expansion
    (as columns with ``columnar``) would take more than :data:`nlcx.preflight.MEMORY_SHARE`
    of the memory available or its outputs more than the free space under ``out_dir``
    (``None``: not written, e.g. a dry run). ``memory`` and ``disk`` replace what the machine
    reports (tests)."""
    size = estimate(spec, base, columnar)
    memory = preflight.available_memory() if memory is None else memory
    disk = _free_disk(out_dir) if disk is None and out_dir is not None else disk
    over_memory = memory is not None and size.memory > preflight.MEMORY_SHARE * memory
    over_disk = out_dir is not None and disk is not None and size.disk > disk
    if over_memory or over_disk:
        key, value = _largest_factor(spec)
        where = (
            f"its expansion needs ~{_size(size.memory)} of memory ({_size(memory or 0)} available)"
            if over_memory
            else f"its outputs need ~{_size(size.disk)} on disk ({_size(disk or 0)} free under {out_dir})"
        )
        raise ConfigError(
            key,
            value,
            f"the plan has {size.variants:,} variants; {where}; allowed: a plan that fits, "
            "e.g. fewer variants or several sweeps over parts of the range",
        )
    return size

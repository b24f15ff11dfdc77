"""Resuming a sweep: the variants that have a complete result, and the staging directory to resume in.

The staging directory (:func:`open_staging`) starts from the finished batches of an
interrupted run, and of a finished sweep of the same plan in the target directory. A batch
is finished when its part files are sealed (:mod:`nlcx.sweeps.seals`); every sealed part a
resumed sweep takes over is checked against its seal first, and a truncated or altered one
is refused in one line naming it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import pandas as pd

import nlcx.sweeps.seals as seals
from nlcx.sweeps.planning import Variant


def completed(out_dir: Path) -> set[str]:
    """Config hashes of every variant with a complete result (status ok or unstable) in a sealed part."""
    done: set[str] = set()
    for part in seals.sealed(out_dir):
        index = pd.read_csv(out_dir / "parts" / f"{part}.index.csv", dtype={"config_hash": str})
        done.update(index.config_hash[index.status.isin(["ok", "unstable"])])
    return done


def _carry_parts(finished: Path, staging: Path, want: Mapping[str, int]) -> None:
    """Link into ``staging`` the sealed parts of the finished sweep ``finished`` that hold a
    variant of this plan (``want``: config hash -> variant index) and are not there yet: each
    part's metrics and index, and the time series of those variants whose index in this plan
    is the one they were written under, then its seal (which marks it complete)."""
    from nlcx import atomic_install

    series: dict[str, list[Path]] = {}
    if (finished / "timeseries").is_dir():
        for path in (finished / "timeseries").iterdir():
            series.setdefault(path.name.partition(".")[0], []).append(path)
    for part in seals.sealed(finished):
        seal = f"{part}{seals.SEAL}"
        if (staging / "parts" / seal).exists():
            continue
        seals.verify_part(finished, part)  # before a byte of it is read
        index = pd.read_csv(finished / "parts" / f"{part}.index.csv", dtype={"config_hash": str})
        planned = index.config_hash.map(want)
        if planned.isna().all():
            continue
        for name in (f"{part}.metrics.csv", f"{part}.index.csv"):
            atomic_install.link_or_copy(finished / "parts" / name, staging / "parts" / name)
        for variant in index.variant[planned.to_numpy() == index.variant.to_numpy()]:
            for source in series.get(f"variant_{int(variant):06d}", []):
                if not (staging / "timeseries" / source.name).exists():
                    atomic_install.link_or_copy(source, staging / "timeseries" / source.name)
        atomic_install.link_or_copy(finished / "parts" / seal, staging / "parts" / seal)


def open_staging(out_dir: Path, variants: list[Variant], hashes: list[str], force: bool) -> Path:
    """The staging directory of a sweep into ``out_dir`` (:func:`nlcx.rundir.open_partial`) with
    the finished batches it resumes from: an interrupted run's, already there, and the finished
    sweep's in ``out_dir`` of this plan's variants (:func:`_carry_parts`); ``force``: none.
    Every sealed part is checked against its seal (:func:`nlcx.sweeps.seals.verify`)."""
    from nlcx import rundir

    staging = rundir.open_partial(out_dir, keep=("parts", "timeseries"), fresh=force)
    if not force and (out_dir / "parts").is_dir():
        _carry_parts(out_dir, staging, {h: v.index for v, h in zip(variants, hashes, strict=True)})
    seals.verify(staging)
    return staging


def open_column_staging(out_dir: Path, force: bool) -> Path:
    """The staging directory of a columnar sweep into ``out_dir``: an interrupted run's sealed
    parts kept, and a finished sweep's in ``out_dir`` linked in (a batch's part name is the hash
    of its values and seeds, so a part of the same name is that batch's result); ``force``:
    none. Every sealed part is checked against its seal (:func:`nlcx.sweeps.seals.verify`)."""
    from nlcx import atomic_install, rundir

    staging = rundir.open_partial(out_dir, keep=("parts",), fresh=force)
    if not force and (out_dir / "parts").is_dir():
        for part in seals.sealed(out_dir):
            seal = f"{part}{seals.SEAL}"
            if not (staging / "parts" / seal).exists():
                seals.verify_part(out_dir, part)
                for name in (f"{part}.metrics.parquet", f"{part}.index.parquet", seal):
                    atomic_install.link_or_copy(out_dir / "parts" / name, staging / "parts" / name)
    seals.verify(staging)
    return staging

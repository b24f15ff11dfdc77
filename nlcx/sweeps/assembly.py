"""A sweep's outputs from its part files: sweep.csv, metrics.csv, config.yaml, manifest.json and the report.

:func:`assemble` reads the part files in variant order (deterministic): per variant its first
complete result, else its last failure. A sweep computed in one go, its parts exactly the
plan's variants in order, gets metrics.csv by joining the parts' files; otherwise they are
read, merged and written, the same bytes.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

import nlcx.sweeps.seals as seals
from nlcx import config as cfg
from nlcx import manifest, plugins
from nlcx.sweeps.planning import SweepSection, Variant

if TYPE_CHECKING:
    import pyarrow as pa


def write_manifest(
    out_dir: Path,
    statuses: dict[str, int],
    spec: SweepSection,
    timings: dict[str, float],
    *,
    name: str,
    variants: int,
    computed: int,
    executor: str,
    jobs: int,
    overrides: Sequence[str] = (),
    started: float | None = None,
    path: str = "",
    allow_env: bool = False,
) -> None:
    """manifest.json: the run (name, kind ``nlcx_output``: sweep, command line, ``overrides``,
    ``allow_env`` (whether the config could call every OmegaConf resolver),
    start and duration from ``started``, variants computed and skipped, statuses, seed,
    executor, and ``path``: how the variants ran, columnar or per-variant and why), the wall
    time of each phase (reading, planning and loading the kernel; the batches; assembling the
    tables), the host, the platform, the package
    versions and the git commit (:func:`nlcx.report.provenance`, :func:`nlcx.report.environment`);
    then the directory's mark and the checksum of every file (:func:`nlcx.manifest.write`; a
    sealed part's as its seal holds it)."""
    from nlcx import report

    info = {
        "name": name,
        "nlcx_output": "sweep",
        **report.provenance(overrides, started),
        "allow_env": allow_env,
        "imports": plugins.loaded(),
        "variants": variants,
        "computed": computed,
        "skipped": variants - computed,
        "status": statuses,
        "path": path,
        "seed": spec.seed,
        "executor": executor,
        "jobs": jobs,
        "wall_s": round(timings["wall"], 3),
        "timings_s": {phase: round(seconds, 3) for phase, seconds in timings.items()},
        **report.environment(),
    }
    manifest.write(out_dir, info, known=seals.known(out_dir))


def _in_plan_order(rows: pd.DataFrame, want: dict[str, int]) -> bool:
    """Whether the part files' rows (concatenated in file order) are each a variant of the plan
    once, under its own index, in ascending order: then metrics.csv is the parts' rows as they
    stand (no retry to supersede, nothing to renumber or reorder)."""
    plan_index = rows.config_hash.map(want)
    return bool(
        plan_index.notna().all()
        and (plan_index.to_numpy() == rows.variant.to_numpy()).all()
        and (np.diff(rows.variant.to_numpy()) > 0).all()
    )


def _joined_metrics(parts_dir: Path, parts: list[str]) -> bytes | None:
    """metrics.csv as the parts' metrics files joined: one header, then each file's rows.

    Only for parts in plan order (:func:`_in_plan_order`) written by this run, whose rows are
    metrics.csv's rows (:func:`nlcx.sweeps.run_batch` writes an empty text as a missing value); None when
    the files' headers differ or no file has a row (then the merge decides the columns)."""
    texts = [(parts_dir / f"{part}.metrics.csv").read_bytes() for part in parts]
    header = texts[0].partition(b"\n")[0] + b"\n"
    if not all(text.startswith(header) and text.endswith(b"\n") for text in texts):
        return None
    body = b"".join(text[len(header) :] for text in texts)
    return header + body if body else None


def _missing_as_null(frame: pd.DataFrame) -> pd.DataFrame:
    """Part tables concatenated, a missing text as a missing value again: a part whose column
    is all empty reads it as numbers (NaN), another as text, and their concatenation holds
    both, which :func:`nlcx.report.write_csv` would write as the text "nan" (a note or
    message of a variant without one)."""
    mixed = [c for c in frame.columns if frame[c].dtype == object]
    return frame.assign(**{c: frame[c].where(frame[c].notna(), None) for c in mixed}) if mixed else frame


def _merged_metrics(parts_dir: Path, parts: list[str], chosen: pd.DataFrame) -> pd.DataFrame:
    """The metrics of the ``chosen`` part rows, read from the part files, renumbered to the
    plan's variant indices and in variant order (a retried variant's last result)."""
    metrics = _missing_as_null(
        pd.concat(
            [
                pd.read_csv(parts_dir / f"{part}.metrics.csv", keep_default_na=False, na_values=[""]).assign(
                    _part=part_no
                )
                for part_no, part in enumerate(parts)
            ],
            ignore_index=True,
        )
    )
    if metrics.empty:
        return metrics.drop(columns="_part")
    link = chosen[["_part", "variant", "new_variant"]]
    metrics = metrics.merge(link, on=["_part", "variant"], how="inner", sort=False)
    metrics = metrics.assign(variant=metrics.new_variant).drop(columns=["_part", "new_variant"])
    metrics = metrics.drop_duplicates(subset=["variant", "controller", "signal", "metric"], keep="last")
    return metrics.sort_values("variant", kind="stable").reset_index(drop=True)


def _member_of(hashes: pd.Series, wanted: Collection[str]) -> np.ndarray:
    """``hashes.isin(wanted)`` by set lookups: pandas' ``isin`` on Arrow-backed strings loops
    in Python, a noticeable part of assembling a large sweep."""
    return np.fromiter((h in wanted for h in hashes.to_numpy(dtype=object)), dtype=bool, count=len(hashes))


def assemble(
    out_dir: Path,
    variants: list[Variant],
    hashes: list[str],
    base_raw: dict[str, object],
    spec: SweepSection,
    written: Collection[str] = (),
) -> pd.DataFrame:
    """The tables sweep and metrics (CSV files or Parquet datasets, ``spec.format``) from the
    part files of a per-variant sweep, in variant order (deterministic).

    ``written`` names the parts this process's run wrote (:func:`nlcx.sweeps.run`): when they are all
    the parts and hold exactly the plan's variants, in order, metrics.csv is their files
    joined (:func:`_joined_metrics`), the same bytes as reading, merging and writing them."""
    from nlcx import report

    want = {h: v.index for v, h in zip(variants, hashes, strict=True)}
    parts = seals.sealed(out_dir)
    indexes = [
        pd.read_csv(out_dir / "parts" / f"{part}.index.csv", dtype={"config_hash": str}).assign(_part=part_no)
        for part_no, part in enumerate(parts)
    ]
    if not indexes:
        report.write_csv(out_dir / "sweep.csv", pd.DataFrame())
        report.write_csv(out_dir / "metrics.csv", pd.DataFrame())
        write_config(out_dir, base_raw, spec)
        return pd.DataFrame()
    rows = _missing_as_null(pd.concat(indexes, ignore_index=True))
    in_plan_order = set(parts) <= set(written) and _in_plan_order(rows, want)
    rows = rows[_member_of(rows.config_hash, want)]
    # per variant: its first complete result, else its last failure (a retry supersedes a failure)
    complete = rows[rows.status != "failed"].drop_duplicates("config_hash", keep="first")
    failed = rows[(rows.status == "failed") & ~_member_of(rows.config_hash, set(complete.config_hash))]
    chosen = pd.concat([complete, failed.drop_duplicates("config_hash", keep="last")])
    chosen = chosen.assign(new_variant=chosen.config_hash.map(want))
    index = chosen.assign(variant=chosen.new_variant).drop(columns=["_part", "new_variant"])
    index = index.sort_values("variant", kind="stable").reset_index(drop=True)
    if spec.format == "parquet":
        write_dataset(out_dir / "sweep.parquet", [(0, arrow_table(index))])
        metrics = _merged_metrics(out_dir / "parts", parts, chosen)
        write_dataset(out_dir / "metrics.parquet", [(0, arrow_table(metrics))])
    else:
        report.write_csv(out_dir / "sweep.csv", index)
        joined = _joined_metrics(out_dir / "parts", parts) if in_plan_order else None
        if joined is not None:
            report.write_bytes(out_dir / "metrics.csv", joined)
        else:
            report.write_csv(out_dir / "metrics.csv", _merged_metrics(out_dir / "parts", parts, chosen))
    write_config(out_dir, base_raw, spec)
    return index


def write_config(out_dir: Path, base_raw: dict[str, object], spec: SweepSection) -> None:
    """config.yaml: the base config interpolated, with its sweep section resolved."""
    import yaml

    from nlcx import report

    resolved = {**cfg.interpolate(base_raw, allow_env=True), "sweep": spec.model_dump()}  # checked by planning.load
    report.write_text(out_dir / "config.yaml", yaml.safe_dump(resolved, sort_keys=False, allow_unicode=True))


def arrow_table(frame: pd.DataFrame) -> pa.Table:
    """``frame`` as the Arrow table of a sweep's Parquet output: text columns as strings (a
    missing or empty text null), numbers as they are (a NaN null), as the CSV form reads back."""
    import pyarrow as pa

    from nlcx.report import empty_text_as_null

    table = pa.Table.from_pandas(_missing_as_null(frame), preserve_index=False)
    columns = [c.cast(pa.string()) if pa.types.is_null(c.type) or pa.types.is_large_string(c.type) else c
               for c in table.columns]  # fmt: skip
    return empty_text_as_null(pa.table(columns, names=table.column_names))


def write_dataset(directory: Path, tables: Sequence[tuple[int, pa.Table]]) -> None:
    """A Parquet dataset: each (first row's variant, table) as ``directory/part-<variant>.parquet``."""
    from nlcx.sweeps.columnar import write_parquet_table

    _fresh(directory)
    for first, table in tables:
        write_parquet_table(directory / f"part-{first:09d}.parquet", table)


def _fresh(directory: Path) -> None:
    """``directory`` empty (a resumed staging directory may hold an earlier run's tables)."""
    import shutil

    if directory.is_dir():
        shutil.rmtree(directory)
    elif directory.exists():
        directory.unlink()
    directory.mkdir(parents=True)


def _text_columns(table: pa.Table) -> pa.Table:
    """``table`` with its dictionary-encoded columns as plain strings (what the CSV writer takes)."""
    import pyarrow as pa

    columns = [c.cast(pa.string()) if pa.types.is_dictionary(c.type) else c for c in table.columns]
    return pa.table(columns, names=table.column_names)


def _csv_of_parts(target: Path, paths: Sequence[Path]) -> None:
    """The part files' tables, in order, as one CSV (the bytes :func:`nlcx.report.write_csv`
    writes for their rows), written part by part."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    from nlcx.drawing import atomic_write

    def write(tmp: Path) -> None:
        writer = None
        for path in paths:
            table = _text_columns(pq.read_table(path))
            if writer is None:
                writer = pacsv.CSVWriter(
                    str(tmp), table.schema, write_options=pacsv.WriteOptions(quoting_style="needed")
                )
            writer.write_table(table)
        if writer is not None:
            writer.close()

    atomic_write(target, write)


def assemble_columns(
    out_dir: Path,
    parts: Sequence[tuple[int, str]],
    base_raw: dict[str, object],
    spec: SweepSection,
    known: Mapping[str, Mapping[str, int]] | None = None,
) -> dict[str, int]:
    """The tables of a columnar sweep from its part files (``parts``: each batch's first variant
    and part name, in plan order, every one complete): in Parquet, the part files themselves,
    linked into the datasets sweep.parquet/ and metrics.parquet/ (nothing is read again); in
    CSV, their rows written out part by part. Returns the count of each status: ``known`` holds
    those of the parts this run computed (their workers counted them); the others' are read."""
    import pyarrow.parquet as pq

    from nlcx import atomic_install

    for name, stem in (("metrics", "metrics"), ("index", "sweep")):
        paths = [out_dir / "parts" / f"{part}.{name}.parquet" for _, part in parts]
        if spec.format == "parquet":
            _fresh(out_dir / f"{stem}.parquet")
            for (first, _), path in zip(parts, paths, strict=True):
                atomic_install.link_or_copy(path, out_dir / f"{stem}.parquet" / f"part-{first:09d}.parquet")
        else:
            _csv_of_parts(out_dir / f"{stem}.csv", paths)
    write_config(out_dir, base_raw, spec)
    counts: dict[str, int] = {}
    for _, part in parts:
        if known is not None and part in known:
            found = dict(known[part])
        else:
            status = pq.read_table(out_dir / "parts" / f"{part}.index.parquet", columns=["status"]).column(0)
            found = {v["values"]: v["counts"] for v in status.value_counts().to_pylist()}
        for key, count in found.items():
            counts[key] = counts.get(key, 0) + count
    return dict(sorted(counts.items()))

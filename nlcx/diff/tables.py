"""The tables ``nlcx diff`` compares, read a chunk of rows at a time: CSV files, Parquet files and
Parquet datasets.

A table (:class:`TableSource`) is never read whole: a CSV file by pyarrow's streaming reader
in blocks of :data:`BLOCK_BYTES` (larger where a row is longer), every cell as text and an
empty cell as missing, or as float64 in the columns asked for as numbers; a Parquet file in
batches of :data:`CHUNK_ROWS` rows; a Parquet dataset (a directory of ``part-*.parquet`` files)
part file by part file in name order. The blocks of a CSV are handed on in chunks of at least
:data:`CHUNK_ROWS` rows. Before any file of a table is read, it is checked against the
manifest of the nlcx output directory that lists it (:func:`open_table`,
:func:`nlcx.manifest.verify_file`): a truncated or altered file is refused in one line; a file
that no manifest lists is read as it is.

The kinds of the columns, their cells as text or numbers and the rows' hashes are
:mod:`nlcx.diff.cells`'s.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from nlcx.diff.cells import BOOLEAN, NUMBER, TEXT, ColumnKind, CsvScan
from nlcx.errors import NlcxError
from nlcx.manifest import verify_file
from nlcx.pages.output_tables import FLOAT_COLUMNS, STEMS, TEXT_COLUMNS, part_files

#: Bytes of a CSV file parsed at a time (pyarrow's streaming reader holds some forty blocks).
BLOCK_BYTES = 1 << 18
#: The largest block, for a CSV whose rows are longer than :data:`BLOCK_BYTES`.
MAX_BLOCK_BYTES = 1 << 30
#: Rows handed on at a time (a CSV's blocks gathered, a Parquet file's batches).
CHUNK_ROWS = 1 << 16
#: Bytes compared at a time when two files may be the same.
COMPARE_BYTES = 1 << 20


@dataclass
class TableSource:
    """One table: a CSV file, a Parquet file or a Parquet dataset directory.

    Parameters
    ----------
    path : Path
        The file, or the dataset directory.
    files : list of Path
        The files that hold its rows, in order, each checked against its manifest.
    """

    path: Path
    files: list[Path]
    _columns: list[str] | None = field(default=None, repr=False)

    @property
    def is_csv(self) -> bool:
        return self.path.suffix != ".parquet"

    @property
    def is_sweep_table(self) -> bool:
        """Whether the table is a sweep's ``metrics`` or ``sweep`` (or a run's metrics.csv)."""
        return self.path.stem in STEMS

    @property
    def columns(self) -> list[str]:
        """The column names, in order (a repeated CSV name as pandas names it: ``a``, ``a.1``)."""
        if self._columns is None:
            self._columns = _csv_header(self.path) if self.is_csv else _parquet_columns(self.files)
        return self._columns

    def batches(self, columns: Sequence[str], numbers: Sequence[str] = ()) -> Iterator[pa.RecordBatch]:
        """The rows of ``columns`` (at least one), about :data:`CHUNK_ROWS` at a time: a CSV's
        cells as text (an empty cell as null) but those of ``numbers``, read as float64; a
        Parquet file's as stored.

        Raises
        ------
        KindChangedError
            A cell of a CSV's column of ``numbers`` is not a number.
        """
        if not columns:
            raise ValueError("batches of no column")
        if self.is_csv:
            yield from _gathered(_csv_batches(self.path, self.columns, list(columns), list(numbers)))
        else:
            for file in self.files:
                yield from _parquet_batches(file, list(columns))

    def first_kinds(self, columns: Sequence[str]) -> dict[str, ColumnKind]:
        """The kind of each of ``columns`` as far as a CSV's first chunk of rows tells (a column
        of numbers may hold text further on: :func:`kind_holds`); a Parquet file's kinds."""
        if not self.is_csv:
            return self.kinds(columns)
        fixed = {c: self._fixed_kind(c) for c in columns}
        scans = {c: CsvScan() for c in columns if fixed[c] is None}
        first = next(self.batches(list(scans)), None) if scans else None
        rows = 0 if first is None else first.num_rows
        for name, scan in scans.items():
            if first is not None:
                scan.update(first.column(name))
        return {c: fixed[c] or scans[c].kind(rows) for c in columns}

    def kinds(self, columns: Sequence[str]) -> dict[str, ColumnKind]:
        """The kind of each of ``columns``: read from a Parquet file's types; found in one pass
        over a CSV's cells (only the columns that may be numbers)."""
        fixed = {c: self._fixed_kind(c) for c in columns}
        if not self.is_csv:
            return {c: fixed[c] or _parquet_kind(self.files, c) for c in columns}
        scans = {c: CsvScan() for c in columns if fixed[c] is None}
        rows = self._scan(scans) if scans else 0
        return {c: fixed[c] or scans[c].kind(rows) for c in columns}

    def _scan(self, scans: dict[str, CsvScan]) -> int:
        """Scan a CSV's cells for ``scans``: its first block for every column, then the whole
        file for the columns that may still be numbers (most text columns show in the first
        block). Returns the rows of the table."""
        first = next(self.batches(list(scans)), None)
        if first is None:
            return 0
        for name, scan in scans.items():
            scan.update(first.column(name))
        still = [c for c, scan in scans.items() if scan.open]
        if not still:
            return first.num_rows or sum(batch.num_rows for batch in self.batches([next(iter(scans))]))
        fresh = {c: CsvScan() for c in still}
        rows = 0
        for batch in self.batches(still):
            rows += batch.num_rows
            for name in [c for c, scan in fresh.items() if scan.open]:
                fresh[name].update(batch.column(name))
        scans.update(fresh)
        return rows

    def has_values(self, column: str) -> bool:
        """Whether a column of numbers holds any number (one pass over it)."""
        return any(batch.column(0).null_count < batch.num_rows for batch in self.batches([column]))

    def _fixed_kind(self, column: str) -> ColumnKind | None:
        """The kind a sweep's table gives ``column`` whatever its cells, or None."""
        if self.is_sweep_table and column in TEXT_COLUMNS:
            return ColumnKind(TEXT)
        if self.is_sweep_table and column in FLOAT_COLUMNS:
            return ColumnKind(NUMBER, None)
        return None


def open_table(path: Path, verified: set[tuple[int, int]] | None = None) -> TableSource:
    """The table at ``path``, each of its files checked against its manifest first.

    Parameters
    ----------
    path : Path
        A CSV or Parquet file, or a Parquet dataset directory.
    verified : set, optional
        The files checked already (device and inode), not checked again; updated.

    Raises
    ------
    nlcx.manifest.IntegrityError
        A file of the table is not the one its manifest lists (one line naming it).
    """
    files = part_files(path) if path.is_dir() else [path]
    seen = verified if verified is not None else set()
    for file in files:
        stat = file.stat()
        if (stat.st_dev, stat.st_ino) not in seen:
            verify_file(file)
            seen.add((stat.st_dev, stat.st_ino))
    return TableSource(path, files)


def same_bytes(base: TableSource, new: TableSource) -> bool:
    """Whether two tables are the same bytes: the same form, and file for file (a dataset's part
    files by name) the same size and the same bytes."""
    if base.is_csv != new.is_csv or base.path.is_dir() != new.path.is_dir() or len(base.files) != len(new.files):
        return False
    if base.path.is_dir() and [f.name for f in base.files] != [f.name for f in new.files]:
        return False
    pairs = list(zip(base.files, new.files, strict=True))
    if any(a.stat().st_size != b.stat().st_size for a, b in pairs):
        return False
    return all(_same_file_bytes(a, b) for a, b in pairs)


def _same_file_bytes(a: Path, b: Path) -> bool:
    """Whether two files of one size hold the same bytes (read a megabyte at a time)."""
    if os.path.samefile(a, b):
        return True
    with open(a, "rb") as one, open(b, "rb") as other:
        while chunk := one.read(COMPARE_BYTES):
            if chunk != other.read(COMPARE_BYTES):
                return False
    return True


def _csv_header(path: Path) -> list[str]:
    """A CSV's column names (none in an empty file); a repeated name as ``name.1``, ``name.2``."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as stream:
            names = next(csv.reader(stream), [])
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise NlcxError(f"diff error: {path}: cannot read its header: {_first_line(exc)}") from None
    seen: dict[str, int] = {}
    out = []
    for name in names:
        count = seen.get(name, 0)
        seen[name] = count + 1
        out.append(name if count == 0 else f"{name}.{count}")
    return out


class KindChangedError(Exception):
    """A CSV column taken for numbers from its first rows holds text further on."""


def _csv_batches(path: Path, names: list[str], columns: list[str], numbers: list[str]) -> Iterator[pa.RecordBatch]:
    """The CSV's ``columns`` a block at a time: as text, an empty cell (quoted or not) as null;
    those of ``numbers`` as float64. A row longer than a block is read in larger blocks (the
    file read again from the top, the rows handed on already skipped)."""
    if not names:
        return
    block, done = BLOCK_BYTES, 0
    while True:
        try:
            for batch in _skipped(_csv_reader(path, names, columns, numbers, block), done):
                done += batch.num_rows
                yield batch
            return
        except (pa.ArrowInvalid, OSError) as exc:
            if "straddling" in str(exc) and block < MAX_BLOCK_BYTES:
                block *= 16
                continue
            if numbers and isinstance(exc, pa.ArrowInvalid):
                raise KindChangedError(str(path)) from None  # read again as text, to tell which
            raise NlcxError(f"diff error: {path}: cannot read it as CSV: {_first_line(exc)}") from None


def _csv_reader(
    path: Path, names: list[str], columns: list[str], numbers: list[str], block: int
) -> pa_csv.CSVStreamingReader:
    """pyarrow's streaming reader of the CSV ``path`` (column ``names``, the header skipped)."""
    read = pa_csv.ReadOptions(block_size=block, column_names=names, skip_rows=1)
    parse = pa_csv.ParseOptions(newlines_in_values=True)
    types = {c: pa.float64() if c in numbers else pa.string() for c in columns}
    convert = pa_csv.ConvertOptions(
        column_types=types,
        include_columns=columns,
        strings_can_be_null=True,
        quoted_strings_can_be_null=True,
        null_values=[""],
    )
    return pa_csv.open_csv(path, read_options=read, parse_options=parse, convert_options=convert)


def _skipped(batches: Iterator[pa.RecordBatch], rows: int) -> Iterator[pa.RecordBatch]:
    """``batches`` without their first ``rows`` rows."""
    for batch in batches:
        if rows >= batch.num_rows:
            rows -= batch.num_rows
            continue
        yield batch.slice(rows) if rows else batch
        rows = 0


def _gathered(batches: Iterator[pa.RecordBatch]) -> Iterator[pa.RecordBatch]:
    """Small batches gathered into batches of at least :data:`CHUNK_ROWS` rows (the last fewer)."""
    held: list[pa.RecordBatch] = []
    rows = 0
    for batch in batches:
        held.append(batch)
        rows += batch.num_rows
        if rows >= CHUNK_ROWS:
            yield _joined(held)
            held, rows = [], 0
    if held:
        yield _joined(held)


def _joined(batches: list[pa.RecordBatch]) -> pa.RecordBatch:
    """Batches of the same columns as one."""
    if len(batches) == 1:
        return batches[0]
    columns = [pa.concat_arrays([b.column(i) for b in batches]) for i in range(batches[0].num_columns)]
    return pa.RecordBatch.from_arrays(columns, batches[0].schema.names)


def _parquet_columns(files: list[Path]) -> list[str]:
    """The column names of a Parquet file or dataset (its first part file's)."""
    if not files:
        return []
    try:
        return list(pq.ParquetFile(files[0]).schema_arrow.names)
    except (pa.ArrowInvalid, OSError) as exc:
        raise NlcxError(f"diff error: {files[0]}: cannot read it as Parquet: {_first_line(exc)}") from None


def _parquet_batches(file: Path, columns: list[str]) -> Iterator[pa.RecordBatch]:
    """The Parquet file's ``columns``, :data:`CHUNK_ROWS` rows at a time."""
    try:
        yield from pq.ParquetFile(file).iter_batches(batch_size=CHUNK_ROWS, columns=columns)
    except (pa.ArrowInvalid, OSError, KeyError) as exc:
        raise NlcxError(f"diff error: {file}: cannot read it as Parquet: {_first_line(exc)}") from None


def _parquet_kind(files: list[Path], column: str) -> ColumnKind:
    """A Parquet column's kind, from its type in each file: numbers (integers, floats, or all
    null), booleans, or text; text where the files disagree."""
    schemas = [pq.ParquetFile(file).schema_arrow for file in files]
    kinds = {_type_kind(schema.field(column).type) for schema in schemas if column in schema.names}
    named = sorted(k for k in kinds if k is not None)
    if not named:
        return ColumnKind(NUMBER, False)
    return ColumnKind(named[0], None) if len(named) == 1 else ColumnKind(TEXT)


def _type_kind(kind: pa.DataType) -> str | None:
    """The kind of a column of the Arrow type ``kind``; None for the null type (any kind)."""
    if pa.types.is_dictionary(kind):
        kind = kind.value_type
    if pa.types.is_null(kind):
        return None
    if pa.types.is_boolean(kind):
        return BOOLEAN
    if pa.types.is_integer(kind) or pa.types.is_floating(kind) or pa.types.is_decimal(kind):
        return NUMBER
    return TEXT


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__

"""A sweep's two tables, ``sweep`` and ``metrics``, read from whichever form holds them.

A sweep writes its index (``sweep``: one row a variant) and its metrics (``metrics``: long
form) in one of two forms, and a directory holds each table in one form only:

- Parquet (the default): ``<stem>.parquet``, a dataset: a directory of ``part-*.parquet``
  files whose rows, the files taken in name order and the rows in file order, are the
  table's rows in order (a single Parquet file of that name is read as well);
- CSV (``sweep.format: csv``): ``<stem>.csv``.

:func:`read_output_table` reads either into the frame the CSV gives (:func:`read_table`), so
every reader of a sweep's tables accepts both forms. A run's directory (``nlcx run``) holds
its metrics as ``metrics.csv``, which reads the same way.

This module imports neither pandas nor pyarrow until a table is read: finding a table
(:func:`table_path`) costs a run's report nothing.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from nlcx.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

#: The tables of a sweep's output directory, by the stem of their file names.
STEMS = ("metrics", "sweep")
#: The text columns of the tables: read as str, a missing text as "".
TEXT_COLUMNS = ("controller", "signal", "metric", "unit", "status", "note", "config_hash", "message")
#: The columns of numbers that are float64 whatever their values (a missing number is NaN).
FLOAT_COLUMNS = ("value",)
#: The files of a Parquet dataset that hold its rows.
PART_FILES = "part-*.parquet"


def table_path(directory: Path, stem: str) -> Path | None:
    """Where ``directory`` holds the table ``stem``: ``<stem>.parquet`` (a dataset directory
    or a file) if present, else ``<stem>.csv`` if present, else None."""
    parquet = directory / f"{stem}.parquet"
    if parquet.is_dir() or parquet.is_file():
        return parquet
    csv = directory / f"{stem}.csv"
    return csv if csv.is_file() else None


def has_table(directory: Path, stem: str) -> bool:
    """Whether ``directory`` holds the table ``stem`` in either form (:func:`table_path`)."""
    return table_path(directory, stem) is not None


def is_table(path: Path) -> bool:
    """Whether ``path`` is a table: a file, or a Parquet dataset (a directory named ``*.parquet``)."""
    return path.is_file() or (path.is_dir() and path.suffix == ".parquet")


def read_output_table(directory: str | os.PathLike[str], stem: str) -> pd.DataFrame:
    """Read a table of a sweep's output directory, in either of its forms.

    Parameters
    ----------
    directory : str or path
        The sweep's output directory (or a run's, for ``metrics``).
    stem : {"metrics", "sweep"}
        The table: ``<stem>.parquet`` (a Parquet dataset directory of ``part-*.parquet``
        files, or one Parquet file) when present, else ``<stem>.csv``.

    Returns
    -------
    pandas.DataFrame
        The table as the CSV gives it, whichever form was read (:func:`read_table`): the
        columns in the file's order, a default index; text columns (controller, signal,
        metric, unit, status, note, config_hash, message) as str, a missing text as "";
        ``value`` as float64, a missing number as NaN; any other column (``variant``,
        ``seed``, a varied value ``value:<key>``) as pandas reads the CSV: integers as int64,
        other numbers as float64, booleans as bool, text as str, a missing value as NaN.

    Raises
    ------
    nlcx.errors.ConfigError
        If ``stem`` is not a table of a sweep, or ``directory`` holds the table in neither form.
    """
    if stem not in STEMS:
        raise ConfigError("stem", stem, f"not a table of a sweep; allowed: {', '.join(STEMS)}")
    where = Path(directory)
    path = table_path(where, stem)
    if path is None:
        raise ConfigError(
            "directory", str(where), f"no {stem}.parquet or {stem}.csv in it; allowed: an nlcx sweep's output directory"
        )
    return read_table(path)


def read_table(path: Path) -> pd.DataFrame:
    """A table file (``*.csv``, ``*.parquet``) or Parquet dataset directory, read as
    :func:`read_output_table` describes: a CSV with empty cells as missing values (any other
    text kept as it is, ``NA`` included), a Parquet table with its dictionary-encoded
    columns decoded and its nulls as the CSV's missing values."""
    if path.suffix == ".parquet":
        return _from_arrow(_read_parquet(path))
    return _read_csv(path)


def _float_precision() -> Literal["round_trip"] | None:
    """How pandas reads the CSV's floats to the last bit, as Parquet holds them: pandas 3
    does by default (None; it deprecates the other choices); pandas 2's default parser may
    miss the last bit of a float written in its shortest round-trip form."""
    import pandas as pd

    return "round_trip" if int(pd.__version__.split(".")[0]) < 3 else None


def _read_csv(path: Path) -> pd.DataFrame:
    """The CSV ``path``: an empty cell is missing, any other text kept; text columns as str;
    floats exact (:func:`_float_precision`)."""
    import pandas as pd

    text = dict.fromkeys(TEXT_COLUMNS, str)
    precision = _float_precision()
    try:
        frame = pd.read_csv(path, dtype=text, keep_default_na=False, na_values=[""], float_precision=precision)
    except pd.errors.EmptyDataError:  # a sweep without variants: an empty file
        return pd.DataFrame()
    return _typed(frame)


def _typed(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with its text columns' missing values as "" and :data:`FLOAT_COLUMNS` as float64."""
    import numpy as np

    fixed = {c: frame[c].fillna("") for c in frame.columns if c in TEXT_COLUMNS}
    fixed.update({c: frame[c].astype(np.float64) for c in frame.columns if c in FLOAT_COLUMNS})
    return frame.assign(**fixed) if fixed else frame


def part_files(path: Path) -> list[Path]:
    """The files that hold a Parquet table's rows, in order: a dataset directory's part files in
    name order, or the file itself."""
    return sorted(path.glob(PART_FILES), key=lambda p: p.name) if path.is_dir() else [path]


def _read_parquet(path: Path) -> pa.Table:
    """The Parquet file ``path``, or the rows of the dataset directory ``path`` in order.

    The part files are scanned as one dataset (in parallel, in their order); where their
    column types differ (a column all null in one file, dictionary-encoded in another) each
    is read alone and the tables are joined with their types unified."""
    import pyarrow as pa
    import pyarrow.dataset as ds
    import pyarrow.parquet as pq

    if path.is_file():
        return pq.read_table(path)
    files = [str(p) for p in part_files(path)]
    if not files:
        return pa.table({})
    try:
        return ds.dataset(files, format="parquet").to_table()
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
        tables = [_plain_table(pq.read_table(file)) for file in files]
        return pa.concat_tables(tables, promote_options="permissive")


def _plain(name: str, column: pa.ChunkedArray) -> pa.ChunkedArray:
    """A column as the CSV's reader types it: dictionaries decoded; a text column
    (:data:`TEXT_COLUMNS`) as strings, null as ""; a float column (:data:`FLOAT_COLUMNS`),
    other floats and an all-null column as float64; integers as int64; text as strings."""
    import pyarrow as pa
    import pyarrow.compute as pc

    kind = column.type
    if pa.types.is_dictionary(kind):
        column, kind = column.cast(kind.value_type), kind.value_type
    if name in TEXT_COLUMNS:
        return pc.fill_null(column.cast(pa.string()), "")
    if name in FLOAT_COLUMNS or pa.types.is_floating(kind) or pa.types.is_null(kind):
        return column.cast(pa.float64())
    if pa.types.is_integer(kind):
        return column.cast(pa.int64())
    if pa.types.is_large_string(kind) or pa.types.is_string_view(kind):
        return column.cast(pa.string())
    return column


def _plain_table(table: pa.Table) -> pa.Table:
    """``table`` with every column :func:`_plain` and no schema metadata (pandas' own among it)."""
    import pyarrow as pa

    names = table.column_names
    return pa.table([_plain(name, table.column(name)) for name in names], names=names)


def _from_arrow(table: pa.Table) -> pd.DataFrame:
    """The frame of an Arrow table, typed as :func:`_read_csv` types the CSV's: a missing
    value of a column of other objects (text, booleans) is NaN, as the CSV's reader gives it."""
    import numpy as np
    import pandas as pd

    if not table.column_names:
        return pd.DataFrame()
    frame = _plain_table(table).to_pandas()
    objects = [c for c in frame.columns if frame[c].dtype == object and c not in TEXT_COLUMNS]
    fixed = {c: frame[c].where(frame[c].notna(), np.nan) for c in objects}
    return frame.assign(**fixed) if fixed else frame

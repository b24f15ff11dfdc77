"""The cells of a column ``nlcx diff`` compares: its kind, and its cells as text, as numbers and
as row hashes.

A column is compared as numbers or as text according to its :class:`ColumnKind`: a Parquet column by
its type; a CSV column as pandas types it (:meth:`nlcx.diff.tables.TableSource.kinds`): numbers
when every cell that is not empty is a number (a column holding the text ``nan`` is text),
booleans when every cell is ``True`` or ``False`` (``TRUE``, ``true``, ...), text otherwise, and
text in a table without rows. :meth:`~nlcx.diff.tables.TableSource.first_kinds` tells the same
from a CSV's first chunk alone; :func:`kind_holds` checks each later chunk against it. In a
sweep's tables (``metrics``, ``sweep``) the columns of
:data:`~nlcx.pages.output_tables.TEXT_COLUMNS` are text and ``value`` holds numbers, as
:func:`nlcx.pages.output_tables.read_table` reads them.

Rows are told apart by 64-bit hashes of their text cells (:func:`hash_rows`): each distinct text
of a chunk is hashed once (pandas' SipHash), and the hashes of a row's cells are mixed in order
(SplitMix64's finalizer, :func:`mix`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

#: The texts pandas reads as booleans.
TRUE_TEXTS = ("True", "TRUE", "true")
FALSE_TEXTS = ("False", "FALSE", "false")
#: A number as text: digits with a point and an exponent, an infinity, or NaN (spaces around it).
_NUMBER = r"^\s*[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[iI][nN][fF]([iI][nN][iI][tT][yY])?|[nN][aA][nN])\s*$"

#: A missing number.
_NO_NUMBER = pa.scalar(None, pa.float64())
#: The kinds of column.
NUMBER, BOOLEAN, TEXT = "number", "boolean", "text"


@dataclass(frozen=True)
class ColumnKind:
    """How a column of one table reads: ``name`` is :data:`NUMBER`, :data:`BOOLEAN` or
    :data:`TEXT`; ``has_values``: whether a column of numbers holds any (None: not known yet)."""

    name: str
    has_values: bool | None = True

    @property
    def numeric(self) -> bool:
        """Whether pandas gives the column a numeric dtype (booleans included)."""
        return self.name != TEXT


@dataclass
class CsvScan:
    """What the cells of one CSV column seen so far allow it to be."""

    numbers: bool = True
    booleans: bool = True
    empty: bool = False
    values: bool = False

    def update(self, column: pa.Array) -> None:
        """Take the cells of one chunk into account."""
        cells = pc.drop_null(column)
        self.empty = self.empty or column.null_count > 0
        self.values = self.values or len(cells) > 0
        if self.numbers:
            self.numbers = _all_numbers(cells)
        if self.booleans:
            self.booleans = _all_booleans(cells)

    def kind(self, rows: int) -> ColumnKind:
        """The column's kind once every cell is seen (``rows``: the table's rows)."""
        if rows == 0:
            return ColumnKind(TEXT)
        if self.numbers:
            return ColumnKind(NUMBER, self.values)
        if self.booleans and not self.empty:
            return ColumnKind(BOOLEAN)
        return ColumnKind(TEXT)

    @property
    def open(self) -> bool:
        """Whether the column may still be numbers or booleans."""
        return self.numbers or self.booleans


def _all_booleans(cells: pa.Array) -> bool:
    """Whether every text of ``cells`` (no missing ones) is one pandas reads as a boolean."""
    return pc.all(pc.is_in(cells, pa.array(TRUE_TEXTS + FALSE_TEXTS))).as_py() is not False


def _all_numbers(cells: pa.Array) -> bool:
    """Whether every text of ``cells`` (no missing ones) is a number pandas reads as one."""
    if len(cells) == 0:
        return True
    numbers = _cast_numbers(cells)
    if numbers is None:
        numbers = _cast_numbers(pc.utf8_trim_whitespace(cells))
    return numbers is not None and not pc.any(pc.is_nan(numbers)).as_py()  # pandas reads "nan" as text


#: Cells tried first when casting text to numbers: a failed cast of a long array is slow.
_SAMPLE = 64


def _cast_numbers(cells: pa.Array) -> pa.Array | None:
    """The texts ``cells`` as float64, or None when one is not a number."""
    try:
        pc.cast(cells.slice(0, _SAMPLE), pa.float64())
        return pc.cast(cells, pa.float64())
    except pa.ArrowInvalid:
        return None


def kind_holds(column: pa.Array, kind: ColumnKind) -> bool:
    """Whether a chunk of a CSV column keeps to the kind its first chunk gave it: no NaN in a
    column of numbers read as float64 (pandas reads a column holding the text ``nan`` as text),
    only ``True``/``False`` in a column of booleans."""
    if kind.name == NUMBER and pa.types.is_floating(column.type):
        return not pc.any(pc.is_nan(column)).as_py()
    if kind.name == BOOLEAN and pa.types.is_string(column.type):
        return column.null_count == 0 and _all_booleans(column)
    return True


def _plain(column: pa.Array) -> pa.Array:
    """A column with its dictionary decoded and a long string type as a string."""
    if pa.types.is_dictionary(column.type):
        column = column.dictionary_decode()
    string_view = getattr(pa.types, "is_string_view", None)  # pyarrow >= 16
    if pa.types.is_large_string(column.type) or (string_view is not None and string_view(column.type)):
        column = column.cast(pa.string())
    return column


def as_texts(column: pa.Array) -> pa.Array:
    """A column's cells as text, as pandas writes them with ``str``: a missing cell as ``""``,
    a boolean as ``True``/``False``, a float as Python writes it."""
    column = _plain(column)
    kind = column.type
    if pa.types.is_string(kind):
        return pc.fill_null(column, "")
    if pa.types.is_null(kind):
        return pa.array([""] * len(column), pa.string())
    if pa.types.is_boolean(kind):
        return pc.fill_null(pc.if_else(column, "True", "False"), "")
    if pa.types.is_floating(kind):
        codes = pc.dictionary_encode(column.cast(pa.float64()))
        names = ["" if v is None or v != v else str(v) for v in codes.dictionary.to_pylist()]
        return pc.fill_null(pa.array(names, pa.string()).take(codes.indices), "")
    return pc.fill_null(column.cast(pa.string()), "")


def as_numbers(column: pa.Array, kind: ColumnKind) -> np.ndarray:
    """A column's cells as float64 (a missing cell, or a text that is not a number, as NaN);
    booleans as 1 and 0."""
    column = _plain(column)
    if pa.types.is_null(column.type):
        return np.full(len(column), np.nan)
    if not pa.types.is_string(column.type):
        return _filled(column.cast(pa.float64()))
    if kind.name == BOOLEAN:
        false = pc.if_else(pc.is_in(column, pa.array(FALSE_TEXTS)), 0.0, _NO_NUMBER)
        return _filled(pc.if_else(pc.is_in(column, pa.array(TRUE_TEXTS)), 1.0, false))
    numbers = _cast_numbers(column)
    if numbers is not None:
        return _filled(numbers)
    number = pc.match_substring_regex(column, _NUMBER)
    cells = pc.if_else(pc.fill_null(number, False), pc.utf8_trim_whitespace(column), pa.scalar(None, pa.string()))
    return _filled(pc.cast(cells, pa.float64()))


def _filled(column: pa.Array) -> np.ndarray:
    """A float64 column as a numpy array, null as NaN."""
    return np.asarray(pc.fill_null(column, np.nan).to_numpy(zero_copy_only=False), dtype=np.float64)


_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def mix(values: np.ndarray) -> np.ndarray:
    """SplitMix64's finalizer of uint64 ``values``: every bit of the input moves every bit."""
    x = values.astype(np.uint64, copy=True)
    x ^= x >> np.uint64(30)
    x *= _M1
    x ^= x >> np.uint64(27)
    x *= _M2
    x ^= x >> np.uint64(31)
    return x


def hash_texts(column: pa.Array) -> np.ndarray:
    """A uint64 hash of each text of ``column`` (no missing cell): the same text, the same hash,
    in any chunk of any table."""
    codes = pc.dictionary_encode(column)
    distinct = np.asarray(codes.dictionary.to_pylist(), dtype=object)
    hashes = pd.util.hash_array(distinct, categorize=False) if len(distinct) else np.zeros(0, np.uint64)
    return hashes[codes.indices.to_numpy(zero_copy_only=False)]


def hash_rows(columns: Sequence[pa.Array], n: int) -> np.ndarray:
    """A uint64 hash of each of ``n`` rows from its text cells in ``columns``, in order; 0 for
    every row when there is no column."""
    out = np.zeros(n, dtype=np.uint64)
    for column in columns:
        out = mix(out * _GOLDEN + hash_texts(column))
    return out

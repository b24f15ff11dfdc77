"""manifest.json: the mark of a directory nlcx wrote, and the checksums every reader verifies.

Every output directory nlcx writes holds a ``manifest.json`` (how, when and where it was made)
and a mark file, ``.nlcx-output``. The manifest names the directory's kind under
:data:`MARKER` (one of :data:`KINDS`) and a random :data:`ID_KEY`; the mark file holds the
same id. A directory is nlcx's (:func:`is_marked`) only when the two agree: a manifest copied
into another directory, or a directory that merely holds files with nlcx's names, is not.

The manifest's ``checksums`` give, for every file of the directory (relative path, ``/``
separated), its SHA-256, its size in bytes and, for a table, its rows (a CSV's lines after the
header; a Parquet file's rows). Readers verify what they read before reading it
(:func:`verify`, :func:`verify_file`): a truncated or altered file is refused with one line
naming it (:class:`IntegrityError`), never read in part.

A manifest is read strictly (:func:`load`): a file that is not JSON, not an object, too large,
or whose known keys hold values of the wrong type is refused in one line naming the key.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import secrets
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from nlcx.errors import NlcxError

__all__ = [
    "ID_KEY",
    "KINDS",
    "MANIFEST",
    "MARK",
    "MARKER",
    "Checksum",
    "IntegrityError",
    "checksum",
    "checksums",
    "is_marked",
    "load",
    "mark",
    "read_mark",
    "unlisted",
    "update",
    "verify",
    "verify_file",
    "write",
]

#: The manifest's file name.
MANIFEST = "manifest.json"
#: The mark file: the directory's half of the id its manifest names.
MARK = ".nlcx-output"
#: The manifest key naming the kind of output directory.
MARKER = "nlcx_output"
#: The manifest key holding the directory's random id (32 hex digits), the same as the mark file's.
ID_KEY = "output_id"
#: The kinds of output directory: the first five are written whole and replaced whole
#: (:mod:`nlcx.rundir`); the others are written in place and resumed.
KINDS = ("run", "sweep", "reproduction", "linearize", "baselines", "identification", "calibration")
#: The largest manifest read (a sweep of many variants lists many part files).
MAX_MANIFEST_BYTES = 64 * 1024 * 1024
#: Bytes read at a time when hashing a file.
_CHUNK = 1 << 20
_ID = re.compile(r"[0-9a-f]{32}")
_SHA256 = re.compile(r"[0-9a-f]{64}")


class IntegrityError(NlcxError):
    """A file of an output directory that cannot be vouched for: names the file, says what is
    wrong with it and what is allowed."""

    def __init__(self, path: Path | str, problem: str, allowed: str = "the file as nlcx wrote it") -> None:
        self.path, self.problem, self.allowed = str(path), problem, allowed
        super().__init__(f"integrity error: {self.path}: {problem}; allowed: {allowed}")

    def __reduce__(self) -> tuple[type, tuple[str, str, str]]:
        return (type(self), (self.path, self.problem, self.allowed))


class Checksum(BaseModel):
    """One file's entry in the manifest's ``checksums``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    sha256: str = Field(pattern=_SHA256.pattern)
    bytes: int = Field(ge=0)
    #: A CSV's lines after its header, a Parquet file's rows; None for any other file.
    rows: int | None = Field(default=None, ge=0)


class _RunRecord(BaseModel):
    """A run's entry in a run directory's ``runs``: the keys readers use, typed."""

    model_config = ConfigDict(extra="allow")

    controller: str
    status: str


class _Manifest(BaseModel):
    """The keys of a manifest that nlcx reads back, typed; any other key is kept as it is."""

    model_config = ConfigDict(extra="allow")

    nlcx_output: str | None = None
    output_id: str | None = None
    checksums: dict[str, Checksum] = Field(default_factory=dict)
    files: list[str] = Field(default_factory=list)
    runs: list[_RunRecord] = Field(default_factory=list)


def new_id() -> str:
    """A fresh random id: 32 hex digits."""
    return secrets.token_hex(16)


def read_mark(directory: Path) -> str | None:
    """The id in ``directory``'s mark file, or None when it has none (or not one nlcx wrote)."""
    path = directory / MARK
    try:
        if path.is_symlink() or not path.is_file() or path.stat().st_size > 1024:
            return None
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    value = record.get(ID_KEY) if isinstance(record, dict) else None
    return value if isinstance(value, str) and _ID.fullmatch(value) else None


def mark(directory: Path, kind: str) -> str:
    """The id of ``directory``'s mark file, written first (a new random id) if it has none."""
    from nlcx.drawing import atomic_write

    found = read_mark(directory)
    if found is not None:
        return found
    identifier = new_id()
    text = json.dumps({MARKER: kind, ID_KEY: identifier}) + "\n"
    atomic_write(directory / MARK, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return identifier


def load(directory: Path, *, where: Path | None = None) -> dict[str, Any]:
    """``directory``'s manifest.json, checked: a JSON object whose known keys have their types.

    Raises
    ------
    IntegrityError
        One line naming the manifest (as ``where``, default its path) when it is missing, too
        large, not JSON, not an object, or holds a known key of the wrong type.
    """
    path = directory / MANIFEST
    shown = where or path
    try:
        size = path.stat().st_size
    except OSError:
        raise IntegrityError(shown, "missing", "an output directory nlcx wrote, with its manifest.json") from None
    if size > MAX_MANIFEST_BYTES:
        raise IntegrityError(shown, f"{size:,} bytes, more than a manifest holds", f"at most {MAX_MANIFEST_BYTES:,}")
    try:
        record = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, ValueError):
        raise IntegrityError(shown, "not valid JSON in UTF-8", "the manifest as nlcx wrote it") from None
    if not isinstance(record, dict):
        raise IntegrityError(shown, "not a JSON object", "the manifest as nlcx wrote it")
    try:
        _Manifest.model_validate(record)
    except ValidationError as exc:
        error = exc.errors()[0]
        key = ".".join(str(part) for part in error["loc"])
        raise IntegrityError(shown, f"{key}: {error['msg'].lower()}", "the manifest as nlcx wrote it") from None
    return record


def is_marked(directory: Path) -> bool:
    """Whether nlcx wrote ``directory``: its manifest names one of :data:`KINDS` and an id that
    its mark file holds too."""
    identifier = read_mark(directory)
    if identifier is None:
        return False
    try:
        record = load(directory)
    except IntegrityError:
        return False
    return record.get(MARKER) in KINDS and record.get(ID_KEY) == identifier


def _rows(path: Path, data_lines: int) -> int | None:
    """A table's rows: a CSV's lines after the header, a Parquet file's rows; None otherwise."""
    if path.suffix == ".csv":
        return max(data_lines - 1, 0)
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        try:
            return int(pq.ParquetFile(path).metadata.num_rows)
        except Exception:  # not a Parquet file: its checksum still stands, it has no rows
            return None
    return None


def checksum(path: Path) -> Checksum:
    """The SHA-256, the size and (a table's) rows of the file at ``path``."""
    digest = hashlib.sha256()
    size = lines = 0
    with open(path, "rb") as stream:
        while chunk := stream.read(_CHUNK):
            digest.update(chunk)
            size += len(chunk)
            lines += chunk.count(b"\n")
    return Checksum(sha256=digest.hexdigest(), bytes=size, rows=_rows(path, lines))


def _files(directory: Path) -> list[Path]:
    """Every regular file under ``directory`` except its manifest and mark, in path order
    (symbolic links are not followed and not listed)."""
    found = []
    for root, dirs, names in os.walk(directory):
        dirs.sort()
        base = Path(root)
        for name in sorted(names):
            path = base / name
            if base == directory and name in (MANIFEST, MARK):
                continue
            if not path.is_symlink() and path.is_file():
                found.append(path)
    return found


def checksums(directory: Path, known: Mapping[str, Checksum] | None = None) -> dict[str, dict[str, object]]:
    """``checksums`` for every file under ``directory`` (:func:`_files`): relative path ->
    SHA-256, bytes and rows. ``known``: entries computed before (by relative path), taken as
    they are; a file hard-linked under two names is hashed once."""
    known = dict(known or {})
    by_inode: dict[tuple[int, int], Checksum] = {}
    out: dict[str, dict[str, object]] = {}
    for path in _files(directory):
        rel = path.relative_to(directory).as_posix()
        stat = path.stat()
        inode = (stat.st_dev, stat.st_ino)
        entry = known.get(rel) or by_inode.get(inode)
        if entry is None or entry.bytes != stat.st_size:
            entry = checksum(path)
        by_inode[inode] = entry
        out[rel] = entry.model_dump()
    return out


def write(
    directory: Path, record: Mapping[str, object], known: Mapping[str, Checksum] | None = None
) -> dict[str, object]:
    """Write ``directory``'s manifest.json: ``record`` (which names its kind under
    :data:`MARKER`), the directory's id (:func:`mark`, written first) and the checksums of
    every file in it (:func:`checksums`). Returns what was written."""
    from nlcx.drawing import atomic_write

    kind = record.get(MARKER)
    if kind not in KINDS:  # pragma: no cover - every writer names its kind
        raise ValueError(f"manifest kind {kind!r} is not one of {KINDS}")
    out = {**record, ID_KEY: mark(directory, str(kind)), "checksums": checksums(directory, known)}
    text = json.dumps(out, indent=2, default=str) + "\n"
    atomic_write(directory / MANIFEST, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return out


def update(directory: Path, changed: Iterable[str] = (), **fields: object) -> dict[str, object]:
    """Add ``fields`` to ``directory``'s manifest and list the files written since (hashed anew:
    those missing from its checksums, and the relative paths ``changed``)."""
    record = load(directory)
    stale = set(changed)
    known = {k: Checksum(**v) for k, v in record.get("checksums", {}).items() if k not in stale}
    return write(directory, {**record, **fields}, known)


def verify(directory: Path, names: Iterable[str] | None = None) -> dict[str, Any]:
    """Check the files ``names`` (relative paths; default every file the manifest lists)
    against ``directory``'s manifest and return the manifest.

    Raises
    ------
    IntegrityError
        The manifest cannot be read (:func:`load`), or a file it lists is missing, or its
        bytes are not those it recorded (truncated or altered); one line naming the file.
    """
    record = load(directory)
    listed: dict[str, dict[str, object]] = record.get("checksums", {})  # validated by load
    for rel in listed if names is None else names:
        _verified(directory / rel, listed.get(rel), directory)
    return record


def _verified(path: Path, entry: Mapping[str, object] | None, directory: Path) -> None:
    """Check one file against its manifest entry (None: the manifest does not list it)."""
    if entry is None:
        raise IntegrityError(path, f"not listed in {directory / MANIFEST}", "a file the manifest lists")
    expected = Checksum(**entry)
    if path.is_symlink() or not path.is_file():
        raise IntegrityError(path, f"missing; {directory / MANIFEST} lists it", "the file as nlcx wrote it")
    size = path.stat().st_size
    if size != expected.bytes:
        problem = f"{size:,} bytes where nlcx wrote {expected.bytes:,} (truncated or altered)"
        raise IntegrityError(path, problem, "the file as nlcx wrote it")
    if checksum(path).sha256 != expected.sha256:
        raise IntegrityError(path, "its SHA-256 is not the one nlcx recorded (altered)", "the file as nlcx wrote it")


def verify_file(path: Path, levels: int = 4) -> bool:
    """Check one file against the manifest of the nearest marked directory above it (at most
    ``levels`` up) that lists it; False when none lists it (nothing to vouch for: a table that
    nlcx did not write, or wrote before it recorded checksums).

    Raises
    ------
    IntegrityError
        The file does not match its entry, or a marked directory's manifest on the way cannot
        be read (:func:`load`)."""
    path = Path(os.path.abspath(path))
    directory = path.parent
    for _ in range(levels):
        if read_mark(directory) is not None:
            listed = load(directory).get("checksums", {})
            rel = path.relative_to(directory).as_posix()
            if rel in listed:
                _verified(path, listed[rel], directory)
                return True
        if directory.parent == directory:
            break
        directory = directory.parent
    return False


def unlisted(directory: Path) -> list[str]:
    """The files under ``directory`` that its manifest does not list (relative paths)."""
    try:
        listed = load(directory).get("checksums", {})
    except IntegrityError:
        listed = {}
    return [rel for path in _files(directory) if (rel := path.relative_to(directory).as_posix()) not in listed]

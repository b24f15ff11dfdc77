"""A sweep's finished batches, sealed: each part's checksums, written last, mark it complete.

A batch writes its part files (its metrics, its index, the time series of its variants),
then ``parts/<part>.sums.json``, the seal: the SHA-256, size and rows of each of those files
(:func:`nlcx.manifest.checksum`), by their paths under the sweep's directory. A part without
a seal is unfinished and is computed again. A resumed sweep checks every sealed part it takes
over against its seal (:func:`verify`): a truncated or altered file is refused in one line
naming it, never read in part. The sweep's manifest takes the sealed checksums as they are
(:func:`known`), so a part is hashed once.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from nlcx import manifest
from nlcx.drawing import atomic_write

__all__ = ["SEAL", "known", "seal", "sealed", "verify", "verify_part"]

#: The suffix of a part's seal, ``parts/<part>.sums.json``.
SEAL = ".sums.json"
#: The largest seal read (a part lists its files: its tables and its variants' time series).
MAX_SEAL_BYTES = 16 * 1024 * 1024


def seal(root: Path, part: str, files: Sequence[Path]) -> None:
    """Write the seal of ``part``: the checksums of ``files`` (under ``root``), by relative path."""
    sums = {path.relative_to(root).as_posix(): manifest.checksum(path).model_dump() for path in files}
    text = json.dumps({"part": part, "files": sums}, indent=1) + "\n"
    atomic_write(root / "parts" / f"{part}{SEAL}", lambda tmp: tmp.write_text(text, encoding="utf-8"))


def sealed(root: Path) -> list[str]:
    """The names of the sealed parts under ``root``, in name order."""
    return sorted(path.name.removesuffix(SEAL) for path in (root / "parts").glob(f"*{SEAL}"))


def _read(root: Path, part: str) -> dict[str, manifest.Checksum]:
    """A part's seal, checked: the checksums it lists, by relative path."""
    path = root / "parts" / f"{part}{SEAL}"
    try:
        if path.stat().st_size > MAX_SEAL_BYTES:
            raise ValueError
        record = json.loads(path.read_bytes().decode("utf-8"))
        return {str(rel): manifest.Checksum(**entry) for rel, entry in record["files"].items()}
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        raise manifest.IntegrityError(
            path,
            "not a seal nlcx wrote (unreadable, truncated or altered)",
            "the file as nlcx wrote it; --force computes every variant again",
        ) from None


def verify(root: Path) -> list[str]:
    """Check every sealed part under ``root`` against its seal; the sealed parts' names.

    Raises
    ------
    nlcx.manifest.IntegrityError
        A seal that cannot be read, or a file it lists that is missing, truncated or altered.
    """
    parts = sealed(root)
    for part in parts:
        verify_part(root, part)
    return parts


def verify_part(root: Path, part: str) -> None:
    """Check the files of one sealed part under ``root`` against its seal (see :func:`verify`)."""
    for rel, expected in _read(root, part).items():
        path = root / rel
        if path.is_symlink() or not path.is_file() or manifest.checksum(path) != expected:
            raise manifest.IntegrityError(
                path, f"missing, truncated or altered since its batch sealed it in parts/{part}{SEAL}",
                "the file as nlcx wrote it; --force computes every variant again",
            )  # fmt: skip


def known(root: Path) -> dict[str, manifest.Checksum]:
    """The checksums the seals under ``root`` hold (relative path -> checksum), seals included."""
    out: dict[str, manifest.Checksum] = {}
    for part in sealed(root):
        out.update(_read(root, part))
    return out

"""Keep numba's disk cache consistent with the package's source.

numba's ``cache=True`` keys each compiled function on its own module's source file only. A
function that calls another module's compiled function directly (the PID calls the built-in
gain schedules, the integrator calls the friction physics) keeps its cached machine code,
with the *old* callee inlined, after only the callee's module changed. nlcx therefore
stamps the cache with a hash of every source file of the package; when the stamp differs,
the package's cache files (``*.nbi``, ``*.nbc`` in its ``__pycache__`` folders) are removed
before anything is compiled or loaded, and numba rebuilds them.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
STAMP = PACKAGE / "__pycache__" / "numba-source.sha256"


def source_digest(root: Path = PACKAGE) -> str:
    """SHA-256 over the relative path and bytes of every ``.py`` file of the package."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_files(root: Path = PACKAGE) -> list[Path]:
    """numba's index and data files in the package's ``__pycache__`` folders."""
    return [p for pattern in ("*.nbi", "*.nbc") for p in root.rglob(f"__pycache__/{pattern}")]


def ensure_consistent(root: Path = PACKAGE, stamp: Path | None = None) -> bool:
    """Remove the package's numba cache if the source changed since it was stamped; True if
    it was removed. A read-only install (no writable ``__pycache__``) is left alone."""
    stamp = stamp or root / "__pycache__" / STAMP.name
    current = source_digest(root)
    try:
        if stamp.is_file() and stamp.read_text(encoding="ascii").strip() == current:
            return False
        for path in cache_files(root):
            path.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(current + "\n", encoding="ascii")
        tmp.replace(stamp)
    except OSError:
        return False
    return True

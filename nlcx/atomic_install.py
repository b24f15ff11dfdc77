"""Directories put in place whole: made beside their target, then renamed to its name.

An output is written into a new directory beside its target (in the same parent, so on the
same file system): ``.<name>.nlcx-tmp-<random>`` (:func:`new_stage`). Only when it is complete
is it renamed to the target's name (:func:`install`). On Linux the new and the old directory
exchange their names in one step (``renameat2`` with ``RENAME_EXCHANGE``, see rename(2)), so
the target's name always holds a complete directory. Elsewhere, or where the file system
cannot exchange names, the old directory is renamed aside (``.<name>.nlcx-old-<random>``) and
the new one renamed in: between those two consecutive renames no directory bears the target's
name. Then the old directory is deleted. The temporary and set-aside directories a killed
writer left are recognised by their names and removed (:func:`remove_leftovers`).

Which targets may be replaced, and the lock that makes one process at a time their writer,
are :mod:`nlcx.rundir`'s.
"""

from __future__ import annotations

import ctypes
import errno
import functools
import os
import secrets
import shutil
import sys
from collections.abc import Callable
from pathlib import Path

_TMP, _OLD = ".nlcx-tmp-", ".nlcx-old-"
#: Hex digits of the random part of a temporary or set-aside directory's name.
_RANDOM_HEX = 8
_AT_FDCWD = -100  # <fcntl.h>: a path relative to the working directory
_RENAME_EXCHANGE = 2  # <linux/fs.h>: renameat2 swaps the two names


def real_path(target: Path) -> Path:
    """``target`` absolute, symbolic links resolved: the directory that is renamed and replaced."""
    return Path(os.path.realpath(target))


def _new_sibling(target: Path, suffix: str) -> Path:
    """A name beside ``target`` that no entry has: ``.<name><suffix><8 random hex digits>``."""
    real = real_path(target)
    while True:
        candidate = real.parent / f".{real.name}{suffix}{secrets.token_hex(_RANDOM_HEX // 2)}"
        if not os.path.lexists(candidate):
            return candidate


def new_stage(target: Path) -> Path:
    """A new, empty directory beside ``target`` (its parent made if missing) to write its output
    into: ``.<name>.nlcx-tmp-<8 random hex digits>``, renamed into place by :func:`install`."""
    real = real_path(target)
    real.parent.mkdir(parents=True, exist_ok=True)
    stage = _new_sibling(target, _TMP)
    stage.mkdir()
    return stage


@functools.cache
def _renameat2() -> Callable[..., int] | None:
    """The C library's ``renameat2``, where there is one (Linux, glibc 2.28 and later)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        function = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


def _exchange(first: Path, second: Path) -> bool:
    """Swap the names of two existing directories in one step; False where the system or the
    file system cannot (then nothing was renamed)."""
    renameat2 = _renameat2()
    if renameat2 is None:
        return False
    if renameat2(_AT_FDCWD, os.fsencode(first), _AT_FDCWD, os.fsencode(second), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(first), None, str(second))


def install(complete: Path, target: Path) -> None:
    """Rename the directory ``complete`` to ``target``, replacing the directory ``target`` holds
    (whose replacement :func:`nlcx.rundir.claim` allowed), then delete the old one. ``complete``
    must be beside ``target``."""
    real = real_path(target)
    if not os.path.lexists(real):
        os.rename(complete, real)
        return
    if _exchange(complete, real):
        shutil.rmtree(complete, ignore_errors=True)  # it names the old directory now
        return
    aside = _new_sibling(target, _OLD)
    os.rename(real, aside)
    try:
        os.rename(complete, real)
    except BaseException:
        os.rename(aside, real)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def _ours(name: str, target: Path) -> bool:
    """Whether ``name`` is a temporary or set-aside directory of ``target`` (random part included,
    so ``.a.nlcx-tmp-b.nlcx-tmp-<random>``, target ``a.nlcx-tmp-b``'s, is not target ``a``'s)."""
    real = real_path(target)
    for suffix in (_TMP, _OLD):
        prefix = f".{real.name}{suffix}"
        rest = name[len(prefix) :]
        if name.startswith(prefix) and len(rest) == _RANDOM_HEX and all(c in "0123456789abcdef" for c in rest):
            return True
    return False


def remove_leftovers(target: Path) -> None:
    """Delete the temporary and set-aside directories a killed writer of ``target`` left beside
    it. Only under ``target``'s lock (:func:`nlcx.rundir.claim`): then none of them is being
    written."""
    parent = real_path(target).parent
    if not parent.is_dir():
        return
    for entry in parent.iterdir():
        if _ours(entry.name, target) and entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)


def link_or_copy(source: Path, destination: Path) -> None:
    """``source`` at ``destination`` too: a hard link (the files of a finished sweep are never
    rewritten in place: :func:`nlcx.drawing.atomic_write` replaces a file by renaming), or a
    copy where the file system has no hard links."""
    destination.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(source, destination)
    except OSError:
        shutil.copy2(source, destination)

"""Output directories written whole: staged beside their target, locked, renamed into place.

A run, a sweep or a reproduction is written into a directory beside its target (in the same
parent, so on the same file system): ``.<name>.nlcx-tmp-<random>`` (:func:`staged`). Only when
every file is there, report included, is it renamed to the target's name. If the target
already is an nlcx output directory, the new directory replaces it whole: nothing of the old
one survives beside the new one. An interrupted write (an exception, Ctrl-C) removes its
temporary directory and leaves the old target as it was. An existing directory that nlcx did
not write is never replaced, whatever it holds: only a directory that carries nlcx's mark
(:func:`written_by_nlcx`: its manifest and its mark file name the same random id,
:mod:`nlcx.manifest`) and holds no file its manifest does not list is. The working directory,
the directories above it, the home directory and the root are refused as targets, whatever
they hold.

Replacing (:func:`nlcx.atomic_install.install`): on Linux the new and the old directory
exchange their names in one step, so the target's name always holds a complete directory;
elsewhere the old directory is renamed aside and the new one renamed in. Then the old
directory is deleted.

Sweeps are the exception to "an interrupted write leaves nothing": their finished batches
(``parts/``, and the time series of each variant) are kept in a staging directory with a
stable name, ``.<name>.nlcx-partial`` (:func:`open_partial`), which a rerun finds and resumes
from; the sweep's own files are written beside them and the whole is renamed into place.

One process at a time writes a target (:func:`locked`): the lock is an advisory file lock
(:mod:`filelock`) on ``.<name>.nlcx-lock`` beside the target, which the operating system
releases if the process dies; the file itself stays (removing it would let two processes lock
two different files of one name). ``.<name>.nlcx-owner`` records the holder's process id and
start time, for the refusal a second process prints. The leftovers of a killed writer
(temporary and set-aside directories) are removed by the next writer of the same target,
which holds the lock and so knows that nobody is writing them. The lock is taken only once
the target has been accepted (:func:`claim` checks it first), so a refused target leaves no
file behind; the check is made again under the lock.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import time
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import TYPE_CHECKING

from nlcx import manifest
from nlcx.atomic_install import install, new_stage, real_path, remove_leftovers
from nlcx.errors import NlcxError
from nlcx.pages.writing import ReportError, write_pages

if TYPE_CHECKING:
    from nlcx.drawing import Painter
    from nlcx.engine.results import ExperimentResult

#: The kinds of output directory nlcx writes whole, as its manifest names them under :data:`MARKER`.
KINDS = ("run", "sweep", "reproduction", "linearize", "baselines")
#: The manifest.json key that marks a directory nlcx wrote; its value is one of :data:`manifest.KINDS`.
MARKER = manifest.MARKER
#: What an output directory may be.
ALLOWED = "a new or empty directory, or one nlcx wrote"
_PARTIAL, _LOCK, _OWNER = ".nlcx-partial", ".nlcx-lock", ".nlcx-owner"

#: Lock files this process holds (:func:`locked`), with the process id that took each one: a
#: forked worker inherits the table but not the right to release.
_held: dict[Path, int] = {}


class OutputError(NlcxError):
    """An output directory that cannot be written: names the option and the directory, says
    why, and what is allowed."""

    def __init__(self, target: Path, problem: str, allowed: str, key: str = "--out") -> None:
        self.target, self.problem, self.allowed, self.key = target, problem, allowed, key
        super().__init__(f"output error: {key} = '{target}': {problem}; allowed: {allowed}")

    def __reduce__(self) -> tuple[type, tuple[Path, str, str, str]]:
        return (type(self), (self.target, self.problem, self.allowed, self.key))


def _beside(target: Path, suffix: str) -> Path:
    real = real_path(target)
    return real.parent / f".{real.name}{suffix}"


def lock_path(target: Path) -> Path:
    """The lock file of ``target``: ``.<name>.nlcx-lock`` beside it."""
    return _beside(target, _LOCK)


def owner_path(target: Path) -> Path:
    """Who holds ``target``'s lock: ``.<name>.nlcx-owner`` beside it (JSON: pid, since, host)."""
    return _beside(target, _OWNER)


def partial_dir(target: Path) -> Path:
    """The staging directory of a sweep into ``target``: ``.<name>.nlcx-partial`` beside it."""
    return _beside(target, _PARTIAL)


def written_by_nlcx(directory: Path) -> bool:
    """Whether ``directory`` carries nlcx's mark: its manifest.json names one of
    :data:`nlcx.manifest.KINDS` under :data:`MARKER` and the random id its mark file holds
    (:func:`nlcx.manifest.is_marked`). File names prove nothing: a directory that merely holds
    a sweep.csv or a manifest.json is not nlcx's."""
    return manifest.is_marked(directory)


def _protected(target: Path) -> str | None:
    """Why ``target`` can never be an output directory (it is the working directory or above
    it, the home directory or the root), or None."""
    real = real_path(target)
    if real == Path(real.anchor):
        return "the root of the file system"
    if real == real_path(Path.home()):
        return "the home directory"
    cwd = real_path(Path.cwd())
    if real == cwd or real in cwd.parents:
        return "the working directory" if real == cwd else "a directory above the working directory"
    return None


def check_target(target: Path, key: str = "--out") -> None:
    """Refuse (:class:`OutputError`, naming ``key``) a ``target`` that nlcx may not write or
    replace: the working directory, a directory above it, the home directory or the root; an
    existing entry that is not a directory; a directory that is not empty and does not carry
    nlcx's mark (:func:`written_by_nlcx`), whatever it holds; a marked directory holding files
    its manifest does not list (someone else's, put there since)."""
    why = _protected(target)
    if why is not None:
        raise OutputError(target, f"is {why}, which nlcx never writes into", ALLOWED, key)
    if not os.path.lexists(target):
        return
    if not target.is_dir():
        raise OutputError(target, "exists and is not a directory", ALLOWED, key)
    if not any(target.iterdir()):
        return
    _readable_manifest(target)
    if not written_by_nlcx(target):
        raise OutputError(target, UNMARKED, ALLOWED, key)
    foreign = manifest.unlisted(target)
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise OutputError(
            target, f"holds files nlcx did not write ({foreign[0]}{more}); move them out first", ALLOWED, key
        )


def _readable_manifest(directory: Path) -> None:
    """A directory with nlcx's mark file whose manifest cannot be read is refused naming the
    manifest (:class:`nlcx.manifest.IntegrityError`), not as a directory nlcx did not write."""
    if manifest.read_mark(directory) is not None:
        manifest.load(directory)


#: Why a directory that is not empty and carries no mark is refused.
UNMARKED = "exists, is not empty and carries no nlcx mark (an output of an nlcx without the mark: remove it by hand)"


def lock_owner(target: Path) -> dict[str, object] | None:
    """The record of the process holding ``target``'s lock (pid, since, host), if readable."""
    try:
        record = json.loads(owner_path(target).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


def _write_owner(target: Path) -> None:
    """Record this process as the holder of ``target``'s lock (written whole, then renamed)."""
    from nlcx.drawing import atomic_write
    from nlcx.report import utc_iso

    record = {"pid": os.getpid(), "since": utc_iso(time.time()), "host": socket.gethostname()}
    text = json.dumps(record) + "\n"
    atomic_write(owner_path(target), lambda tmp: tmp.write_text(text, encoding="utf-8"))


def _busy(target: Path, key: str) -> OutputError:
    """The refusal of a target whose lock another process holds."""
    owner = lock_owner(target) or {}
    holder = f"pid {owner.get('pid', 'unknown')}, since {owner.get('since', 'unknown')}"
    allowed = "wait for it to finish" + (", or choose another --out" if key == "--out" else "")
    return OutputError(target, f"being written by another nlcx process ({holder})", allowed, key)


@contextmanager
def locked(target: Path, key: str = "--out") -> Iterator[None]:
    """Hold the lock of ``target`` for the block; refuse at once (:class:`OutputError`, naming
    ``key``) while another process holds it. Within a process the lock nests: a block inside
    another one's lock of the same target goes on under it."""
    from filelock import FileLock, Timeout

    path = lock_path(target)
    if _held.get(path) == os.getpid():
        yield
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    lock = FileLock(path)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise _busy(target, key) from None
    _held[path] = os.getpid()
    try:
        _write_owner(target)
        yield
    finally:
        del _held[path]
        with suppress(FileNotFoundError):
            owner_path(target).unlink()
        lock.release()


@contextmanager
def claim(target: Path) -> Iterator[None]:
    """Make ``target`` this process's to write: check that it may be replaced
    (:func:`check_target`), hold its lock (:func:`locked`), check again under the lock and
    clear a killed writer's leftovers. Take it before the work that fills it, so a refusal
    comes before that work, not after; a refused target leaves no file behind."""
    check_target(target)
    with locked(target):
        check_target(target)
        remove_leftovers(target)
        yield


@contextmanager
def claim_in_place(target: Path, kind: str, key: str = "--out") -> Iterator[None]:
    """Make ``target`` this process's to write into and resume in place (an identification or
    a calibration): refused as :func:`check_target` refuses, locked; a new or empty directory
    gets its mark and a first manifest (kind ``kind``). When the work ends, finished or stopped
    part-way by an error or Ctrl-C, the manifest lists every file then in ``target`` (hashed
    anew), so a rerun resumes from what this process wrote instead of refusing it."""
    check_target(target, key)
    with locked(target, key):
        check_target(target, key)
        if not written_by_nlcx(target):
            target.mkdir(parents=True, exist_ok=True)
            manifest.write(target, {"name": target.name, MARKER: kind})
        try:
            yield
        except BaseException:
            with suppress(manifest.IntegrityError, OSError):
                _list_written(target)
            raise
        _list_written(target)


def _list_written(target: Path) -> None:
    """``target``'s manifest listing every file in it, each hashed anew."""
    manifest.write(target, manifest.load(target))  # no checksum known: every file hashed anew


def check_marked(directory: Path, key: str = "DIR") -> None:
    """Refuse (:class:`OutputError`) a ``directory`` nlcx did not write, before anything is
    written into it (``nlcx report``)."""
    if directory.is_dir():
        _readable_manifest(directory)
    if not directory.is_dir() or not written_by_nlcx(directory):
        raise OutputError(directory, "is not an output directory nlcx wrote (it carries no nlcx mark)",
                          "a run, sweep or reproduction directory nlcx wrote", key)  # fmt: skip


@contextmanager
def staged(target: Path) -> Iterator[Path]:
    """A new, empty directory beside ``target`` to write its output into
    (:func:`nlcx.atomic_install.new_stage`), renamed into place
    (:func:`nlcx.atomic_install.install`) when the block completes; removed, ``target``
    untouched, when the block raises or is interrupted. ``target`` is claimed (:func:`claim`)
    for the block."""
    with claim(target):
        stage = new_stage(target)
        try:
            yield stage
            install(stage, target)
        except BaseException:
            shutil.rmtree(stage, ignore_errors=True)
            raise


def open_partial(target: Path, keep: Collection[str], fresh: bool = False) -> Path:
    """The staging directory of a sweep into ``target`` (:func:`partial_dir`), created if missing,
    holding only its entries named in ``keep`` (the resumable results; the files an
    interrupted write of the rest left are removed), or, ``fresh``, nothing. Only under
    ``target``'s claim (:func:`claim`)."""
    partial = partial_dir(target)
    if fresh:
        shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True, exist_ok=True)
    for entry in partial.iterdir():
        if entry.name in keep:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()
    return partial


def save_run(
    result: ExperimentResult,
    out_dir: Path,
    *,
    with_report: bool = True,
    overrides: Sequence[str] = (),
    timings: Mapping[str, float] | None = None,
    painter: Painter | None = None,
    started: float | None = None,
) -> Path:
    """Write the run directory of ``result`` as ``nlcx run`` does (it calls this): staged, under
    the lock of ``out_dir``, the files of :func:`nlcx.report.write_run` (results and manifest
    first) and, ``with_report``, report.html and report.md
    (:func:`nlcx.pages.writing.write_pages`), then renamed into place (:func:`staged`).

    Parameters
    ----------
    result
        The experiment's result (:func:`nlcx.engine.run_experiment`).
    out_dir
        The run directory: new, empty, or one nlcx wrote (replaced whole).
    with_report
        Write report.html and report.md (:func:`nlcx.pages.render.write_report`).
    overrides
        The overrides the experiment was built with, as given; recorded in the manifest.
    timings
        Seconds of each phase for the manifest; default ``result.timings``.
    painter
        A figure painter process (:class:`nlcx.drawing.Painter`); default: draw in a thread.
    started
        The ``time.perf_counter()`` instant the run began; default: now less the seconds of
        ``timings``.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    ReportError
        The report failed: the results are in ``out_dir`` all the same, and its manifest
        records the failure.
    """
    from nlcx import report

    phases = dict(result.timings if timings is None else timings)
    begun = time.perf_counter() - sum(phases.values()) if started is None else started
    failure = None
    with staged(out_dir) as stage:
        report.write_run(result, stage, phases, started=begun, painter=painter, overrides=overrides)
        if with_report:
            failure = write_pages(stage)
    if failure is not None:
        raise ReportError(out_dir, failure)
    return out_dir

"""YAML read within limits: no file, alias or nesting can exhaust the machine.

Every YAML file nlcx reads (a config and the files it ``extends``, a spec, a cluster file, a
run directory's config.yaml) and every override's value goes through :func:`load_file` or
:func:`load_text`. Before anything is built, one pass over the parser's events checks:

- the size: at most :data:`MAX_BYTES`;
- the text: strict UTF-8 (a byte-order mark is allowed), no lone surrogate in any string
  (a ``"\\ud800"`` escape), which no output file could hold;
- the nodes after alias expansion: at most :data:`MAX_NODES` (a "billion laughs" file of a
  few hundred bytes names a million nodes through nested aliases);
- the nesting: at most :data:`MAX_DEPTH` levels, aliases expanded; no alias inside the value it
  refers to (a value that holds itself).

Each refusal is one :class:`~nlcx.errors.ConfigError` line naming the file. The values are
then built by ``yaml.SafeLoader``, so the numbers are the ones the configs were written for.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import yaml

from nlcx.errors import ConfigError, did_you_mean

__all__ = ["MAX_BYTES", "MAX_DEPTH", "MAX_NODES", "load_file", "load_text", "surrogate_free"]

#: The largest YAML file read, in bytes.
MAX_BYTES = 5 * 1024 * 1024
#: The most nodes (mappings, sequences, scalars) a document may name, aliases expanded.
MAX_NODES = 100_000
#: The deepest nesting of mappings and sequences, aliases expanded.
MAX_DEPTH = 64

_EventParser = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's parser where PyYAML has it


def load_file(path: str | os.PathLike[str]) -> object:
    """The YAML document of the file at ``path``, read within the limits of this module.

    Raises
    ------
    ConfigError
        One line naming the file: missing, too large, not UTF-8, not valid YAML, or beyond a
        limit (nodes, nesting, a lone surrogate).
    """
    path = Path(path)
    source = str(path)
    try:
        size = path.stat().st_size
        if not path.is_file():
            raise IsADirectoryError
    except OSError:
        raise not_found(path) from None
    if size > MAX_BYTES:
        raise ConfigError("", source, f"{size:,} bytes; allowed: a YAML file of at most {MAX_BYTES:,} bytes")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError("", source, f"cannot be read ({exc.strerror or 'input/output error'})") from None
    return load_text(_decoded(data, source), source)


def not_found(path: Path) -> ConfigError:
    """``config file not found``, the closest file name of its directory suggested as a path
    written like ``path``."""
    try:
        names = [p.name for p in path.parent.iterdir() if p.is_file()] if path.parent.is_dir() else []
    except OSError:
        names = []
    hint = did_you_mean(path.name, names, lambda name: str(path.with_name(name)))
    return ConfigError("", str(path), f"config file not found{hint}")


def _decoded(data: bytes, source: str) -> str:
    """``data`` as UTF-8 text, strictly, a leading byte-order mark dropped."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError("", source, f"not UTF-8 text (byte {data[exc.start]:#04x} at offset {exc.start})") from None
    return text.removeprefix("\ufeff")


def load_text(text: str, source: str, key: str = "") -> object:
    """The YAML document of ``text`` from ``source`` (named in errors), within the limits.

    ``key``: the config key ``text`` is the value of (an override's value); an error then
    names the key and the text instead of the source."""
    try:
        if not surrogate_free(text):  # e.g. a byte that is not UTF-8, as the shell hands it over
            raise _RefusedError("holds a lone surrogate (text that is not UTF-8); allowed: text that is valid Unicode")
        if len(text) > MAX_BYTES:
            raise _RefusedError(f"{len(text):,} characters; allowed: at most {MAX_BYTES:,}")
        try:
            _check_events(yaml.parse(text, Loader=_EventParser))
        except yaml.YAMLError:  # PyYAML's own parser says why in the words of its loader (or checks)
            _check_events(yaml.parse(text, Loader=yaml.SafeLoader))
        return yaml.load(text, Loader=yaml.SafeLoader)
    except _RefusedError as exc:
        problem = str(exc)
    except yaml.YAMLError as exc:
        problem = f"not valid YAML{'' if key else _where(exc)}: {_problem(exc, redact=not key)}"
    raise ConfigError(key, text if key else source, problem) from None


class _RefusedError(Exception):
    """A document beyond a limit of this module: the problem, as the error line states it."""


def _where(exc: yaml.YAMLError) -> str:
    mark = getattr(exc, "problem_mark", None)
    return f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""


def _problem(exc: yaml.YAMLError, redact: bool) -> str:
    """PyYAML's description of the problem; ``redact``: without the quoted text of the file it
    may echo (a file that did not parse may not be a config at all)."""
    if isinstance(exc, yaml.MarkedYAMLError):
        problem = str(exc.problem or "cannot be parsed")
    else:  # a reader's error (a character YAML does not allow) has no problem: its first line
        problem = str(exc).partition("\n")[0] or "cannot be parsed"
    parts = problem.split("'")
    return "'...'".join(parts[::2]) if redact and len(parts) > 2 else problem


@dataclass
class _Open:
    """A collection whose end the walk of :func:`_check_events` has not reached yet."""

    #: Its nodes so far.
    nodes: int
    anchor: str | None
    #: The deepest nesting below it so far.
    below: int


def _check_events(events: Iterable[yaml.Event]) -> None:
    """Walk the parser's events once: nesting, nodes after alias expansion, lone surrogates."""
    open_sizes: list[_Open] = []  # per open collection
    anchors: dict[str, tuple[int, int]] = {}  # anchor -> (nodes, nesting)
    nodes = 0
    for event in events:
        if isinstance(event, yaml.CollectionStartEvent):
            nodes += 1
            open_sizes.append(_Open(1, event.anchor, 0))
            if len(open_sizes) > MAX_DEPTH:
                raise _RefusedError(f"nested deeper than {MAX_DEPTH} levels; allowed: at most {MAX_DEPTH}")
        elif isinstance(event, yaml.CollectionEndEvent):
            closed = open_sizes.pop()
            size, anchor, below = closed.nodes, closed.anchor, closed.below
            if anchor is not None:
                anchors[anchor] = (size, below + 1)
            _add(open_sizes, size, below + 1)
        elif isinstance(event, yaml.ScalarEvent):
            nodes += 1
            if not surrogate_free(event.value):
                raise _RefusedError("holds a lone surrogate (e.g. \\ud800); allowed: text that is valid Unicode")
            if event.anchor is not None:
                anchors[event.anchor] = (1, 0)
            _add(open_sizes, 1, 0)
        elif isinstance(event, yaml.AliasEvent):
            if any(entry.anchor == event.anchor for entry in open_sizes):
                raise _RefusedError(f"the alias *{event.anchor} refers to a value that holds it; allowed: aliases "
                                    "of values defined before them")  # fmt: skip
            size, depth = anchors.get(str(event.anchor), (1, 0))
            nodes += size
            if len(open_sizes) + depth > MAX_DEPTH:
                raise _RefusedError(f"nested deeper than {MAX_DEPTH} levels through aliases; allowed: {MAX_DEPTH}")
            _add(open_sizes, size, depth)
        if nodes > MAX_NODES:
            raise _RefusedError(f"more than {MAX_NODES:,} values (aliases expanded); allowed: at most {MAX_NODES:,}")


def _add(open_sizes: list[_Open], size: int, depth: int) -> None:
    """Count a finished node of ``size`` nodes and ``depth`` levels into the collection holding it."""
    if open_sizes:
        open_sizes[-1].nodes += size
        open_sizes[-1].below = max(open_sizes[-1].below, depth)


def surrogate_free(text: str) -> bool:
    """Whether ``text`` holds no lone surrogate (it encodes as UTF-8)."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True

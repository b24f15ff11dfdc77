"""Plugins the command line finds: the Python files and modules a config's ``imports:`` names.

A plant written with :func:`nlcx.plant` or a controller written with :func:`nlcx.controller`
registers itself when its module runs. A config makes such plugins known to every command
(``nlcx run``, ``sweep``, ``validate``, ``linearize``) by naming them::

    imports: [my_plants.py, mypkg.controllers]     # a file relative to the config, or a module

:func:`load` imports each before the config is validated, once per process and file content
(a file whose content changed is imported again, so a notebook sees an edited plugin), and
returns what was imported: the name as written, the file's path and its SHA-256, which the
manifest records (``imports``). ``--plugins FILE`` does the same for one command.

Code runs only from a config the user names (on the command line, or to :func:`nlcx.run` and
:func:`nlcx.sweep`): reading a run directory (:func:`nlcx.load_run`, ``nlcx report``,
``nlcx diff``) never imports anything.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypeVar

from nlcx.errors import ConfigError

T = TypeVar("T")

__all__ = ["IMPORTS", "SUFFIX", "load", "load_config_imports", "loaded", "resolved"]

#: The config key that names plugin files and modules.
IMPORTS = "imports"
#: How a plugin file ends; anything else is a module name.
SUFFIX = ".py"
_MODULE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*")
#: What this process imported: a file's resolved path -> (its SHA-256, the module's name).
_FILES: dict[Path, tuple[str, str]] = {}
#: Every plugin file and module this process imported (name, path, SHA-256), in order, once each.
_LOADED: dict[str, dict[str, str]] = {}


def resolved(entries: object, base: Path, key: str = IMPORTS) -> list[str]:
    """``entries`` (a config file's ``imports``) with each file made absolute against ``base``,
    the config file's directory; a module name as it is. One line for anything else."""
    if entries is None:
        return []
    if isinstance(entries, str):
        entries = [entries]
    if not isinstance(entries, list):
        raise ConfigError(key, entries, "a list of plugin files (my_plants.py, relative to the config) or modules")
    out = []
    for i, entry in enumerate(entries):
        if not isinstance(entry, str) or not entry.strip():
            raise ConfigError(f"{key}.{i}", entry, "a plugin file (ending in .py) or an importable module name")
        if entry.endswith(SUFFIX):
            out.append(str((base / entry).resolve()))
        elif _MODULE.fullmatch(entry):
            out.append(entry)
        else:
            raise ConfigError(f"{key}.{i}", entry, "a plugin file (ending in .py) or an importable module name")
    return out


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _import_file(path: Path, key: str) -> dict[str, str]:
    """Run the plugin file at ``path`` as a module of its own (again only if its content changed)."""
    if not path.is_file():
        raise ConfigError(key, str(path), "a plugin file that exists (relative to the config file)")
    digest = _digest(path)
    known = _FILES.get(path)
    if known is not None and known[0] == digest:
        return {"name": str(path), "path": str(path), "sha256": digest}
    module_name = f"nlcx_plugin_{hashlib.sha256(str(path).encode()).hexdigest()[:12]}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:  # pragma: no cover - a .py file always has a loader
        raise ConfigError(key, str(path), "a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    loader = spec.loader
    _run(lambda: loader.exec_module(module), key, str(path))
    _FILES[path] = (digest, module_name)
    return {"name": str(path), "path": str(path), "sha256": digest}


def _import_module(name: str, key: str) -> dict[str, str]:
    """Import the module ``name``; its file and that file's SHA-256, where it has one."""
    module = _run(lambda: importlib.import_module(name), key, name)
    file = getattr(module, "__file__", None)
    record = {"name": name, "path": str(file) if file else "", "sha256": ""}
    if file and Path(file).is_file():
        record["sha256"] = _digest(Path(file))
    return record


def _run(action: Callable[[], T], key: str, what: str) -> T:
    """``action()``, a failure of the plugin's own code as one line naming it: a config error
    it raised as it is, anything else by the plugin's first line of complaint."""
    try:
        return action()
    except ConfigError:
        raise
    except ModuleNotFoundError as exc:
        raise ConfigError(key, what, f"cannot be imported: no module named {exc.name!r}") from None
    except Exception as exc:
        lines = str(exc).strip().splitlines()
        raise ConfigError(key, what, f"failed as it was imported: {lines[0] if lines else 'an error'}") from None


def load(entries: Sequence[str], key: str = IMPORTS) -> list[dict[str, str]]:
    """Import the plugin files and modules ``entries`` (as :func:`resolved` leaves them), in
    order; what was imported, for the manifest (name, path, SHA-256)."""
    records = []
    for i, entry in enumerate(entries):
        where = f"{key}.{i}"
        record = _import_file(Path(entry), where) if entry.endswith(SUFFIX) else _import_module(entry, where)
        _LOADED[record["name"]] = record
        records.append(record)
    return records


def loaded() -> list[dict[str, str]]:
    """Every plugin file and module this process imported (name, path, SHA-256; a file
    imported again after a change, with its new SHA-256): what a manifest records as ``imports``."""
    return [dict(record) for record in _LOADED.values()]


def load_config_imports(raw: dict[str, object], base: Path | None = None) -> dict[str, object]:
    """Import what a raw config's ``imports`` names (files relative to ``base``, default the
    working directory, where a file is not absolute yet) before it is validated; the config
    with those entries made absolute."""
    entries = resolved(raw.get(IMPORTS), base or Path.cwd())
    load(entries)
    return {**raw, IMPORTS: entries} if IMPORTS in raw else raw

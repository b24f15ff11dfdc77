"""Reading config files: YAML parsed by PyYAML, and the files named by ``extends`` merged under them.

YAML is parsed by :mod:`nlcx.safe_yaml` (``yaml.SafeLoader`` within limits of size, nodes,
nesting and text; its numbers are the ones the configs were written for)
and the files named by ``extends:`` are merged under the file's own keys by :func:`deep_merge`.
The merge is written out here rather than done by ``OmegaConf.merge`` because of its one rule
OmegaConf has no place for: a plugin section whose ``kind`` changes is replaced whole, not
merged key by key. Merging the plain mappings also costs a small fraction of converting each
file to OmegaConf's containers and back.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from pathlib import Path
from typing import cast

from nlcx import safe_yaml
from nlcx.errors import ConfigError
from nlcx.plugins import IMPORTS, resolved


def deep_merge(base: dict[str, object], top: Mapping[str, object]) -> dict[str, object]:
    """``top`` over ``base``: mappings merge key by key, anything else replaces.

    A plugin section whose ``kind`` changes (e.g. a step reference replaced by a sine) is
    replaced whole, since the two kinds have different keys.
    """
    out = copy.deepcopy(base)
    for key, value in top.items():
        old = out.get(key)
        changes_kind = (
            isinstance(old, dict) and isinstance(value, dict) and value.get("kind", old.get("kind")) != old.get("kind")
        )
        if isinstance(value, dict) and isinstance(old, dict) and not changes_kind:
            out[key] = deep_merge(old, value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def read_config(path: str | Path, _seen: tuple[Path, ...] = ()) -> dict[str, object]:
    """Read a config file, first merging the files its ``extends`` key names.

    ``extends`` is a YAML file (``.yaml`` or ``.yml``) or a list of them, relative to the file;
    they are merged in order and the file's own keys go on top (see :func:`deep_merge`).
    ``imports`` (plugin files and modules, :mod:`nlcx.plugins`) is made absolute against each
    file's directory and gathered along the chain, the extended files' first; nothing is
    imported here.
    """
    given = Path(path)
    path = given.resolve()
    if not _seen and not path.is_file():
        raise safe_yaml.not_found(given)
    if path in _seen:
        raise ConfigError("extends", str(path), "circular extends")
    data = read_yaml(path)
    own_imports = resolved(data.pop(IMPORTS, None), path.parent, key=IMPORTS)
    parents = data.pop("extends", [])
    if isinstance(parents, str):
        parents = [parents]
    if not isinstance(parents, list) or not all(isinstance(p, str) for p in parents):
        raise ConfigError("extends", parents, "must be a file path or a list of file paths")
    for parent in parents:
        if Path(parent).suffix.lower() not in YAML_SUFFIXES:
            raise ConfigError("extends", parent, f"a YAML file ({' or '.join(YAML_SUFFIXES)}) relative to {path.name}")
    merged: dict[str, object] = {}
    for parent in parents:
        merged = deep_merge(merged, read_config(path.parent / parent, (*_seen, path)))
    inherited = cast(list[str], merged.pop(IMPORTS, []))  # as read_config puts them: resolved entries
    imports = list(dict.fromkeys([*inherited, *own_imports]))
    out = deep_merge(merged, data)
    return {IMPORTS: imports, **out} if imports else out


#: The suffixes of a file ``extends`` may name.
YAML_SUFFIXES = (".yaml", ".yml")


def read_yaml(path: str | Path) -> dict[str, object]:
    """Parse a YAML file within the limits of :mod:`nlcx.safe_yaml`; it must hold a mapping.
    No error quotes the file's content: a file that is not a config may be anything."""
    path = Path(path)
    data = safe_yaml.load_file(path)
    if not isinstance(data, dict):
        raise ConfigError("", str(path), "a config file must hold a mapping of sections")
    return data

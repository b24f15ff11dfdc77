"""Overrides in Hydra's grammar, and setting values at dotted key paths.

``key=value`` sets a key (new or not), ``+key=value`` adds a key that must not exist yet,
``++key=value`` adds or sets, ``~key`` deletes a key that must exist and ``~key=value``
deletes it only when it holds that value. Keys are dotted paths; values are parsed as YAML.
:func:`set_values` sets (key path, value) pairs copying only the mappings on the paths, which
is how a sweep's variants are made from their base.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Literal

from nlcx import safe_yaml
from nlcx.errors import MISSING, ConfigError

#: What an override may look like (Hydra's override grammar).
OVERRIDE_FORMS = (
    "an override must look like section.key=value (set), +section.key=value (add a new key), "
    "++section.key=value (add or set), ~section.key or ~section.key=value (delete)"
)


@dataclass(frozen=True)
class Override:
    """One override in Hydra's grammar (see :func:`parse_override`)."""

    #: ``set`` (key=value), ``add`` (+key=value), ``force`` (++key=value) or ``delete`` (~key).
    action: Literal["set", "add", "force", "delete"]
    #: The dotted key, split at its dots.
    key: tuple[str, ...]
    #: The value parsed as YAML; for a delete, the value the key must hold (MISSING: any value).
    value: Any
    #: The override as written.
    text: str

    @property
    def dotted(self) -> str:
        """The key as written, ``section.key``."""
        return ".".join(self.key)


_PREFIXES: tuple[tuple[str, Literal["set", "add", "force", "delete"]], ...] = (
    ("++", "force"),
    ("+", "add"),
    ("~", "delete"),
)


def parse_override(text: str) -> Override:
    """Parse one override in Hydra's grammar.

    Parameters
    ----------
    text
        ``key=value``, ``+key=value``, ``++key=value``, ``~key`` or ``~key=value``; the key is a
        dotted path (``simulation.t_end``), the value is parsed as YAML (empty: null).

    Returns
    -------
    Override
        The action, the key split at its dots and the parsed value.

    Raises
    ------
    ConfigError
        The override has none of these forms, or its value is not valid YAML.
    """
    body = text.lstrip()
    action: Literal["set", "add", "force", "delete"] = "set"
    for prefix, name in _PREFIXES:
        if body.startswith(prefix):
            action, body = name, body[len(prefix) :]
            break
    key, sep, value = body.partition("=")
    key = key.strip()
    parts = tuple(key.split("."))
    if (not sep and action != "delete") or not key or key[0] in "+~" or not all(parts):
        raise ConfigError("", text, OVERRIDE_FORMS)
    if not sep:
        return Override(action, parts, MISSING, text)
    parsed = safe_yaml.load_text(value, "override", key=key) if value.strip() else None
    return Override(action, parts, parsed, text)


def apply_overrides(raw: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """A deep copy of ``raw`` with each override (Hydra's grammar, :func:`parse_override`) applied in order.

    ``key=value`` and ``++key=value`` set the key whether it exists or not (creating the
    mappings above it); ``+key=value`` adds a key and is an error where it exists;
    ``~key`` deletes a key and is an error where it does not exist; ``~key=value`` also
    requires the key to hold that value.
    """
    data = copy.deepcopy(raw)
    for text in overrides:
        data = _apply(data, parse_override(text))
    return data


def _apply(data: dict[str, Any], override: Override) -> dict[str, Any]:
    """``data`` with one override applied (the mappings on the key's path copied)."""
    if override.action in ("set", "force"):
        return set_values(data, [(list(override.key), override.value)])
    found, current = _find(data, override.key)
    if override.action == "add":
        if found:
            raise ConfigError(
                override.dotted,
                current,
                "already set; +key=value adds a new key only (key=value or ++key=value sets it)",
            )
        return set_values(data, [(list(override.key), override.value)])
    if not found:
        raise ConfigError(override.dotted, MISSING, "not in the config, so ~key cannot delete it")
    if override.value is not MISSING and not _same(current, override.value):
        raise ConfigError(
            override.dotted, current, f"{override.text.strip()} deletes it only where its value is {override.value!r}"
        )
    return _without(data, override.key)


def _find(data: dict[str, Any], key: tuple[str, ...]) -> tuple[bool, Any]:
    """(whether ``key`` is in ``data``, its value or None)."""
    node: Any = data
    for part in key:
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _same(current: Any, value: Any) -> bool:
    """Equal values, where a boolean equals only a boolean (``True == 1`` in Python)."""
    return isinstance(current, bool) == isinstance(value, bool) and current == value


def _without(data: dict[str, Any], key: tuple[str, ...]) -> dict[str, Any]:
    """A copy of ``data`` without the (existing) ``key``; only the mappings on its path are copied."""
    out = dict(data)
    node = out
    for part in key[:-1]:
        node[part] = dict(node[part])
        node = node[part]
    del node[key[-1]]
    return out


def set_values(raw: dict[str, Any], values: list[tuple[list[str], Any]]) -> dict[str, Any]:
    """A copy of ``raw`` with each (key path, value) set; only the mappings on the paths are
    copied, the rest is shared with ``raw`` (treat both as read-only afterwards)."""
    data = dict(raw)
    for parts, value in values:
        node = data
        for i, part in enumerate(parts[:-1]):
            child = node.get(part)
            if child is None:
                child = {}
            if not isinstance(child, dict):
                raise ConfigError(".".join(parts[: i + 1]), child, "is not a mapping, so it has no sub-keys")
            child = node[part] = dict(child)
            node = child
        node[parts[-1]] = copy.deepcopy(value)
    return data

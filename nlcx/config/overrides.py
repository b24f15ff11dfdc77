"""Overrides in Hydra's grammar, and setting values at dotted key paths.

``key=value`` sets a key (new or not), ``+key=value`` adds a key that must not exist yet,
``++key=value`` adds or sets, ``~key`` deletes a key that must exist and ``~key=value``
deletes it only when it holds that value. Keys are dotted paths; values are parsed as YAML.
:func:`set_values` sets (key path, value) pairs copying only the mappings on the paths, which
is how a sweep's variants are made from their base.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, cast

from nlcx import safe_yaml
from nlcx.errors import MISSING, ConfigError, did_you_mean

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
    value: object
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


def apply_overrides(raw: dict[str, object], overrides: list[str]) -> dict[str, Any]:
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


#: Sections of labelled plugin sections: a plain ``key=value`` under a label they lack, other
#: than the label's ``kind``, is a typo of a label (a new one starts with its kind, or with ``+``).
LABELLED = {"controllers": "controller", "reference": "reference"}


def _check_label(data: dict[str, object], override: Override) -> None:
    """Refuse ``section.label.key=value`` where ``section`` (:data:`LABELLED`) has no ``label``
    and ``key`` is not ``kind``: one line naming the labels, the closest one suggested."""
    section, key = override.key[0], override.key
    if section not in LABELLED or len(key) < 3 or key[2] == "kind":
        return
    section_data = data.get(section)
    labels = [str(k) for k in section_data] if isinstance(section_data, dict) else []
    if key[1] in labels:
        return
    what = LABELLED[section]
    raise ConfigError(
        override.dotted,
        override.value,
        f"no {what} {key[1]!r}{did_you_mean(key[1], labels)}; allowed: {', '.join(labels) or '(none)'}, or a new "
        f"{what} started with {section}.{key[1]}.kind=KIND (or +{override.dotted}=...)",
    )


def _apply(data: dict[str, object], override: Override) -> dict[str, object]:
    """``data`` with one override applied (the mappings on the key's path copied)."""
    if override.action == "set":
        _check_label(data, override)
    if override.action in ("set", "force"):
        return set_values(data, [(list(override.key), override.value)], schema_default)
    found, current = _find(data, override.key)
    if override.action == "add":
        if found:
            raise ConfigError(
                override.dotted,
                current,
                "already set; +key=value adds a new key only (key=value or ++key=value sets it)",
            )
        return set_values(data, [(list(override.key), override.value)], schema_default)
    if not found:
        raise ConfigError(override.dotted, MISSING, "not in the config, so ~key cannot delete it")
    if override.value is not MISSING and not _same(current, override.value):
        raise ConfigError(
            override.dotted, current, f"{override.text.strip()} deletes it only where its value is {override.value!r}"
        )
    return _without(data, override.key)


def _find(data: dict[str, object], key: tuple[str, ...]) -> tuple[bool, object]:
    """(whether ``key`` is in ``data``, its value or None)."""
    node: object = data
    for part in key:
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _same(current: object, value: object) -> bool:
    """Equal values, where a boolean equals only a boolean (``True == 1`` in Python)."""
    return isinstance(current, bool) == isinstance(value, bool) and current == value


def _without(data: dict[str, object], key: tuple[str, ...]) -> dict[str, object]:
    """A copy of ``data`` without the (existing) ``key``; only the mappings on its path are copied."""
    out = dict(data)
    node = out
    for part in key[:-1]:
        # the key exists (_find), so every value on its path is a mapping
        child = dict(cast(dict[str, object], node[part]))
        node[part] = child
        node = child
    del node[key[-1]]
    return out


def set_values(
    raw: Mapping[str, object],
    values: Sequence[tuple[list[str], object]],
    defaults: Callable[[list[str]], list[object] | None] | None = None,
) -> dict[str, object]:
    """A copy of ``raw`` with each (key path, value) set; only the mappings and lists on the
    paths are copied, the rest is shared with ``raw`` (treat both as read-only afterwards).

    A part of a path that is a number indexes a list, as in OmegaConf's grammar
    (``metrics.rise_limits.0``): the element must exist. A list the config does not hold is
    taken from ``defaults`` (the key path -> the schema's default list, or None).
    """
    data = dict(raw)
    for parts, value in values:
        node: dict[str, object] | list[object] = data
        for i in range(len(parts) - 1):
            child = _child(node, parts, i)
            if child is None and parts[i + 1].isdigit() and defaults is not None:
                child = defaults(parts[: i + 1])
            if child is None:
                child = {}
            if isinstance(child, list | tuple):
                child = list(child)
            elif not isinstance(child, dict):
                raise ConfigError(".".join(parts[: i + 1]), child, "is not a mapping, so it has no sub-keys")
            else:
                child = dict(child)
            _put(node, parts, i, child)
            node = child
        _put(node, parts, len(parts) - 1, copy.deepcopy(value))
    return data


def _index(node: list[object], parts: list[str], i: int) -> int:
    """The list index ``parts[i]`` names in ``node``; a one-line error where it is none."""
    part, where = parts[i], ".".join(parts[: i + 1])
    if not part.isdigit():
        raise ConfigError(where, part, f"{'.'.join(parts[:i])} is a list: its elements are 0 to {len(node) - 1}")
    index = int(part)
    if index >= len(node):
        raise ConfigError(
            where,
            index,
            f"index {index} is out of range: {'.'.join(parts[:i])} has {len(node)} element(s), "
            f"allowed: 0 to {len(node) - 1}",
        )
    return index


def _child(node: dict[str, object] | list[object], parts: list[str], i: int) -> object:
    """What ``node`` holds at ``parts[i]`` (None where a mapping lacks it)."""
    if isinstance(node, list):
        return node[_index(node, parts, i)]
    return node.get(parts[i])


def _put(node: dict[str, object] | list[object], parts: list[str], i: int, value: object) -> None:
    """Set ``parts[i]`` of ``node`` (a list's element, which must exist, or a mapping's key)."""
    if isinstance(node, list):
        node[_index(node, parts, i)] = value
    else:
        node[parts[i]] = value


def schema_default(parts: list[str]) -> list[object] | None:
    """The default list of the section field at ``parts`` (e.g. ``metrics.rise_limits``), or None."""
    from pydantic import BaseModel

    from nlcx.config.sections import ExperimentSection

    model: object = ExperimentSection
    default: object = None
    for part in parts:
        field = model.model_fields.get(part) if isinstance(model, type) and issubclass(model, BaseModel) else None
        if field is None:
            return None
        default = field.get_default(call_default_factory=True)
        model = type(default)
    return list(default) if isinstance(default, list | tuple) else None

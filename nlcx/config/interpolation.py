"""Interpolation of ``${...}`` references by OmegaConf's rules, and a config interpolated once for many variants.

``"${a.b}"`` is replaced by a copy of that key's value (a number, a mapping, a list),
``"gain_${a.b}"`` by a string, and references nest and chain; then the free ``vars`` section
is dropped. The reference that takes a whole value and names an absolute key
(``"${vars.gains}"``, the only kind the configs use) is resolved by a short walk here, to the
same result; OmegaConf resolves every other kind, and reports every failure (a missing key, a
circular reference). The walk exists for speed: a sweep interpolates its base once per batch
of variants (:class:`Interpolated`), and a variant that sets a referenced key (one of
``vars``, say) is interpolated in full, so this step runs thousands of times where converting
to and from OmegaConf's containers would cost more than building the variant does.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, cast

from nlcx.config.overrides import set_values
from nlcx.errors import MISSING, ConfigError

if TYPE_CHECKING:
    from omegaconf.errors import OmegaConfBaseException


#: A key part that OmegaConf's interpolation grammar and a plain mapping lookup read alike.
_KEY = r"[A-Za-z_][A-Za-z0-9_\-]*"
#: A reference to an absolute dotted key, ``${a.b.c}``.
_REFERENCE = re.compile(rf"\$\{{({_KEY}(?:\.{_KEY})*)\}}")
#: OmegaConf's marker of a missing value; a reference to it is an error.
_MISSING_VALUE = "???"


class _NotDirectError(Exception):
    """The direct walk of :func:`interpolate` stops: OmegaConf resolves the config (or reports its error)."""


def interpolate(raw: dict[str, object], *, allow_env: bool = False) -> dict[str, object]:
    """Resolve every ``${...}`` reference by OmegaConf's rules, then drop ``vars``.

    ``"${dotted.key}"`` is replaced by a copy of that key's value, ``"x_${a}"`` by a string,
    and references chain and nest. ``vars`` is a free section for named values that other
    keys refer to, e.g. the conventional gains shared by the x and y loops of the thesis's
    pendulums. Of OmegaConf's resolvers only those that read the config itself
    (:data:`CONFIG_RESOLVERS`) are on; ``allow_env`` turns on every resolver OmegaConf knows,
    ``oc.env`` (which reads the process's environment) included.

    Raises
    ------
    ConfigError
        One line naming the key that holds the failing reference: it refers to a key that does
        not exist, is part of a circular reference, is not a valid interpolation, or calls a
        resolver that is off.
    """
    try:
        out = _resolved_directly(raw)
    except _NotDirectError:
        if not allow_env:
            check_resolvers(raw)
        out = _resolved_by_omegaconf(raw)
    out.pop("vars", None)
    return out


#: The resolvers on without ``allow_env``: they read nothing but the config's own keys.
CONFIG_RESOLVERS = frozenset({"oc.select", "oc.dict.keys", "oc.dict.values"})


def check_resolvers(node: object, path: tuple[str, ...] = ()) -> None:
    """Refuse (:class:`ConfigError`, naming the key) a string anywhere in ``node`` that calls a
    resolver outside :data:`CONFIG_RESOLVERS`: ``oc.env`` reads the process's environment,
    ``oc.decode`` and ``oc.create`` parse text outside the limits of :mod:`nlcx.safe_yaml`, and
    a resolver registered by other code may read anything. Nothing of the process reaches a
    config, and so an output, unless the user allows it (``--allow-env``)."""
    if isinstance(node, dict):
        for key, value in node.items():
            check_resolvers(value, (*path, str(key)))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            check_resolvers(value, (*path, str(i)))
    elif isinstance(node, str) and "${" in node:
        off = sorted(name for name in _resolvers_called(node) if name not in CONFIG_RESOLVERS)
        if off:
            raise ConfigError(
                ".".join(path), node, f"calls the resolver {off[0]}, which is off: a config reads only its own "
                f"values (references and {', '.join(sorted(CONFIG_RESOLVERS))}); --allow-env turns every resolver "
                "on, oc.env included",
            )  # fmt: skip


class _ParseNode(Protocol):
    """A node of the tree OmegaConf's grammar parses (a rule's context or a terminal)."""

    def getChild(self, i: int) -> _ParseNode: ...


def _resolvers_called(text: str) -> list[str]:
    """The names of the resolvers ``text`` calls, as OmegaConf's grammar parses it (a name built
    by an interpolation appears as its text, ``${...}``, and is never one that is on); none
    where it does not parse (OmegaConf then reports it)."""
    from omegaconf import grammar_parser
    from omegaconf.errors import GrammarParseError
    from omegaconf.grammar.gen.OmegaConfGrammarParser import OmegaConfGrammarParser

    try:
        tree = grammar_parser.parse(text)
    except GrammarParseError:
        return []
    names: list[str] = []
    stack: list[_ParseNode] = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, OmegaConfGrammarParser.InterpolationResolverContext):
            names.append(node.resolverName().getText())
        stack.extend(node.getChild(i) for i in range(getattr(node, "getChildCount", lambda: 0)()))
    return names


def _resolved_directly(raw: dict[str, object]) -> dict[str, object]:
    """``raw`` with each whole-value reference to an absolute key (``"${a.b}"``) replaced by its
    resolved value, as OmegaConf resolves it; :class:`_NotDirectError` for any other reference
    and for any reference that does not resolve (OmegaConf then resolves it or reports it)."""

    def lookup(path: str, trail: tuple[str, ...]) -> object:
        if path in trail:
            raise _NotDirectError
        node: object = raw
        for part in path.split("."):
            if not isinstance(node, dict) or part not in node:
                raise _NotDirectError
            node = node[part]
        if isinstance(node, str) and node == _MISSING_VALUE:
            raise _NotDirectError
        return resolve(node, (*trail, path))

    def resolve(node: object, trail: tuple[str, ...]) -> object:
        if isinstance(node, dict):
            return {k: resolve(v, trail) for k, v in node.items()}
        if isinstance(node, list):
            return [resolve(v, trail) for v in node]
        if isinstance(node, str) and "${" in node:
            match = _REFERENCE.fullmatch(node)
            if match is None:
                raise _NotDirectError
            return lookup(match.group(1), trail)
        return node

    return {k: resolve(v, ()) for k, v in raw.items()}


def _resolved_by_omegaconf(raw: dict[str, object]) -> dict[str, object]:
    """``raw`` resolved by ``OmegaConf.to_container(..., resolve=True)``: plain mappings and lists
    again, every other value (PyYAML's numbers included) as it was."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        resolved = OmegaConf.to_container(OmegaConf.create(raw, flags={"allow_objects": True}), resolve=True)
    except OmegaConfBaseException as exc:
        raise _interpolation_error(raw, exc) from None
    return cast(dict[str, object], resolved)


def _interpolation_error(raw: dict[str, object], exc: OmegaConfBaseException) -> ConfigError:
    """OmegaConf's error as one line: the key holding the reference, its value and the problem."""
    where = getattr(exc, "full_key", None) or ""
    parts = [index or key for index, key in re.findall(r"\[(\d+)\]|([^.\[\]]+)", where)]
    value = _raw_value(raw, parts)
    lines = str(getattr(exc, "msg", None) or exc).splitlines()
    problem = lines[0] if lines else type(exc).__name__
    if missing := re.fullmatch(r"Interpolation key '(.*)' not found", problem):
        return ConfigError(".".join(parts), value, f"refers to {missing.group(1)}, a key that does not exist")
    if problem in ("Recursive interpolation detected", "Interpolation to parent node detected"):
        return ConfigError(".".join(parts), value, "circular reference: the value refers back to itself")
    return ConfigError(".".join(parts), value, f"cannot be interpolated: {problem}")


def _raw_value(raw: dict[str, object], parts: list[str]) -> object:
    """The value at a key path whose list indices are digits, or MISSING."""
    node: object = raw
    for part in parts:
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return MISSING
    return node


def _reference_targets(node: object) -> set[tuple[str, ...]]:
    """The key paths that the ``${...}`` references anywhere in ``node`` refer to; the empty path
    (every key) for a reference whose target is not an absolute dotted key (a relative or
    nested reference, a resolver)."""
    if isinstance(node, dict):
        return set().union(*(_reference_targets(v) for v in node.values()))
    if isinstance(node, list):
        return set().union(*(_reference_targets(v) for v in node))
    if isinstance(node, str) and "${" in node:
        targets = {tuple(path.split(".")) for path in _REFERENCE.findall(node)}
        return targets | {()} if "${" in _REFERENCE.sub("", node) else targets
    return set()


@dataclass(frozen=True)
class Interpolated:
    """A raw config interpolated once, for the many configs that set a few values on it (a
    sweep's variants): :meth:`resolve` gives exactly ``interpolate(set_values(raw, values))``,
    without interpolating the whole config again when no value can change what a reference
    resolves to."""

    raw: dict[str, object]
    resolved: dict[str, object]
    targets: frozenset[tuple[str, ...]]

    allow_env: bool = False

    @classmethod
    def of(cls, raw: dict[str, object], *, allow_env: bool = False) -> Interpolated:
        return cls(raw, interpolate(raw, allow_env=allow_env), frozenset(_reference_targets(raw)), allow_env)

    def resolve(self, values: Sequence[tuple[list[str], object]]) -> dict[str, object]:
        """``interpolate(set_values(raw, values))``: the values set on the interpolated config
        when each is independent of interpolation (:meth:`_independent`), else the full path.
        Both share unchanged parts with ``raw`` or ``resolved`` (treat them as read-only)."""
        if all(self._independent(parts, value) for parts, value in values):
            return set_values(self.resolved, values)
        return interpolate(set_values(self.raw, values), allow_env=self.allow_env)

    def _independent(self, parts: list[str], value: object) -> bool:
        """Whether setting ``value`` at ``parts`` commutes with interpolation: the value holds
        no reference; no reference points at, into or above the key (one whose target is not
        an absolute dotted key, a relative or nested reference, points above every key); the
        key is not in ``vars`` (which interpolation drops); and the raw config holds a mapping
        (or nothing) at every key above it, as :func:`set_values` requires (else the full path
        reports it)."""
        key = tuple(parts)
        if key[0] == "vars" or _reference_targets(value):
            return False
        if any(target[: len(key)] == key or key[: len(target)] == target for target in self.targets):
            return False
        node = self.raw
        for part in key[:-1]:
            child = node.get(part)
            if child is None:
                return True
            if not isinstance(child, dict):
                return False
            node = child
        return True

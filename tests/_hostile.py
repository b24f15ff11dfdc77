"""Shared helpers of the hostile-input suites (``test_fuzz.py``, ``test_corruption.py``).

- :func:`one_line`: the check every refusal must pass (an exit status, exactly one line on
  stderr, no Python exception name, no traceback, nothing a terminal would obey).
- :func:`from_model_schema`: a Hypothesis strategy for the values a pydantic model's JSON
  schema describes. Objects, ``$ref``, ``anyOf`` and ``prefixItems`` are assembled here;
  every other schema (numbers, strings, enums, constants, arrays of those) is drawn by
  :func:`hypothesis_jsonschema.from_schema`.
- :func:`hostile_values`, :func:`mutated`, :func:`overrides`: wrong types, extreme numbers,
  hostile strings and deep nesting, placed anywhere in a config or written as overrides.
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml
from hypothesis import strategies as st
from hypothesis_jsonschema import from_schema

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "x_error_ags.yaml"
#: The environment variable the suites set; its value must reach no output.
SECRET_VARIABLE = "NLCX_FUZZ_SECRET"
SECRET = "nlcx-fuzz-secret-7f3a9c1e"
#: A Python exception's name, or a traceback, as no message to a user may show them.
EXCEPTION_NAME = re.compile(r"\b[A-Z][A-Za-z]*(Error|Exception)\b|Traceback")
#: Characters a terminal obeys instead of showing (:mod:`nlcx.terminal`): C0 controls but tab and
#: line feed, DEL, C1 controls, bidirectional overrides and isolates, lone surrogates.
TERMINAL_UNSAFE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\ud800-\udfff]")


def one_line(result: Any, codes: Sequence[int] = (2,)) -> str:
    """The single stderr line of a refused command: its exit status is one of ``codes``, no
    exception escaped the command, stderr holds exactly one line, which names no Python
    exception and holds no character a terminal would obey."""
    assert result.exit_code in codes, (result.exit_code, result.output)
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert not EXCEPTION_NAME.search(lines[0]), lines[0]
    assert not TERMINAL_UNSAFE.search(lines[0]), lines[0]
    return lines[0]


def files_under(directory: Path) -> Iterator[Path]:
    """Every regular file under ``directory`` (hidden ones included)."""
    return (path for path in sorted(directory.rglob("*")) if path.is_file() and not path.is_symlink())


# ------------------------------------------------------------------ strategies from a model's JSON schema

#: Any JSON value, small.
JSON_VALUES: st.SearchStrategy[Any] = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=6,
)
_ANNOTATIONS = ("title", "description", "default", "unit", "examples")


def from_model_schema(schema: Mapping[str, Any], keys: st.SearchStrategy[str] | None = None) -> st.SearchStrategy[Any]:
    """The values ``schema`` (a pydantic model's ``model_json_schema()``) describes.

    Parameters
    ----------
    schema
        A JSON schema whose ``$ref`` point into its own ``$defs``.
    keys
        The names drawn for an object's ``additionalProperties`` (default: short text).
    """
    definitions: Mapping[str, Any] = schema.get("$defs", {})
    names = keys if keys is not None else st.text(max_size=8)

    def build(node: Mapping[str, Any]) -> st.SearchStrategy[Any]:
        if "$ref" in node:
            target = definitions[node["$ref"].rsplit("/", 1)[-1]]
            return st.deferred(lambda: build(target))
        for combinator in ("anyOf", "oneOf"):
            if combinator in node:
                return st.one_of([build(option) for option in node[combinator]])
        if "allOf" in node and len(node["allOf"]) == 1:
            return build({**{k: v for k, v in node.items() if k != "allOf"}, **node["allOf"][0]})
        if node.get("type") == "object" or "properties" in node:
            return build_object(node)
        if node.get("type") == "array" and "prefixItems" in node:
            return st.tuples(*(build(item) for item in node["prefixItems"])).map(list)
        if node.get("type") == "array" and isinstance(node.get("items"), Mapping):
            return st.lists(build(node["items"]), min_size=node.get("minItems", 0), max_size=4)
        leaf = {k: v for k, v in node.items() if k not in _ANNOTATIONS}
        return from_schema(leaf) if leaf else JSON_VALUES

    def build_object(node: Mapping[str, Any]) -> st.SearchStrategy[Any]:
        properties: Mapping[str, Any] = node.get("properties", {})
        required = set(node.get("required", ()))
        fixed = st.fixed_dictionaries(
            {k: build(v) for k, v in properties.items() if k in required},
            optional={k: build(v) for k, v in properties.items() if k not in required},
        )
        extra = node.get("additionalProperties", not properties)
        if extra is False:
            return fixed
        values = build(extra) if isinstance(extra, Mapping) else JSON_VALUES
        least = node.get("minProperties", 0)
        more = st.dictionaries(names, values, min_size=least, max_size=max(least, 3))
        return st.builds(lambda a, b: {**b, **a}, fixed, more)

    return build(schema)


# ------------------------------------------------------------------ hostile values

#: Numbers at and past every edge: the largest and smallest floats, zero of both signs,
#: negatives, integers past 64 bits and past a float's range, not-a-number and infinities
#: (written to YAML as ``.nan``, ``.inf``, ``-.inf``), booleans where numbers are expected.
EXTREME_NUMBERS: list[Any] = [
    1e308, -1e308, 1.7976931348623157e308, 1e-308, -1e-308, 5e-324, 0, 0.0, -0.0, -1, -1.0, -1e-9,
    2**31, 2**63, 2**64 + 1, -(2**63) - 1, 10**30, 10**400, -(10**400),
    math.nan, math.inf, -math.inf, True, False,
]  # fmt: skip
#: Values of the wrong type for (almost) any key.
WRONG_TYPES: list[Any] = [None, [], {}, [1, 2], {"a": 1}, "text", "1.0", "", [None], {"kind": None}, [[[]]]]
#: ``${...}`` references: resolvers that read the process (off unless ``--allow-env``), resolvers
#: that parse or build text, references to the config's own keys, missing keys, and broken ones.
RESOLVERS: list[str] = [
    f"${{oc.env:{SECRET_VARIABLE}}}", f"${{oc.env:{SECRET_VARIABLE},none}}", "${oc.env:HOME}", "${oc.env:PATH,x}",
    f"x-${{oc.env:{SECRET_VARIABLE}}}-y", f"${{oc.decode:'${{oc.env:{SECRET_VARIABLE}}}'}}", "${oc.decode:'{a: 1}'}",
    "${oc.create:{a: 1}}", "${oc.deprecated:name}", "${oc.select:name}", "${oc.select:nope,fallback}",
    "${oc.dict.keys:plant}", "${oc.dict.values:plant.params}", "${name}", "${title}", "${plant.params.M}",
    "${simulation}", "${missing.key}", "${..}", "${}", "${", "}", "${now:%Y}", "${hydra:runtime.cwd}",
    "${env:HOME}", f"\\${{oc.env:{SECRET_VARIABLE}}}", f"${{${{oc.env:{SECRET_VARIABLE}}}}}", "${a:${b:${c}}}",
]  # fmt: skip
#: Strings that hold what a terminal obeys, what YAML cannot hold, what a path escapes through.
HOSTILE_STRINGS: list[str] = [
    "", " ", "\x00", "a\x00b", "\x1b[31mred\x1b[0m", "\x1b]0;owned\x07", "\x1b[2J", "\u202etxt.exe", "\x9b31m",
    "\r", "\r\n", "line\nbreak", "\t", "\x7f", "\x0c", "\ufeff", "\ud800", "\udfff", "a\ud83db", "\U0010ffff",
    "../..", "../../etc/passwd", "/", "/etc/passwd", "a/b", "a\\b", ".", "..", "~", "~root", "-rf", "--out",
    "nan", ".nan", ".inf", "-.inf", "1e999", "true", "null", "~", "&a", "*a", "!!python/object:os.system",
    "%TAG", "'", '"', "{", "[", ": x", "- x", "#", "<<", "=", "x=y", "key.with.dots", "CON", "NUL", "aux.yaml",
    "x" * 10_000, "é" * 4_000, "\U0001f600" * 1_000,
]  # fmt: skip
#: One string past the 5 MB limit of every YAML text nlcx reads.
HUGE_STRING = "x" * (5 * 1024 * 1024 + 16)
_SURROGATES = st.characters(min_codepoint=0xD800, max_codepoint=0xDFFF)
#: Any character: printable ones, the controls a terminal obeys, lone surrogates.
_ANY_CHARACTER = st.one_of(
    st.characters(),
    _SURROGATES,
    st.sampled_from(["\x00", "\x07", "\x1b", "\x7f", "\x9b", "\u202e", "\n", "\r", "\t", "\ufeff"]),
)


def hostile_strings(huge: bool = False) -> st.SearchStrategy[str]:
    """Hostile strings: :data:`HOSTILE_STRINGS`, :data:`RESOLVERS`, any text (control characters,
    lone surrogates included) and, ``huge``, :data:`HUGE_STRING`."""
    options = [
        st.sampled_from(HOSTILE_STRINGS),
        st.sampled_from(RESOLVERS),
        st.text(_ANY_CHARACTER, max_size=12),
        st.tuples(st.text(max_size=4), _SURROGATES, st.text(max_size=4)).map("".join),
    ]
    if huge:
        options.append(st.just(HUGE_STRING))
    return st.one_of(options)


def nested(value: Any, depth: int, as_list: bool) -> Any:
    """``value`` inside ``depth`` levels of lists (``as_list``) or single-key mappings."""
    for level in range(depth):
        value = [value] if as_list else {f"k{level}": value}
    return value


def hostile_values() -> st.SearchStrategy[Any]:
    """A value that a config key should refuse, or at least survive: an extreme number, a wrong
    type, a hostile string, or one of those nested 2 to 200 levels deep (past the 64 levels the
    YAML reader allows)."""
    flat = st.one_of(st.sampled_from(EXTREME_NUMBERS), st.sampled_from(WRONG_TYPES), hostile_strings())
    deep = st.builds(nested, flat, st.sampled_from([2, 10, 63, 64, 65, 200]), st.booleans())
    return st.one_of(flat, flat, deep)


#: Keys no section knows, and keys that a reader might treat specially.
HOSTILE_KEYS: list[Any] = [
    "unknown", "extends", "vars", "defaults", "hydra", "_target_", "__class__", "<<", "", " ", "\x00", "\x1b[31m",
    "\ud800", "a.b", "a/b", "..", "${oc.env:HOME}", 0, -1, 1.5, None, True,
]  # fmt: skip


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """The path (keys and list indexes) of every node under ``node``, ``node`` itself first."""
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, (*prefix, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from _paths(value, (*prefix, index))


def _at(node: Any, path: tuple[Any, ...]) -> Any:
    for step in path:
        node = node[step]
    return node


@st.composite
def mutated(draw: Callable[..., Any], raw: dict[str, Any], most: int = 3) -> dict[str, Any]:
    """``raw`` after 1 to ``most`` mutations, each at a node drawn anywhere in it: replaced by a
    hostile value (:func:`hostile_values`), given an unknown key (:data:`HOSTILE_KEYS` or any
    text) holding one, or deleted."""
    config = copy.deepcopy(raw)
    for _ in range(draw(st.integers(1, most))):
        path = draw(st.sampled_from(list(_paths(config))))
        action = draw(st.sampled_from(["replace", "replace", "add", "delete"]))
        node = _at(config, path)
        if action == "add" and isinstance(node, dict):
            key = draw(st.sampled_from(HOSTILE_KEYS) | st.text(_ANY_CHARACTER, max_size=6))
            node[key] = draw(hostile_values())
        elif action == "delete" and path:
            parent = _at(config, path[:-1])
            del parent[path[-1]]
        elif path:
            _at(config, path[:-1])[path[-1]] = draw(hostile_values())
        else:  # the whole config replaced
            return draw(st.one_of(st.sampled_from(WRONG_TYPES), st.sampled_from(EXTREME_NUMBERS), hostile_strings()))
    return config


def yaml_text(value: Any, allow_unicode: bool = True, flow: bool = False) -> str:
    """``value`` as YAML text, as PyYAML writes it: NaN and infinities as ``.nan``, ``.inf``;
    control characters, NUL and lone surrogates as double-quoted escapes (``"\\x1b"``,
    ``"\\0"``, ``"\\uD800"``); ``flow``: on one line, without the document end marker."""
    text = yaml.safe_dump(
        value, allow_unicode=allow_unicode, sort_keys=False, default_flow_style=flow or None, width=math.inf
    )
    if flow:
        text = text.removesuffix("\n").removesuffix("\n...").strip()
    return text


#: Edits of a config's YAML text that the structured mutations cannot make: tags PyYAML's safe
#: loader refuses, aliases (a recursive one included), merge keys, a second document, duplicate
#: keys, a byte-order mark, CRLF line ends, tabs, raw control bytes, bytes that are not UTF-8,
#: a title of 1 MB, a file past the 5 MB limit, a file cut in half.
TEXT_EDITS: dict[str, Callable[[str], str | bytes]] = {
    "none": lambda text: text,
    "python-tag": lambda text: text + "pwn: !!python/object/apply:os.system ['true']\n",
    "binary-tag": lambda text: text + "title: !!binary aGVsbG8=\n",
    "timestamp": lambda text: text + "title: 2001-12-14t21:59:43.10-05:00\n",
    "anchors": lambda text: "x-anchor: &a {M: 2.0}\n" + text + "extra: *a\n",
    "recursive-alias": lambda text: text + "loop: &b [*b]\n",
    "merge-key": lambda text: "base: &m {t_end: 1.0}\n" + text.replace("simulation:", "simulation:\n  <<: *m\n ", 1),
    "second-document": lambda text: text + "---\nname: other\n",
    "duplicate-key": lambda text: text + "name: duplicate\n",
    "bom": lambda text: "\ufeff" + text,
    "crlf": lambda text: text.replace("\n", "\r\n"),
    "tab-indent": lambda text: text.replace("  ", "\t", 1),
    "raw-nul": lambda text: text.replace(":", ":\x00", 1),
    "raw-escape": lambda text: text + "title: \x1b[31mred\n",
    "over-5-MB": lambda text: text + "# " + HUGE_STRING + "\n",
    "one-mb-title": lambda text: text + "title: " + "x" * 1_000_000 + "\n",
    "latin-1": lambda text: text.encode("utf-8") + b"title: caf\xe9\n",
    "surrogate-bytes": lambda text: text.encode("utf-8") + b"title: \xed\xa0\x80\n",
    "cut-in-half": lambda text: text[: len(text) // 2],
    "empty": lambda text: "",
    "only-a-comment": lambda text: "# nothing\n",
}


def override_keys(raw: Mapping[str, Any]) -> list[str]:
    """The dotted keys of ``raw`` (its mappings' keys only): what overrides aim at."""
    out = []
    for path in _paths(raw):
        if path and all(isinstance(step, str) for step in path):
            out.append(".".join(path))
    return out


@st.composite
def overrides(draw: Callable[..., Any], raw: Mapping[str, Any], most: int = 3) -> list[str]:
    """1 to ``most`` override strings in (and around) Hydra's grammar: a prefix (none, ``+``,
    ``++``, ``~``), a key of ``raw`` or a hostile one, ``=`` and a hostile value written as YAML
    or as raw text; or any text at all. None starts with ``-`` (the command line's options)."""
    keys = st.sampled_from(override_keys(raw)) | st.sampled_from(
        ["name", "title", "seed", "a..b", ".x", "x.", "simulation.t_end.x", "plant.params.M.deep", "vars.v",
         "controllers.proposed.loops.theta.schedule.kp.min", "reference.x.time", "outputs.dir", "extends"]
    ) | st.text(_ANY_CHARACTER, max_size=8)  # fmt: skip
    value = st.one_of(
        st.builds(yaml_text, hostile_values(), st.booleans(), st.just(True)),
        hostile_strings(huge=True),
        st.text(_ANY_CHARACTER, max_size=16),
    )
    one = st.one_of(
        st.builds(lambda p, k, v: f"{p}{k}={v}", st.sampled_from(["", "", "+", "++", "~"]), keys, value),
        st.builds(lambda k: f"~{k}", keys),
        st.text(_ANY_CHARACTER, max_size=20),
    )
    return draw(st.lists(one.filter(lambda text: not text.startswith("-")), min_size=1, max_size=most))

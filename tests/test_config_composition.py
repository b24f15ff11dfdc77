"""Config composition: extends, kind-changing merges and ${...} references."""

from __future__ import annotations

from pathlib import Path

import pytest

from nlcx.config import Interpolated, deep_merge, interpolate, read_config, set_values
from nlcx.errors import ConfigError


def test_extends_merges_in_order(tmp_path: Path) -> None:
    (tmp_path / "a.yaml").write_text("simulation: {t_end: 5, dt: 0.01}\nreference: {x: {kind: step, final: 1}}\n")
    (tmp_path / "b.yaml").write_text("extends: a.yaml\nsimulation: {t_end: 7}\n")
    (tmp_path / "c.yaml").write_text("extends: [b.yaml]\nreference: {x: {kind: sine, amplitude: 0.3, frequency: 1}}\n")
    data = read_config(tmp_path / "c.yaml")
    assert data["simulation"] == {"t_end": 7, "dt": 0.01}
    assert data["reference"]["x"] == {"kind": "sine", "amplitude": 0.3, "frequency": 1}  # kind changed: replaced
    (tmp_path / "loop.yaml").write_text("extends: loop.yaml\n")
    with pytest.raises(ConfigError, match="circular"):
        read_config(tmp_path / "loop.yaml")


def test_deep_merge_keeps_same_kind_sections_merged() -> None:
    base = {"r": {"kind": "step", "final": 1.0, "time": 2.0}}
    assert deep_merge(base, {"r": {"final": 3.0}}) == {"r": {"kind": "step", "final": 3.0, "time": 2.0}}


def test_references_resolve_and_vars_disappear() -> None:
    raw = {"vars": {"g": {"kp": 1}}, "a": "${vars.g}", "b": ["${vars.g}"]}
    assert interpolate(raw) == {"a": {"kp": 1}, "b": [{"kp": 1}]}
    with pytest.raises(ConfigError, match="does not exist"):
        interpolate({"a": "${vars.missing}"})
    with pytest.raises(ConfigError, match="circular"):
        interpolate({"a": "${b}", "b": "${a}"})


def _leaves(node: object, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every key path to a leaf of a raw mapping."""
    if isinstance(node, dict):
        return [leaf for key, value in node.items() for leaf in _leaves(value, (*path, str(key)))]
    return [path]


def _resolved_or_error(fn: object) -> object:
    try:
        return fn()  # type: ignore[operator]
    except ConfigError as exc:
        return f"ConfigError: {exc}"


@pytest.mark.parametrize(
    "name", ["thesis/ch2/fig_2_17.yaml", "thesis/ch3/fig_3_06.yaml", "sweeps/robustness.yaml", "xyz_error_ags.yaml"]
)
def test_interpolating_once_then_setting_values_equals_setting_then_interpolating(name: str) -> None:
    """A sweep variant's config (:class:`nlcx.config.Interpolated`): the base interpolated once
    and the variant's values set on it, when that is the same, else the full path; the result
    (or error) always equals interpolating the base with the values set. Changes: every leaf
    of the raw config (numbers, references, the ``vars`` they point at), a value holding a
    reference, a key below a reference, a new key, a whole section."""
    raw = read_config(Path(__file__).resolve().parent.parent / "configs" / name)
    raw.pop("sweep", None)
    once = Interpolated.of(raw)
    changes: list[list[tuple[list[str], object]]] = [[(list(path), 1.25)] for path in _leaves(raw)]
    changes += [
        [(["seed"], 7), (["plant", "params", "M"], 1.1)],
        [(["plant", "params", "l"], "${plant.params.M}")],
        [(["controllers", "conventional", "loops", "x", "schedule", "kp"], 3.0)],
        [(["controllers", "new_one"], {"kind": "pid"})],
        [(["simulation"], {"t_end": 2.0, "dt": 0.01})],
        [(["vars", "conventional", "position", "kp"], 9.0)],
    ]
    fast = 0
    for values in changes:
        expected = _resolved_or_error(lambda values=values: interpolate(set_values(raw, values)))
        assert _resolved_or_error(lambda values=values: once.resolve(values)) == expected, values
        fast += all(once._independent(parts, value) for parts, value in values)
    assert 0 < fast < len(changes)  # both paths taken


def test_setting_a_referenced_key_takes_the_full_path() -> None:
    raw = {"vars": {"k": 1.0}, "a": {"gain": "${vars.k}", "n": 2}, "b": "${a.n}"}
    once = Interpolated.of(raw)
    assert once.resolve([(["vars", "k"], 5.0)]) == {"a": {"gain": 5.0, "n": 2}, "b": 2}
    assert once.resolve([(["a", "n"], 3)]) == {"a": {"gain": 1.0, "n": 3}, "b": 3}
    assert once.resolve([(["a", "gain"], 4.0)]) == {"a": {"gain": 4.0, "n": 2}, "b": 2}
    assert once._independent(["a", "gain"], 4.0) and not once._independent(["a", "n"], 3)
    with pytest.raises(ConfigError, match="not a mapping"):
        once.resolve([(["a", "gain", "x"], 1.0)])

"""Config composition: extends, kind-changing merges and ${...} references (OmegaConf's rules)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml
from omegaconf import OmegaConf

from nlcx.config import Interpolated, apply_overrides, deep_merge, interpolate, read_config, set_values
from nlcx.errors import ConfigError

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


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


def test_extends_then_overrides_then_references(tmp_path: Path) -> None:
    """A kind-changing section from ``extends`` is replaced whole, overrides apply to the merged
    mapping, and references resolve after them (a reference to a deleted key is an error)."""
    (tmp_path / "base.yaml").write_text(
        "vars: {final: 2.0}\nreference: {x: {kind: step, final: '${vars.final}', time: 1.0}}\n"
    )
    (tmp_path / "top.yaml").write_text("extends: base.yaml\nreference: {x: {kind: constant, value: '${vars.final}'}}\n")
    raw = read_config(tmp_path / "top.yaml")
    assert raw["reference"] == {"x": {"kind": "constant", "value": "${vars.final}"}}  # no step keys left
    assert interpolate(apply_overrides(raw, ["vars.final=3.5"]))["reference"] == {
        "x": {"kind": "constant", "value": 3.5}
    }
    with pytest.raises(ConfigError, match=r"refers to vars\.final, a key that does not exist"):
        interpolate(apply_overrides(raw, ["~vars.final"]))


def test_references_nest_chain_and_interpolate_into_strings() -> None:
    raw = {
        "vars": {"gains": {"kp": 2.0, "ki": 0.5}, "which": "ki", "tag": "pid"},
        "label": "${vars.tag}_kp${vars.gains.kp}",
        "gain": "${vars.gains.${vars.which}}",
        "chained": "${label}",
        "copies": ["${vars.gains}", "${vars.gains}"],
        "loop": {"kp": 1.5, "same": "${.kp}"},
    }
    out = interpolate(raw)
    assert out == {
        "label": "pid_kp2.0",
        "gain": 0.5,
        "chained": "pid_kp2.0",
        "copies": [{"kp": 2.0, "ki": 0.5}, {"kp": 2.0, "ki": 0.5}],
        "loop": {"kp": 1.5, "same": 1.5},
    }
    assert out["copies"][0] is not out["copies"][1]  # each reference is a copy of its own
    assert raw["label"] == "${vars.tag}_kp${vars.gains.kp}"  # the input is left as it was


def test_numbers_stay_as_pyyaml_reads_them() -> None:
    """OmegaConf resolves the references; every other value is PyYAML's (``1e-3`` is a string in
    YAML 1.1, ``1.0e-3`` a float), also where it is referred to."""
    raw = yaml.safe_load("a: 1e-3\nb: 1.0e-3\nc: 0x10\nd: 1_000\ne: '${a}'\nf: '${b}'\ng: 'x${vars.h}'\nvars: {h: 2}\n")
    out = interpolate(raw)
    assert repr(out) == repr({"a": "1e-3", "b": 0.001, "c": 16, "d": 1000, "e": "1e-3", "f": 0.001, "g": "x2"})


def _one_line_error(raw: dict[str, Any]) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        interpolate(raw)
    assert len(str(info.value).splitlines()) == 1
    return info.value


def test_a_reference_to_a_missing_key_names_both_keys() -> None:
    error = _one_line_error({"vars": {}, "controllers": {"c": {"schedule": "${vars.gains}"}}})
    assert str(error) == (
        "config error: controllers.c.schedule = '${vars.gains}': refers to vars.gains, a key that does not exist"
    )
    error = _one_line_error({"vars": {"k": 1}, "names": ["a", "gain_${vars.kp}"]})
    assert (error.path, error.value) == ("names.1", "gain_${vars.kp}")
    assert "refers to vars.kp, a key that does not exist" in error.allowed


def test_a_circular_reference_is_one_line_naming_the_key() -> None:
    error = _one_line_error({"a": {"gain": "${b}"}, "b": "${a.gain}"})
    assert (error.path, error.value) == ("a.gain", "${b}")
    assert "circular reference" in error.allowed
    error = _one_line_error({"vars": {"x": "x_${vars.x}"}})
    assert error.path == "vars.x" and "circular reference" in error.allowed
    error = _one_line_error({"a": "${b"})
    assert error.path == "a" and "cannot be interpolated" in error.allowed


def test_every_config_interpolates_as_omegaconf_resolves_it() -> None:
    """The configs' references (whole values naming a key) are resolved by a direct walk; it
    gives OmegaConf's result, types included, on every config."""
    with_references = 0
    for path in sorted(CONFIGS.rglob("*.yaml")):
        raw = read_config(path)
        expected = OmegaConf.to_container(OmegaConf.create(raw), resolve=True)
        assert isinstance(expected, dict)
        expected.pop("vars", None)
        assert repr(interpolate(raw)) == repr(expected), path
        with_references += "${" in repr(raw)
    assert with_references > 10


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


#: A reference inside a string (to a named key), and nested and relative references, whose
#: targets depend on other keys.
STRING_REFERENCES = {"vars": {"k": 1.0, "tag": "pid"}, "a": {"label": "${vars.tag}_${vars.k}", "n": 3}, "c": {"x": 5.0}}
MOVING_REFERENCES = {
    "vars": {"k": 1.0, "which": "k", "other": 2.0},
    "a": {"gain": "${vars.${a.which}}", "which": "k", "n": 3},
    "b": {"n": 4, "copy": "${.n}"},
    "c": {"x": 5.0},
}


@pytest.mark.parametrize("raw", [STRING_REFERENCES, MOVING_REFERENCES])
def test_variants_of_a_config_with_string_nested_and_relative_references(raw: dict[str, Any]) -> None:
    """:class:`nlcx.config.Interpolated` on references that only OmegaConf resolves: setting any
    leaf, or a value with a reference, gives what interpolating the changed config gives (or
    the same error). With a reference whose target moves, every change takes the full path."""
    once = Interpolated.of(raw)
    changes: list[list[tuple[list[str], object]]] = [[(list(path), 1.25)] for path in _leaves(raw)]
    changes += [[(["a", "which"], "other")], [(["c", "x"], "${vars.k}")], [(["c", "new"], "n_${a.n}")]]
    fast = 0
    for values in changes:
        expected = _resolved_or_error(lambda values=values: interpolate(set_values(raw, values)))
        assert _resolved_or_error(lambda values=values: once.resolve(values)) == expected, values
        fast += all(once._independent(parts, value) for parts, value in values)
    if raw is MOVING_REFERENCES:
        assert fast == 0 and () in once.targets
        assert once.resolve([(["a", "which"], "other")])["a"]["gain"] == 2.0
    else:
        assert 0 < fast < len(changes)
        assert once.resolve([(["vars", "k"], 3.0)])["a"]["label"] == "pid_3.0"


def test_setting_a_referenced_key_takes_the_full_path() -> None:
    raw = {"vars": {"k": 1.0}, "a": {"gain": "${vars.k}", "n": 2}, "b": "${a.n}"}
    once = Interpolated.of(raw)
    assert once.resolve([(["vars", "k"], 5.0)]) == {"a": {"gain": 5.0, "n": 2}, "b": 2}
    assert once.resolve([(["a", "n"], 3)]) == {"a": {"gain": 1.0, "n": 3}, "b": 3}
    assert once.resolve([(["a", "gain"], 4.0)]) == {"a": {"gain": 4.0, "n": 2}, "b": 2}
    assert once._independent(["a", "gain"], 4.0) and not once._independent(["a", "n"], 3)
    with pytest.raises(ConfigError, match="not a mapping"):
        once.resolve([(["a", "gain", "x"], 1.0)])

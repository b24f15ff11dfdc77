"""Config composition: extends, kind-changing merges and ${...} references."""

from __future__ import annotations

from pathlib import Path

import pytest

from nlcx.config import deep_merge, interpolate, read_config
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

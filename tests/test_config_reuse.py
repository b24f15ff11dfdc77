"""``config.build(raw, like=base)``, the sweep's per-variant path, equals a full build.

A variant that changes a few numbers re-validates only the sections holding them; the other
sections are taken over from the base. These tests change one number at a time in every
section of real configs and compare the result (or the error) with ``config.build(raw)``.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from nlcx import config as cfg
from nlcx.errors import ConfigError

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
#: Every top-level config, and the chapter configs that add tuners, preview, fuzzy, noise,
#: friction and disturbance sections.
NAMES = sorted(
    [p.relative_to(CONFIGS).as_posix() for p in CONFIGS.glob("*.yaml")]
    + ["thesis/ch5/fig_5_19.yaml", "thesis/ch5/fig_5_10.yaml", "thesis/ch2/fig_2_24.yaml", "thesis/ch2/fig_2_26.yaml"]
)


def _numbers(node: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], float]]:
    """Every numeric leaf of a raw mapping (bools are not numbers here), with its key path."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _numbers(value, (*path, str(key)))
    elif isinstance(node, int | float) and not isinstance(node, bool):
        yield path, node


def _outcome(raw: dict[str, Any], like: cfg.Experiment | None) -> cfg.Experiment | str:
    """The experiment built, or the one-line error it gives."""
    try:
        return cfg.build(raw, like=like)
    except ConfigError as exc:
        return f"ConfigError: {exc}"


def _changes(raw: dict[str, Any]) -> list[tuple[list[str], Any]]:
    """One change per number of the config (the first few of each section), scaled by 1.1,
    plus a new seed and a negative value (an error) for every section's first number."""
    out: list[tuple[list[str], Any]] = [(["seed"], 12345)]
    for section in ("plant", "controllers", "uncertainty", "reference", "simulation", "metrics"):
        leaves = list(_numbers(raw.get(section, {}), (section,)))
        out += [(list(path), value * 1.1 + 0.25) for path, value in leaves[:6]]
        out += [(list(path), -abs(value) - 1.0) for path, value in leaves[:1]]
    return out


@pytest.mark.parametrize("name", NAMES)
def test_a_variant_built_like_its_base_equals_a_full_build(name: str) -> None:
    raw = cfg.interpolate(cfg.read_config(CONFIGS / name))
    raw.pop("sweep", None)
    base = cfg.build(raw)
    changes = _changes(raw)
    assert len(changes) > 4
    errors = 0
    for change in changes:
        varied = cfg.set_values(raw, [change])
        full = _outcome(varied, None)
        assert _outcome(varied, base) == full, (name, change)
        errors += isinstance(full, str)
    assert errors < len(changes)  # most changes are valid configs, so experiments were compared


def test_only_the_changed_sections_are_validated_again() -> None:
    raw = cfg.interpolate(cfg.read_config(CONFIGS / "x_error_ags.yaml"))
    base = cfg.build(raw)
    mass = cfg.build(cfg.set_values(raw, [(["plant", "params", "M"], 1.7), (["seed"], 3)]), like=base)
    assert mass.plant_params.M == 1.7 and mass.section.seed == 3
    assert mass.plant_params is not base.plant_params
    assert all(a is b for a, b in zip(mass.controllers, base.controllers, strict=True))
    assert mass.section.simulation is base.section.simulation
    assert mass.section.plant is not base.section.plant

    label, data = next(iter(raw["controllers"].items()))
    path, value = next(leaf for leaf in _numbers(data, ("controllers", label)) if "schedule" in leaf[0])
    gain = cfg.build(cfg.set_values(raw, [(list(path), value + 1.0)]), like=base)
    assert gain.plant_params is base.plant_params
    for before, after in zip(base.controllers, gain.controllers, strict=True):
        assert (after is before) == (before.label != label)
    assert gain == cfg.build(cfg.set_values(raw, [(list(path), value + 1.0)]))

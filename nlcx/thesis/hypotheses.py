"""Hypotheses about the loop the thesis simulated: named sets of real loop options.

Every option is a setting a user can put in any config (nothing here is a special case of
the kernel): the pendulums' options are :mod:`nlcx.thesis.loop_options`' (:data:`FAMILIES`),
chapter 5's :mod:`nlcx.thesis.cstr_options`' (:data:`CSTR_FAMILIES`). A hypothesis picks at
most one non-default value per family; :meth:`Hypothesis.apply` writes it into an experiment's
(interpolated) raw config, with the continuous parameters it frees (e.g. F_max). A value
changes only what the experiment has: a disturbance option leaves an experiment without a
disturbance as it is.

The literal hypothesis (no option) is the default loop, every experiment as its config has it.
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Mapping
from dataclasses import dataclass

from nlcx.thesis.cstr_options import CSTR_FAMILIES, CSTR_OPERATING_CB
from nlcx.thesis.loop_options import FAMILIES, NEUTRAL, OptionValue
from nlcx.thesis.scenario_options import Raw

__all__ = [
    "CSTR_FAMILIES", "CSTR_OPERATING_CB", "FAMILIES", "NEUTRAL", "OPTIONS", "Hypothesis", "OptionValue", "combine",
    "default", "family", "from_options", "parse",
]  # fmt: skip


def _merged(
    first: dict[str, dict[str, OptionValue]], second: dict[str, dict[str, OptionValue]]
) -> dict[str, dict[str, OptionValue]]:
    """Both catalogues in one, each keeping its own order of families (a hypothesis's name
    lists its options in that order): ``second``'s families before one both hold come before
    it. A family both hold has ``first``'s values, then any more of ``second``'s."""
    out: dict[str, dict[str, OptionValue]] = {}
    rest = list(second)
    for name, values in first.items():
        if name in second:
            while (before := rest.pop(0)) != name:
                out[before] = second[before]
            values = values | {k: v for k, v in second[name].items() if k not in values}
        out[name] = values
    return out | {name: second[name] for name in rest}


#: Every option by family, both chapters (step_time is a family of both, chapter 5's values
#: among the pendulums').
OPTIONS = _merged(FAMILIES, CSTR_FAMILIES)


def default(family: str) -> str:
    return next(iter(OPTIONS[family]))


@dataclass(frozen=True)
class Hypothesis:
    """Non-default option values by family (empty: the literal loop)."""

    options: tuple[tuple[str, str], ...] = ()

    @property
    def name(self) -> str:
        return "+".join(f"{f}={v}" for f, v in self.options) or "literal"

    def free(self) -> dict[str, tuple[float, float]]:
        """The continuous parameters this hypothesis frees (beyond the conventional gains)."""
        out: dict[str, tuple[float, float]] = {}
        for family, value in self.options:
            out.update(OPTIONS[family][value].free)
        return out

    def neutral(self) -> dict[str, float]:
        """Each free parameter's value nearest the default loop (:data:`NEUTRAL`)."""
        return {name: NEUTRAL[name] for name in self.free()}

    def apply(self, raw: Raw, params: Mapping[str, float], inputs: list[str]) -> Raw:
        """A copy of the interpolated experiment ``raw`` with the options on every PID controller
        (the plant's ``inputs`` are what a saturation limits)."""
        out = copy.deepcopy(raw)
        for family, value in self.options:
            option = OPTIONS[family][value]
            if option.scope == "experiment":
                option.change(out, params, inputs)
                continue
            for controller in out.get("controllers", {}).values():
                if controller.get("kind") == "pid":
                    option.change(controller, params, inputs)
        return out


def parse(name: str) -> Hypothesis:
    """The hypothesis named ``name`` ("literal", or "family=value+family=value ..."; its options
    in the order of :data:`OPTIONS`). Raises ValueError naming an unknown family or value."""
    if name == "literal":
        return Hypothesis()
    options: dict[str, str] = {}
    for part in name.split("+"):
        family_name, _, value = part.partition("=")
        if family_name not in OPTIONS or value not in OPTIONS[family_name] or family_name in options:
            known = ", ".join(OPTIONS.get(family_name, OPTIONS))
            raise ValueError(f"hypothesis {name!r}: {part!r} is not one option of a family (allowed: {known})")
        options[family_name] = value
    return from_options(options)


def from_options(options: Mapping[str, str]) -> Hypothesis:
    """The hypothesis of ``options`` (family -> value), its options in the order of :data:`OPTIONS`."""
    return Hypothesis(tuple((f, options[f]) for f in OPTIONS if f in options))


def combine(first: Hypothesis, second: Hypothesis) -> Hypothesis:
    """``first``'s options with ``second``'s (``second``'s value where both set a family)."""
    return from_options(dict(first.options) | dict(second.options))


def family(
    families: list[str], max_options: int, catalogue: Mapping[str, Mapping[str, OptionValue]] | None = None
) -> list[Hypothesis]:
    """The literal loop and every combination of up to ``max_options`` non-default values of
    distinct ``families`` (in the order of :data:`OPTIONS`), each family's values those of
    ``catalogue`` (default: :data:`CSTR_FAMILIES` where a family named is chapter 5's alone, so
    chapter 5's step_time has its own two values; :data:`OPTIONS` otherwise)."""
    if catalogue is None:
        chapter5 = any(f in CSTR_FAMILIES and f not in FAMILIES for f in families)
        catalogue = CSTR_FAMILIES if chapter5 else OPTIONS
    ordered = [f for f in OPTIONS if f in families]
    out = [Hypothesis()]
    for size in range(1, max_options + 1):
        for chosen in itertools.combinations(ordered, size):
            values = [[v for v in catalogue[f] if v != default(f)] for f in chosen]
            out += [Hypothesis(tuple(zip(chosen, combo, strict=True))) for combo in itertools.product(*values)]
    return out

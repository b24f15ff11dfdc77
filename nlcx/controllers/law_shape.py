"""What a control law written in plain Python reads and writes (:class:`LawShape`), from what
:func:`nlcx.controllers.law.controller` is given, every part checked: its measures, references,
inputs, states, parameters, signals and period, by name and in order."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from nlcx.errors import ConfigError

#: How a parameter may be declared: its default, or (default, unit), or (default, unit, description).
ParamSpec = float | tuple[float, str] | tuple[float, str, str]


@dataclass(frozen=True)
class LawShape:
    """What a law reads and writes, by name and in order (see the module docstring)."""

    name: str
    measures: tuple[str, ...]
    references: tuple[str, ...]
    inputs: tuple[str, ...]
    #: (name, initial value) of each of the law's states.
    states: tuple[tuple[str, float], ...] = ()
    #: (name, default, unit, description) of each parameter.
    params: tuple[tuple[str, float, str, str], ...] = ()
    #: Internal signals the law returns third, to be logged.
    signals: tuple[str, ...] = ()
    #: The law's period, s; None: every integration step.
    sample_time: float | None = None
    #: ``p`` by name (a named tuple); False: a plain tuple by position.
    named_params: bool = True

    @property
    def n_y(self) -> int:
        return len(self.measures)

    @property
    def n_r(self) -> int:
        return len(self.references)

    @property
    def n_u(self) -> int:
        return len(self.inputs)

    @property
    def n_s(self) -> int:
        return len(self.states)

    @property
    def n_p(self) -> int:
        return len(self.params)

    @property
    def n_g(self) -> int:
        return len(self.signals)

    @property
    def hold(self) -> int:
        """Offset of ``hold`` in ``cp``."""
        return self.n_y + self.n_u

    @property
    def p0(self) -> int:
        """Offset of the first parameter in ``cp`` (after ``hold`` and the period)."""
        return self.hold + 2

    @property
    def s0(self) -> int:
        """Offset of the first state in ``cs`` (after the step count and the held inputs)."""
        return 1 + self.n_u

    @property
    def log_names(self) -> tuple[str, ...]:
        """The logged columns: ``<name>.<state>`` then ``<name>.<signal>``."""
        return tuple(f"{self.name}.{n}" for n, _ in self.states) + tuple(f"{self.name}.{n}" for n in self.signals)


def _names(key: str, names: Sequence[str], allow_empty: bool = False) -> tuple[str, ...]:
    """Names declared for ``key``: identifiers, each once; at least one unless ``allow_empty``."""
    if isinstance(names, str):
        raise ConfigError(key, names, "a list of names, e.g. ['x', 'theta']")
    out = tuple(names)
    for name in out:
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise ConfigError(key, name, "a signal name: a Python identifier, e.g. x_dot")
    if len(set(out)) != len(out):
        raise ConfigError(key, list(out), "each name once")
    if not out and not allow_empty:
        raise ConfigError(key, list(out), "declare at least one")
    return out


def _parameters(spec: Mapping[str, ParamSpec]) -> tuple[tuple[str, float, str, str], ...]:
    """(name, default, unit, description) of each declared parameter, checked."""
    out = []
    for name, value in spec.items():
        if not isinstance(name, str) or not name.isidentifier() or name.startswith("_") or name in _RESERVED:
            allowed = f"a Python identifier not starting with _, nor one of {', '.join(_RESERVED)}"
            raise ConfigError("params", name, allowed)
        default, unit, text = (value, "", "") if not isinstance(value, tuple) else (*value, "", "")[:3]
        if isinstance(default, bool) or not isinstance(default, int | float) or not math.isfinite(default):
            raise ConfigError(f"params.{name}", default, "a finite number as the default")
        out.append((name, float(default), str(unit), str(text)))
    return tuple(out)


#: Keys of a law's config section that are not parameters.
_RESERVED = ("kind", "sample_time")


def _states(spec: Mapping[str, float] | None) -> tuple[tuple[str, float], ...]:
    """(name, initial value) of each declared state, checked."""
    names = _names("states", list(spec or {}), allow_empty=True)
    out = []
    for name in names:
        value = (spec or {})[name]
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ConfigError(f"states.{name}", value, "a finite number: the state's initial value")
        out.append((name, float(value)))
    return tuple(out)


def shape_of(
    name: str,
    measures: Sequence[str],
    references: Sequence[str],
    inputs: Sequence[str],
    states: Mapping[str, float] | None = None,
    params: Mapping[str, ParamSpec] | None = None,
    signals: Sequence[str] = (),
    sample_time: float | None = None,
) -> LawShape:
    """The law's :class:`LawShape` from what :func:`controller` was given, every part checked."""
    if sample_time is not None and (
        isinstance(sample_time, bool) or not isinstance(sample_time, int | float) or not 0 < sample_time < math.inf
    ):
        raise ConfigError("sample_time", sample_time, "None (every integration step) or a period > 0, s")
    return LawShape(
        name=name,
        measures=_names("measures", measures, allow_empty=True),
        references=_names("references", references, allow_empty=True),
        inputs=_names("inputs", inputs),
        states=_states(states),
        params=_parameters(params or {}),
        signals=_names("signals", signals, allow_empty=True),
        sample_time=None if sample_time is None else float(sample_time),
    )

"""The fuzzy self-tuning PID's configuration (section 5.4.1, Tables 5.2-5.7, 25 rules) and its
membership functions.

Membership functions. The thesis prints for every fuzzy set only its "crisp input range"
(lower, upper) and its shape (Tables 5.3-5.7). They are read as follows:

- a triangular set (NS, ZE, PS) has its feet at ``lower`` and ``upper`` and its peak at the
  midpoint (lower + upper) / 2;
- the left shoulder NB ("trapezoidal") is 1 from ``lower`` up to the universe minimum and falls
  linearly to 0 at ``upper``; it is 1 for every input at or below the universe minimum;
- the right shoulder PB rises linearly from 0 at ``lower`` to 1 at the universe maximum and
  stays 1 beyond it.

Every printed shoulder straddles its universe edge (lower < edge < upper), which the
configuration checks. The inputs e and de/dt are clipped to their universes (Table 5.2)
before fuzzification, so beyond an edge the shoulder set fires fully and some rule always
fires (the configuration also checks that the sets of each input cover its universe).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeAlias

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, create_model, field_validator

from nlcx.controllers.schedules import GainRange, ScheduleConfig

#: Linguistic values, in order: negative big, negative small, zero, positive small, positive big.
SET_NAMES: tuple[str, ...] = ("NB", "NS", "ZE", "PS", "PB")
SET_MEANINGS: tuple[str, ...] = ("negative big", "negative small", "zero", "positive small", "positive big")
#: Input variables (rows and columns of the rule grid) and output variables (eqs. 5.12-5.14).
INPUTS: tuple[str, ...] = ("e", "de_dt")
OUTPUTS: tuple[str, ...] = ("kp1", "ki1", "kd1")
VARIABLES: tuple[str, ...] = INPUTS + OUTPUTS

#: Table 5.2: universes of discourse of the inputs ...
E_UNIVERSE: tuple[float, float] = (-1.44, 1.56)
DE_DT_UNIVERSE: tuple[float, float] = (-15.7, 4.3)
#: ... and of the scaled gains k_p1, k_i1, k_d1 (eqs. 5.12-5.14).
OUTPUT_UNIVERSE: tuple[float, float] = (0.0, 1.0)

#: Table 5.3: crisp ranges of the fuzzy sets of e (NB, PB trapezoidal; NS, ZE, PS triangular).
E_SETS: dict[str, tuple[float, float]] = {
    "NB": (-2.43, -0.92),
    "NS": (-1.063, -0.214),
    "ZE": (-0.3725, 0.445),
    "PS": (0.27, 1.088),
    "PB": (0.9449, 2.64),
}
#: Table 5.4: de/dt.
DE_DT_SETS: dict[str, tuple[float, float]] = {
    "NB": (-22.9, -11.65),
    "NS": (-12.5, -6.89),
    "ZE": (-7.835, -2.817),
    "PS": (-3.88, 1.258),
    "PB": (0.358, 11.5),
}
#: Table 5.5: k_p1.
KP1_SETS: dict[str, tuple[float, float]] = {
    "NB": (-0.36, 0.168),
    "NS": (0.1124, 0.39),
    "ZE": (0.322, 0.617),
    "PS": (0.564, 0.842),
    "PB": (0.7897, 1.36),
}
#: Table 5.6: k_i1.
KI1_SETS: dict[str, tuple[float, float]] = {
    "NB": (-0.321, 0.208),
    "NS": (0.16, 0.43),
    "ZE": (0.379, 0.646),
    "PS": (0.586, 0.827),
    "PB": (0.753, 1.32),
}
#: Table 5.7: k_d1.
KD1_SETS: dict[str, tuple[float, float]] = {
    "NB": (-0.334, 0.221),
    "NS": (0.181, 0.443),
    "ZE": (0.3849, 0.642),
    "PS": (0.575, 0.864),
    "PB": (0.8029, 1.36),
}
TABLE_SETS: dict[str, dict[str, tuple[float, float]]] = {
    "e": E_SETS,
    "de_dt": DE_DT_SETS,
    "kp1": KP1_SETS,
    "ki1": KI1_SETS,
    "kd1": KD1_SETS,
}

#: A linguistic value (one of :data:`SET_NAMES`).
SetName: TypeAlias = Literal["NB", "NS", "ZE", "PS", "PB"]

#: Section 5.4.1, rules 1-25: the output set of k_p1, k_i1 and k_d1 (the same for all three)
#: by e (row NB..PB) and de/dt (column NB..PB); rule n has e = SET_NAMES[(n - 1) % 5] and
#: de/dt = SET_NAMES[(n - 1) // 5].
RULES: tuple[tuple[SetName, ...], ...] = (
    ("NB", "NB", "NS", "NS", "ZE"),
    ("NB", "NS", "NS", "ZE", "PS"),
    ("NS", "NS", "ZE", "PS", "PS"),
    ("NS", "ZE", "PS", "PS", "PB"),
    ("ZE", "PS", "PS", "PB", "PB"),
)

RuleRow = Annotated[list[SetName], Field(min_length=5, max_length=5)]

# ---------------------------------------------------------------------------- configuration


def _check_range(value: tuple[float, float], names: tuple[str, str]) -> tuple[float, float]:
    lower, upper = value
    if not (np.isfinite(lower) and np.isfinite(upper)):
        raise ValueError(f"({names[0]}, {names[1]}) must be finite")
    if not lower < upper:
        raise ValueError(f"{names[0]} {lower:g} must be below {names[1]} {upper:g}")
    return value


class _VariableSets(BaseModel):
    """The five fuzzy sets of one variable: (lower, upper) crisp range each."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    @field_validator(*SET_NAMES, check_fields=False)
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _check_range(value, ("lower", "upper"))


def _sets_model(variable: str, table: dict[str, tuple[float, float]]) -> type[_VariableSets]:
    fields: dict[str, Any] = {
        name: (
            tuple[float, float],
            Field(table[name], description=f"crisp range (lower, upper) of {variable}'s set {name} ({meaning})"),
        )
        for name, meaning in zip(SET_NAMES, SET_MEANINGS, strict=True)
    }
    return create_model(f"FuzzySets_{variable}", __base__=_VariableSets, **fields)


if TYPE_CHECKING:  # the fields of a model created at run time are unknown to a type checker: it sees the base
    ESets: TypeAlias = _VariableSets
    DeDtSets: TypeAlias = _VariableSets
    Kp1Sets: TypeAlias = _VariableSets
    Ki1Sets: TypeAlias = _VariableSets
    Kd1Sets: TypeAlias = _VariableSets
else:
    ESets = _sets_model("e", E_SETS)
    DeDtSets = _sets_model("de_dt", DE_DT_SETS)
    Kp1Sets = _sets_model("kp1", KP1_SETS)
    Ki1Sets = _sets_model("ki1", KI1_SETS)
    Kd1Sets = _sets_model("kd1", KD1_SETS)


class FuzzySets(BaseModel):
    """Fuzzy sets of every variable (defaults: Tables 5.3-5.7); a partial mapping overrides sets."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    e: ESets = Field(ESets(), description="fuzzy sets of the error e (Table 5.3)")
    de_dt: DeDtSets = Field(DeDtSets(), description="fuzzy sets of de/dt (Table 5.4)")
    kp1: Kp1Sets = Field(Kp1Sets(), description="fuzzy sets of the scaled gain k_p1 (Table 5.5)")
    ki1: Ki1Sets = Field(Ki1Sets(), description="fuzzy sets of the scaled gain k_i1 (Table 5.6)")
    kd1: Kd1Sets = Field(Kd1Sets(), description="fuzzy sets of the scaled gain k_d1 (Table 5.7)")

    def ranges(self, variable: str) -> list[tuple[float, float]]:
        """The (lower, upper) ranges of ``variable`` in the order NB, NS, ZE, PS, PB."""
        sets = getattr(self, variable)
        return [tuple(getattr(sets, name)) for name in SET_NAMES]


class FuzzyUniverses(BaseModel):
    """Universes of discourse of the inputs (Table 5.2); the outputs' universe is [0, 1]."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    e: tuple[float, float] = Field(E_UNIVERSE, description="universe of discourse of e, (min, max) (Table 5.2)")
    de_dt: tuple[float, float] = Field(
        DE_DT_UNIVERSE, description="universe of discourse of de/dt, (min, max) (Table 5.2)"
    )

    @field_validator("e", "de_dt")
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _check_range(value, ("min", "max"))


class FuzzyConfig(ScheduleConfig):
    kind: Literal["fuzzy"] = Field(
        "fuzzy", description="registered name of this gain schedule; selects the model that validates this section"
    )
    kp: GainRange = Field(
        description=(
            "range of k_p that the scaled output k_p1 in [0, 1] spans (eq. 5.12; from the Ziegler-Nichols tuning)"
        )
    )
    ki: GainRange = Field(description="range of k_i spanned by k_i1 (eq. 5.13)")
    kd: GainRange = Field(description="range of k_d spanned by k_d1 (eq. 5.14)")
    universes: FuzzyUniverses = Field(
        FuzzyUniverses(),
        description="universes of discourse of the inputs (Table 5.2); the outputs' universe is [0, 1]",
    )
    resolution: int = Field(
        101,
        ge=3,
        le=100_001,
        description="samples of the output universe [0, 1] for the centroid (MATLAB's default 101)",
    )
    centroid: Literal["discrete", "piecewise_linear"] = Field(
        "discrete",
        description=(
            "discrete: sum(z mu) / sum(mu) over the samples (MATLAB); piecewise_linear: centroid of the linear "
            "interpolant through the samples (scikit-fuzzy)"
        ),
    )
    sets: FuzzySets = Field(
        default_factory=FuzzySets,
        validate_default=True,
        description=(
            "the fuzzy sets of every variable (defaults: Tables 5.3-5.7), checked against the universes; a partial "
            "mapping overrides single sets"
        ),
    )
    rules: Annotated[list[RuleRow], Field(min_length=5, max_length=5)] = Field(
        default_factory=lambda: [list(row) for row in RULES],
        description=(
            "output set of k_p1, k_i1, k_d1 by e (row NB..PB) and de/dt (column NB..PB): the 25 rules of section 5.4.1"
        ),
    )

    @field_validator("sets")
    @classmethod
    def _shapes(cls, sets: FuzzySets, info: ValidationInfo) -> FuzzySets:
        universes = info.data.get("universes")
        resolution = info.data.get("resolution")
        for variable in VARIABLES:
            if variable in INPUTS:
                if universes is None:
                    continue
                umin, umax = getattr(universes, variable)
            else:
                umin, umax = OUTPUT_UNIVERSE
            ranges = sets.ranges(variable)
            (nb_lo, nb_hi), (pb_lo, pb_hi) = ranges[0], ranges[-1]
            if not nb_lo < umin < nb_hi:
                raise ValueError(
                    f"{variable}.NB = ({nb_lo:g}, {nb_hi:g}) must straddle the universe minimum {umin:g} "
                    "(lower < min < upper): it is the left shoulder"
                )
            if not pb_lo < umax < pb_hi:
                raise ValueError(
                    f"{variable}.PB = ({pb_lo:g}, {pb_hi:g}) must straddle the universe maximum {umax:g} "
                    "(lower < max < upper): it is the right shoulder"
                )
            if variable in INPUTS:
                gap = _uncovered(ranges, umin, umax)
                if gap is not None:
                    raise ValueError(f"{variable} = {gap:g} lies in no fuzzy set of {variable}: the sets must cover")
            elif resolution is not None:
                z = np.linspace(umin, umax, resolution)
                for name, (lower, upper) in zip(SET_NAMES, ranges, strict=True):
                    if not np.any(_mf_np(z, lower, upper, SET_NAMES.index(name), umin, umax) > 0):
                        raise ValueError(
                            f"{variable}.{name} = ({lower:g}, {upper:g}) is zero at all {resolution} output samples"
                        )
        return sets


def _uncovered(ranges: list[tuple[float, float]], umin: float, umax: float) -> float | None:
    """A point of [umin, umax] where every set of the variable is zero, or None."""
    # open supports: NB (-inf, upper), triangles (lower, upper), PB (lower, inf)
    supports = [(-np.inf, ranges[0][1]), *ranges[1:-1], (ranges[-1][0], np.inf)]
    reach = -np.inf
    for lower, upper in sorted(supports):
        if lower >= reach > -np.inf and max(reach, umin) <= min(lower, umax):
            return float(max(reach, umin))  # the gap [reach, lower] meets the universe
        reach = max(reach, upper)
    return None


def as_config(cfg: FuzzyConfig | dict[str, object]) -> FuzzyConfig:
    """``cfg`` itself, or the dict validated as a :class:`FuzzyConfig`."""
    return cfg if isinstance(cfg, FuzzyConfig) else FuzzyConfig.model_validate({"kind": "fuzzy", **cfg})


# ---------------------------------------------------------------------- membership functions

_LEFT, _RIGHT = 0, len(SET_NAMES) - 1


def _mf_np(x: np.ndarray, lower: float, upper: float, position: int, umin: float, umax: float) -> np.ndarray:
    """Membership of ``x`` (an array) in the set at ``position`` (0 NB shoulder, 4 PB shoulder, else
    triangle); the compiled schedule computes it with the same arithmetic
    (``_mf`` of :mod:`nlcx.controllers.fuzzy_step`)."""
    x = np.asarray(x, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        if position == _LEFT:
            return np.where(x <= umin, 1.0, np.where(x >= upper, 0.0, (upper - x) / (upper - umin)))
        if position == _RIGHT:
            return np.where(x >= umax, 1.0, np.where(x <= lower, 0.0, (x - lower) / (umax - lower)))
        peak = 0.5 * (lower + upper)
        inner = np.where(x <= peak, (x - lower) / (peak - lower), (upper - x) / (upper - peak))
        return np.where((x <= lower) | (x >= upper), 0.0, inner)


def universe(cfg: FuzzyConfig | dict[str, object], variable: str) -> tuple[float, float]:
    """(min, max) of the universe of discourse of ``variable``."""
    cfg = as_config(cfg)
    if variable in INPUTS:
        return tuple(getattr(cfg.universes, variable))
    if variable in OUTPUTS:
        return OUTPUT_UNIVERSE
    raise ValueError(f"unknown fuzzy variable {variable!r}; allowed: {', '.join(VARIABLES)}")


def membership(cfg: FuzzyConfig | dict[str, object], variable: str, x: np.ndarray) -> dict[str, np.ndarray]:
    """Membership of ``x`` (not clipped) in each set of ``variable``: {"NB": mu, ..., "PB": mu}."""
    cfg = as_config(cfg)
    umin, umax = universe(cfg, variable)
    return {
        name: _mf_np(x, lower, upper, k, umin, umax)
        for k, (name, (lower, upper)) in enumerate(zip(SET_NAMES, cfg.sets.ranges(variable), strict=True))
    }

"""Fuzzy self-tuning PID gain schedule of section 5.4.1 (eqs. 5.12-5.14, Tables 5.2-5.7, 25 rules).

A two-input, three-output Mamdani system maps the error e = r - y and its rate de/dt to the
scaled gains k_p1, k_i1, k_d1 in [0, 1]; eqs. 5.12-5.14 inverted give the PID gains

    k_p = kp_min + k_p1 (kp_max - kp_min),   likewise k_i and k_d.

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

Inference (Mamdani, as MATLAB's defaults): AND = min, implication = min (clipping),
aggregation = max, centroid defuzzification over the output universe [0, 1] sampled at
``resolution`` points (101, MATLAB's default). ``centroid: discrete`` (the default) is
MATLAB's sum(z mu(z)) / sum(mu(z)) over the samples; ``centroid: piecewise_linear`` is the
exact centroid of the linear interpolant through the samples, as scikit-fuzzy's ``defuzz``
computes it. The two differ by the end-point weighting of the sampled aggregate (at most a
few 1e-3 of the output universe with the thesis's sets). Should no output sample have a
positive membership (impossible with a validated configuration) the centroid is the middle
of the output universe, as MATLAB returns.

The compiled schedule reads the output membership functions from tables sampled once by
:meth:`Fuzzy.pack`, so a call costs a few hundred min/max operations and allocates nothing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeAlias

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, create_model, field_validator

from nlcx._numba_compat import hot_njit
from nlcx.controllers.schedules import GainRange, ScheduleConfig, ScheduleModel, gain_ranges
from nlcx.layout import Layout

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

#: Axis labels of Figures 5.4-5.8.
LABELS = {"e": "e", "de_dt": "de/dt", "kp1": "$k_{p1}$", "ki1": "$k_{i1}$", "kd1": "$k_{d1}$"}

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


def as_config(cfg: FuzzyConfig | dict[str, Any]) -> FuzzyConfig:
    """``cfg`` itself, or the dict validated as a :class:`FuzzyConfig`."""
    return cfg if isinstance(cfg, FuzzyConfig) else FuzzyConfig.model_validate({"kind": "fuzzy", **cfg})


# ---------------------------------------------------------------------- membership functions

_LEFT, _RIGHT = 0, len(SET_NAMES) - 1


@njit(cache=True, error_model="numpy")
def _mf(x, lower, upper, position, umin, umax):  # pragma: no cover - compiled
    """Membership of x in the set at ``position`` (0 NB shoulder, 4 PB shoulder, else triangle)."""
    if position == 0:
        if x <= umin:
            return 1.0
        if x >= upper:
            return 0.0
        return (upper - x) / (upper - umin)
    if position == 4:
        if x >= umax:
            return 1.0
        if x <= lower:
            return 0.0
        return (x - lower) / (umax - lower)
    if x <= lower or x >= upper:
        return 0.0
    peak = 0.5 * (lower + upper)
    if x <= peak:
        return (x - lower) / (peak - lower)
    return (upper - x) / (upper - peak)


def _mf_np(x: np.ndarray, lower: float, upper: float, position: int, umin: float, umax: float) -> np.ndarray:
    """Vectorised :func:`_mf` (the same arithmetic)."""
    x = np.asarray(x, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        if position == _LEFT:
            return np.where(x <= umin, 1.0, np.where(x >= upper, 0.0, (upper - x) / (upper - umin)))
        if position == _RIGHT:
            return np.where(x >= umax, 1.0, np.where(x <= lower, 0.0, (x - lower) / (umax - lower)))
        peak = 0.5 * (lower + upper)
        inner = np.where(x <= peak, (x - lower) / (peak - lower), (upper - x) / (upper - peak))
        return np.where((x <= lower) | (x >= upper), 0.0, inner)


def universe(cfg: FuzzyConfig | dict[str, Any], variable: str) -> tuple[float, float]:
    """(min, max) of the universe of discourse of ``variable``."""
    cfg = as_config(cfg)
    if variable in INPUTS:
        return tuple(getattr(cfg.universes, variable))
    if variable in OUTPUTS:
        return OUTPUT_UNIVERSE
    raise ValueError(f"unknown fuzzy variable {variable!r}; allowed: {', '.join(VARIABLES)}")


def membership(cfg: FuzzyConfig | dict[str, Any], variable: str, x: Any) -> dict[str, np.ndarray]:
    """Membership of ``x`` (not clipped) in each set of ``variable``: {"NB": mu, ..., "PB": mu}."""
    cfg = as_config(cfg)
    umin, umax = universe(cfg, variable)
    return {
        name: _mf_np(x, lower, upper, k, umin, umax)
        for k, (name, (lower, upper)) in enumerate(zip(SET_NAMES, cfg.sets.ranges(variable), strict=True))
    }


def membership_figure(cfg: FuzzyConfig | dict[str, Any], variable: str, points: int = 1001) -> Any:
    """Figures 5.4-5.8: the five membership functions of ``variable`` over its universe."""
    from matplotlib.figure import Figure

    cfg = as_config(cfg)
    umin, umax = universe(cfg, variable)
    x = np.linspace(umin, umax, points)
    mus = membership(cfg, variable, x)
    fig = Figure(figsize=(6.4, 3.2))
    ax = fig.add_subplot()
    for name, mu in mus.items():
        ax.plot(x, mu, lw=1.4, label=name)
        k = int(np.argmax(mu))
        ax.annotate(name, (x[k], 1.0), xytext=(0, 3), textcoords="offset points", ha="center", fontsize=8)
    ax.set_xlim(umin, umax)
    ax.set_ylim(-0.02, 1.12)
    ax.set_xlabel(LABELS[variable])
    ax.set_ylabel("Degree of membership")
    ax.set_title(f"Fuzzy Membership functions for {LABELS[variable]}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="center right", fontsize=8)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------- compiled schedule

#: The head of the schedule block sp: output grid resolution n, centroid (0 discrete, 1
#: piecewise linear) and the universes of e and de/dt (Table 5.2).
FUZZY_HEAD = Layout("FuzzyHead", ("resolution", "piecewise", "e_min", "e_max", "de_min", "de_max"))
#: One crisp range: a fuzzy set's (Tables 5.3-5.4) or an output gain's (eqs. 5.12-5.14).
RANGE = Layout("Range", ("lower", "upper"))
F = FUZZY_HEAD.at
R = RANGE.at
N_SETS = len(SET_NAMES)
N_OUTPUTS = len(OUTPUTS)
RANGE_SIZE = RANGE.size
#: Where the tables of sp start: the ranges of the sets of e, then of de/dt, the gain ranges
#: of k_p, k_i, k_d, the rule table (outputs x e sets x de/dt sets: the concluded set's
#: index), the output grid z_0..z_{n-1} and its memberships (outputs x sets x n).
E_RANGES = FUZZY_HEAD.size
DE_RANGES = E_RANGES + N_SETS * RANGE_SIZE
GAIN_RANGES = DE_RANGES + N_SETS * RANGE_SIZE
RULE_TABLE = GAIN_RANGES + N_OUTPUTS * RANGE_SIZE
OUTPUT_GRID = RULE_TABLE + N_OUTPUTS * N_SETS * N_SETS


@njit(cache=True, error_model="numpy")
def _output_mu(sp, base, n, s, k):  # pragma: no cover - compiled
    """mu_s(z_k) of one output whose membership table starts at sp[base]."""
    return sp[base + s * n + k]


@njit(cache=True, error_model="numpy")
def _aggregate(sp, base, n, k, w0, w1, w2, w3, w4):  # pragma: no cover - compiled
    """max_s min(W_s, mu_s(z_k)) of one output (base: its membership table)."""
    a = min(w0, _output_mu(sp, base, n, 0, k))
    a = max(a, min(w1, _output_mu(sp, base, n, 1, k)))
    a = max(a, min(w2, _output_mu(sp, base, n, 2, k)))
    a = max(a, min(w3, _output_mu(sp, base, n, 3, k)))
    return max(a, min(w4, _output_mu(sp, base, n, 4, k)))


@njit(cache=True, error_model="numpy")
def _centroid(sp, base, n, piecewise, w0, w1, w2, w3, w4):  # pragma: no cover - compiled
    """Centroid of the aggregated output on the grid z (discrete, or of its piecewise-linear
    interpolation); the universe's middle if nothing fires."""
    z0 = OUTPUT_GRID
    num = 0.0
    den = 0.0
    if piecewise:
        y1 = _aggregate(sp, base, n, 0, w0, w1, w2, w3, w4)
        x1 = sp[z0]
        for k in range(1, n):
            y2 = _aggregate(sp, base, n, k, w0, w1, w2, w3, w4)
            x2 = sp[z0 + k]
            if y1 != 0.0 or y2 != 0.0:
                h = x2 - x1
                area = 0.5 * h * (y1 + y2)
                num += h * h * (y1 + 2.0 * y2) / 6.0 + x1 * area
                den += area
            y1 = y2
            x1 = x2
    else:
        for k in range(n):
            a = _aggregate(sp, base, n, k, w0, w1, w2, w3, w4)
            num += sp[z0 + k] * a
            den += a
    if den > 0.0:
        return num / den
    return 0.5 * (OUTPUT_UNIVERSE[0] + OUTPUT_UNIVERSE[1])


@njit(cache=True, error_model="numpy")
def _fuzzy_gain(sp, g, me, md, n, piecewise):  # pragma: no cover - compiled
    """Output g (0 k_p1, 1 k_i1, 2 k_d1) for the input memberships me (e) and md (de/dt),
    scaled to its gain range (eqs. 5.12-5.14)."""
    # W_s = max over the rules concluding set s of min(mu_e, mu_de): max_r min(w_r, mu_s(z))
    # = min(W_s, mu_s(z)) for the rules sharing s, so 5 clipped sets make the aggregate.
    w0 = 0.0
    w1 = 0.0
    w2 = 0.0
    w3 = 0.0
    w4 = 0.0
    rb = RULE_TABLE + N_SETS * N_SETS * g
    for i in range(N_SETS):
        a = me[i]
        if a <= 0.0:
            continue
        for j in range(N_SETS):
            w = min(a, md[j])
            if w <= 0.0:
                continue
            s = int(sp[rb + N_SETS * i + j])
            if s == 0:
                w0 = max(w0, w)
            elif s == 1:
                w1 = max(w1, w)
            elif s == 2:
                w2 = max(w2, w)
            elif s == 3:
                w3 = max(w3, w)
            else:
                w4 = max(w4, w)
    k1 = _centroid(sp, OUTPUT_GRID + n + N_SETS * n * g, n, piecewise, w0, w1, w2, w3, w4)
    gain = GAIN_RANGES + RANGE_SIZE * g
    lo = sp[gain + R.lower]
    return lo + k1 * (sp[gain + R.upper] - lo)


@njit(cache=True, error_model="numpy")
def _set_mu(x, sp, ranges, i, umin, umax):  # pragma: no cover - compiled
    """Membership of x in input set i, whose crisp range is the i-th RANGE at sp[ranges]."""
    at = ranges + RANGE_SIZE * i
    return _mf(x, sp[at + R.lower], sp[at + R.upper], i, umin, umax)


@hot_njit(cache=True, error_model="numpy")
def fuzzy_gains(t, e, edot, p, row, o):  # pragma: no cover - compiled
    """Mamdani self-tuning PID, section 5.4.1: (e, de/dt) -> (k_p1, k_i1, k_d1) -> eqs. 5.12-5.14.

    The packed tables start at p[row, o] (layout above)."""
    sp = p[row, o:]
    n = int(sp[F.resolution])
    piecewise = sp[F.piecewise] != 0.0
    emin, emax, dmin, dmax = sp[F.e_min], sp[F.e_max], sp[F.de_min], sp[F.de_max]
    x = min(max(e, emin), emax)
    v = min(max(edot, dmin), dmax)
    me = (
        _set_mu(x, sp, E_RANGES, 0, emin, emax),
        _set_mu(x, sp, E_RANGES, 1, emin, emax),
        _set_mu(x, sp, E_RANGES, 2, emin, emax),
        _set_mu(x, sp, E_RANGES, 3, emin, emax),
        _set_mu(x, sp, E_RANGES, 4, emin, emax),
    )
    md = (
        _set_mu(v, sp, DE_RANGES, 0, dmin, dmax),
        _set_mu(v, sp, DE_RANGES, 1, dmin, dmax),
        _set_mu(v, sp, DE_RANGES, 2, dmin, dmax),
        _set_mu(v, sp, DE_RANGES, 3, dmin, dmax),
        _set_mu(v, sp, DE_RANGES, 4, dmin, dmax),
    )
    kp = _fuzzy_gain(sp, 0, me, md, n, piecewise)
    ki = _fuzzy_gain(sp, 1, me, md, n, piecewise)
    kd = _fuzzy_gain(sp, 2, me, md, n, piecewise)
    return kp, ki, kd


def _tables(cfg: FuzzyConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Output grid z (n,), output memberships (3, 5, n) and rule table (3, 5, 5) of set indices."""
    z = np.linspace(*OUTPUT_UNIVERSE, cfg.resolution)
    mu = np.array([list(membership(cfg, out, z).values()) for out in OUTPUTS])
    rule = np.array([[SET_NAMES.index(s) for s in row] for row in cfg.rules])
    return z, mu, np.stack([rule] * len(OUTPUTS))


class Fuzzy(ScheduleModel):
    """Fuzzy self-tuning PID (Mamdani, 25 rules), section 5.4.1."""

    Config = FuzzyConfig
    gains = staticmethod(fuzzy_gains)

    def pack(self, cfg: FuzzyConfig) -> np.ndarray:
        z, mu, rules = _tables(cfg)
        (emin, emax), (dmin, dmax) = cfg.universes.e, cfg.universes.de_dt
        head = FUZZY_HEAD.pack(
            resolution=cfg.resolution, piecewise=cfg.centroid == "piecewise_linear",
            e_min=emin, e_max=emax, de_min=dmin, de_max=dmax,
        )  # fmt: skip
        ranges = [*cfg.sets.ranges("e"), *cfg.sets.ranges("de_dt"), *np.reshape(gain_ranges(cfg), (-1, 2))]
        sp = np.concatenate(
            [head, *(RANGE.pack(lower=lo, upper=hi) for lo, hi in ranges), rules.ravel().astype(float), z, mu.ravel()]
        )
        assert sp.size == OUTPUT_GRID + cfg.resolution * (1 + N_OUTPUTS * N_SETS)
        return sp


# ------------------------------------------------------------------ vectorised (numpy) surface


def fuzzy_surface(cfg: FuzzyConfig | dict[str, Any], e: Any, edot: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k_p, k_i, k_d) at every (e, de/dt) (broadcast arrays), for control-surface plots and tests."""
    cfg = as_config(cfg)
    e, edot = np.broadcast_arrays(np.asarray(e, dtype=float), np.asarray(edot, dtype=float))
    shape = e.shape
    x = np.clip(e.ravel(), *cfg.universes.e)
    v = np.clip(edot.ravel(), *cfg.universes.de_dt)
    me = np.array(list(membership(cfg, "e", x).values()))  # (5, N)
    md = np.array(list(membership(cfg, "de_dt", v).values()))
    fire = np.minimum(me[:, None, :], md[None, :, :])  # (5 e, 5 de, N)
    z, mu, rules = _tables(cfg)
    ranges = (cfg.kp, cfg.ki, cfg.kd)
    out = []
    for o in range(len(OUTPUTS)):
        agg = np.zeros((x.size, z.size))
        for s in range(len(SET_NAMES)):
            mask = rules[o] == s
            if not mask.any():
                continue
            w = fire[mask].max(axis=0)  # W_s, (N,)
            agg = np.maximum(agg, np.minimum(w[:, None], mu[o, s][None, :]))
        if cfg.centroid == "discrete":
            num, den = agg @ z, agg.sum(axis=1)
        else:
            y1, y2 = agg[:, :-1], agg[:, 1:]
            h = np.diff(z)
            area = 0.5 * h * (y1 + y2)
            num = (h * h * (y1 + 2.0 * y2) / 6.0 + z[:-1] * area).sum(axis=1)
            den = area.sum(axis=1)
        k1 = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.5 * (z[0] + z[-1]))
        g = ranges[o]
        out.append((g.min + k1 * (g.max - g.min)).reshape(shape))
    return out[0], out[1], out[2]

"""The fuzzy self-tuning PID's compiled schedule (section 5.4.1, eqs. 5.12-5.14): Mamdani
inference from the tables :meth:`nlcx.controllers.fuzzy.Fuzzy.pack` samples once.

Inference (Mamdani, as MATLAB's defaults): AND = min, implication = min (clipping),
aggregation = max, centroid defuzzification over the output universe [0, 1] sampled at
``resolution`` points (101, MATLAB's default). ``centroid: discrete`` (the default) is
MATLAB's sum(z mu(z)) / sum(mu(z)) over the samples; ``centroid: piecewise_linear`` is the
exact centroid of the linear interpolant through the samples, as scikit-fuzzy's ``defuzz``
computes it. The two differ by the end-point weighting of the sampled aggregate (at most a
few 1e-3 of the output universe with the thesis's sets). Should no output sample have a
positive membership (impossible with a validated configuration) the centroid is the middle
of the output universe, as MATLAB returns.

The schedule reads the output membership functions from the sampled tables, so a call costs
a few hundred min/max operations and allocates nothing.
"""

from __future__ import annotations

from typing import TypeAlias

from numba import njit

from nlcx._numba_compat import hot_njit
from nlcx.controllers.fuzzy_config import OUTPUT_UNIVERSE, OUTPUTS, SET_NAMES
from nlcx.kernel.signatures import FloatArray
from nlcx.layout import Layout

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


#: The memberships of one input in its five sets.
Memberships: TypeAlias = tuple[float, float, float, float, float]


@njit(cache=True, error_model="numpy")
def _mf(
    x: float, lower: float, upper: float, position: int, umin: float, umax: float
) -> float:  # pragma: no cover - compiled
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


@njit(cache=True, error_model="numpy")
def _output_mu(sp: FloatArray, base: int, n: int, s: int, k: int) -> float:  # pragma: no cover - compiled
    """mu_s(z_k) of one output whose membership table starts at sp[base]."""
    return sp[base + s * n + k]


@njit(cache=True, error_model="numpy")
def _aggregate(
    sp: FloatArray, base: int, n: int, k: int, w0: float, w1: float, w2: float, w3: float, w4: float
) -> float:  # pragma: no cover - compiled
    """max_s min(W_s, mu_s(z_k)) of one output (base: its membership table)."""
    a = min(w0, _output_mu(sp, base, n, 0, k))
    a = max(a, min(w1, _output_mu(sp, base, n, 1, k)))
    a = max(a, min(w2, _output_mu(sp, base, n, 2, k)))
    a = max(a, min(w3, _output_mu(sp, base, n, 3, k)))
    return max(a, min(w4, _output_mu(sp, base, n, 4, k)))


@njit(cache=True, error_model="numpy")
def _centroid(
    sp: FloatArray, base: int, n: int, piecewise: bool, w0: float, w1: float, w2: float, w3: float, w4: float
) -> float:  # pragma: no cover - compiled
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
def _fuzzy_gain(
    sp: FloatArray, g: int, me: Memberships, md: Memberships, n: int, piecewise: bool
) -> float:  # pragma: no cover - compiled
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
def _set_mu(
    x: float, sp: FloatArray, ranges: int, i: int, umin: float, umax: float
) -> float:  # pragma: no cover - compiled
    """Membership of x in input set i, whose crisp range is the i-th RANGE at sp[ranges]."""
    at = ranges + RANGE_SIZE * i
    return _mf(x, sp[at + R.lower], sp[at + R.upper], i, umin, umax)


@hot_njit(cache=True, error_model="numpy")
def fuzzy_gains(
    t: float, e: float, edot: float, p: FloatArray, row: int, o: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
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

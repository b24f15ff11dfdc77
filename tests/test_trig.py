"""nlcx.kernel.trig: sin and cos of the plants' angles, vector code with fixed bits.

Checked against the true values (mpmath, 50 digits), against libm (numpy), and for the one
property the kernel relies on: an angle gets the same bits whatever batch it is in."""

from __future__ import annotations

import importlib
import math

import mpmath
import numpy as np
import pytest
from numba import njit

from nlcx.kernel.trig import NO_REDUCTION, REDUCTION_LIMIT, TINY, sincos, sincos_column

RNG = np.random.default_rng(20261124)
HALF_PI_MULTIPLES = np.arange(-60_000, 60_000) * (np.pi / 2)
RANGES = {
    "pendulum angles": RNG.normal(size=200_000) * 0.3,
    "one turn": RNG.uniform(-2 * np.pi, 2 * np.pi, 200_000),
    "up to the reduction limit": RNG.uniform(-REDUCTION_LIMIT, REDUCTION_LIMIT, 200_000),
    "next to multiples of pi/2": np.concatenate(
        [np.nextafter(HALF_PI_MULTIPLES, np.inf), np.nextafter(HALF_PI_MULTIPLES, -np.inf)]
    ),
    "small": RNG.uniform(-1e-4, 1e-4, 50_000),
}


@njit(cache=True)
def _one_at_a_time(a):  # pragma: no cover - compiled
    out = np.empty((2, a.size))
    for i in range(a.size):
        out[0, i], out[1, i] = sincos(a[i])
    return out


def _column(a: np.ndarray, n: int | None = None) -> np.ndarray:
    """(sin a, cos a) of the first n angles (all by default) by :func:`sincos_column`, (2, n)."""
    n = a.size if n is None else n
    out = np.full((2, n), np.nan)
    sincos_column(np.ascontiguousarray(a, dtype=float), n, out[0], out[1])
    return out


def _ulps(value: np.ndarray, exact: np.ndarray) -> np.ndarray:
    return np.abs(value - exact) / np.spacing(np.abs(exact))


@pytest.mark.parametrize("name", list(RANGES))
def test_within_one_ulp_of_libm(name: str) -> None:
    a = RANGES[name]
    sc = _column(a)
    assert _ulps(sc[0], np.sin(a)).max() <= 1.0
    assert _ulps(sc[1], np.cos(a)).max() <= 1.0


def test_faithful_against_50_digit_values() -> None:
    """Error below one ulp of the true value (so never more than a rounding step from it)."""
    mpmath.mp.dps = 50
    a = np.concatenate([RNG.normal(size=1500) * 0.5, RNG.uniform(-1e4, 1e4, 500), HALF_PI_MULTIPLES[::6000] + 1e-9])
    sc = _column(a)
    for i, x in enumerate(a):
        exact_sin, exact_cos = mpmath.sin(mpmath.mpf(float(x))), mpmath.cos(mpmath.mpf(float(x)))
        for got, exact in ((sc[0, i], exact_sin), (sc[1, i], exact_cos)):
            err = abs(mpmath.mpf(float(got)) - exact)
            assert err < math.ulp(float(exact)), (x, got, float(exact))


def test_same_bits_in_any_batch_and_alone() -> None:
    """The vector loop and its scalar remainder compute alike: batch size and position do not
    change an angle's sin and cos, nor does reading it from a row of a state batch, whole or
    its first nb angles."""
    a = RNG.uniform(-3.0, 3.0, 1003)
    full = _column(a)
    for n in (1, 2, 3, 7, 8, 9, 15, 16, 17, 31, 33, 100):
        for start in range(0, a.size - n, 89):
            assert np.array_equal(_column(a[start : start + n]), full[:, start : start + n]), (n, start)
    states = np.stack([RNG.normal(size=a.size), a, RNG.normal(size=a.size)])
    assert np.array_equal(_column(states[1]), full)
    assert np.array_equal(_column(states[1], 37), full[:, :37])
    rows = np.full((4, a.size), -7.0)  # into rows of a (n, B) array, as a plant's dx: the rest untouched
    sincos_column(states[1], 37, rows[1], rows[3])
    assert np.array_equal(rows[[1, 3], :37], full[:, :37])
    assert np.all(rows[[0, 2]] == -7.0) and np.all(rows[:, 37:] == -7.0)
    assert np.array_equal(_one_at_a_time(a), full)


def test_one_angle_without_the_reduction_same_bits() -> None:
    """:func:`sincos` skips the reduction below NO_REDUCTION: the same bits as the reduced
    vector path (signs of zero included) below, at and above that edge and pi/4, and the
    reduction is indeed the identity there (its quotient is 0 up to the edge)."""
    edges = np.array([NO_REDUCTION, np.pi / 4])
    near = np.concatenate([np.nextafter(edges, 0.0), edges, np.nextafter(edges, 1.0)])
    near = np.concatenate([near + k * 1e-12 for k in range(-200, 201)])
    a = np.concatenate([near, -near, RNG.uniform(-1.0, 1.0, 100_000), RNG.normal(size=100_000) * 0.3,
                        [0.0, -0.0, 5e-324, -5e-324, TINY, -TINY, TINY / 2]])  # fmt: skip
    alone, column = _one_at_a_time(a), _column(a)
    assert np.array_equal(alone.view(np.int64), column.view(np.int64))
    below = np.abs(a) < NO_REDUCTION
    assert np.all(np.floor(a[below] * (2 / np.pi) + 0.5) == 0.0)


def test_outside_the_reduction_range_libm_decides() -> None:
    a = np.array([REDUCTION_LIMIT * 1.0000001, -3.0e7, 1e300, np.inf, -np.inf, np.nan])
    with np.errstate(invalid="ignore"):
        sin_ref, cos_ref = np.sin(a), np.cos(a)
    for sc in (_column(a), _one_at_a_time(a)):
        assert np.array_equal(sc[0], sin_ref, equal_nan=True)
        assert np.array_equal(sc[1], cos_ref, equal_nan=True)


def test_zero_and_tiny_angles_as_libm() -> None:
    a = np.array([0.0, -0.0, 5e-324, -TINY / 2, TINY / 2])
    for sc in (_column(a), _one_at_a_time(a)):
        assert np.array_equal(sc[0], a) and np.array_equal(np.signbit(sc[0]), np.signbit(a))
        assert np.array_equal(sc[1], np.ones_like(a))


MODELS = [("x", 4, 1), ("xy", 8, 2), ("xz", 6, 2), ("xyz", 10, 3)]


def _batch(model: str, n: int, n_u: int, size: int, equations: str = "derived") -> tuple:
    """A pendulum's right-hand side (``equations``: derived or printed) and a batch of ``size``
    variants (x, u, p as columns)."""
    rhs = getattr(importlib.import_module(f"nlcx.plants.{model}_pendulum"), f"{model}_{equations}_rhs")
    x = RNG.normal(size=(n, size)) * 0.5
    u = RNG.normal(size=(n_u, size))
    p = np.stack([RNG.uniform(0.8, 1.2, size), RNG.uniform(0.08, 0.12, size), RNG.uniform(0.24, 0.36, size),
                  np.full(size, 9.81)])  # fmt: skip
    return rhs, x, u, p


@pytest.mark.parametrize("equations", ["derived", "printed"])
@pytest.mark.parametrize(("model", "n", "n_u"), MODELS)
def test_same_bits_in_any_batch(model: str, n: int, n_u: int, equations: str) -> None:
    """The right-hand sides take their sines one variant at a time below COLUMN_ROWS variants
    and, the generated ones and eqs. 2.8-2.11, for the whole batch above: a variant's
    derivative is the same in a batch of 1, 3 or 50."""
    from nlcx.kernel import trig

    variants = 50
    rhs, x, u, p = _batch(model, n, n_u, variants, equations)
    whole = np.empty((n, variants))
    rhs(0.0, x, u, p, whole, variants)
    for size in (1, 3, trig.COLUMN_ROWS - 1, trig.COLUMN_ROWS, 13):
        for start in range(0, variants - size, 11):
            cols = slice(start, start + size)
            part = np.empty((n, size))
            rhs(0.0, *(np.ascontiguousarray(a[:, cols]) for a in (x, u, p)), part, size)
            assert np.array_equal(part, whole[:, cols]), (size, start)


@pytest.mark.parametrize("nb", [3, 13])
@pytest.mark.parametrize("equations", ["derived", "printed"])
@pytest.mark.parametrize(("model", "n", "n_u"), MODELS)
def test_the_columns_from_nb_on_are_left_alone(model: str, n: int, n_u: int, equations: str, nb: int) -> None:
    """Columns from nb on are neither read (NaN there changes nothing) nor written (a
    sentinel stays), below and above COLUMN_ROWS."""
    rhs, x, u, p = _batch(model, n, n_u, 20, equations)
    expected = np.empty((n, 20))
    rhs(0.0, x, u, p, expected, nb)
    for a in (x, u, p):
        a[:, nb:] = np.nan
    dx = np.full((n, 20), -7.0)
    rhs(0.0, x, u, p, dx, nb)
    assert np.array_equal(dx[:, :nb], expected[:, :nb])
    assert np.all(dx[:, nb:] == -7.0)


def test_no_contraction_in_the_compiled_code() -> None:
    """The same-bits property rests on every multiply and add being rounded on its own: no
    fast-math flags, no fused multiply-add in the compiled IR of the vector loop. Compiled
    afresh with the same options: numba cannot show the IR of code it loaded from its cache."""
    options = {k: v for k, v in sincos_column.targetoptions.items() if k != "nopython"}
    fresh = njit(**options)(sincos_column.py_func)
    fresh(np.zeros(3), 3, np.zeros(3), np.zeros(3))
    ir = fresh.inspect_llvm(fresh.signatures[0])
    assert "fadd" in ir and "fmul" in ir
    for marker in ("contract", "fast ", "llvm.fma", "llvm.fmuladd"):
        assert marker not in ir, marker

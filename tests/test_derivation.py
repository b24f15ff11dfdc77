"""The generated pendulum code (nlcx/plants/generated) against a fresh sympy derivation.

scripts/derive_pendulums.py derives M(q) q'' = b(q, q', u) from the thesis's energies; here
the unsimplified expressions are lambdified, solved numerically and compared with the
compiled right-hand sides and energies, and the emitted text with the committed file.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import sympy as sp
from numba import njit

from nlcx.plants.base import evaluate_rhs
from nlcx.plants.generated import pendulums as gen
from nlcx.plants.x_pendulum import x_pendulum_rhs

ROOT = Path(__file__).resolve().parent.parent
PV = np.array([1.0, 0.1, 0.3, 9.8])


def load_script(name: str) -> ModuleType:
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


derive = load_script("derive_pendulums")
KEYS = list(derive.MODELS)


@pytest.fixture(scope="module")
def derivations() -> dict:
    return {k: derive.derive(k) for k in KEYS}


def random_states(d, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions within +-5, rates N(0, 2), forces within +-20 N; theta about upright or hanging
    with |cos theta| >= cos 1.2 (the spherical coordinates are singular at cos theta = 0),
    phi anywhere."""
    rng = np.random.default_rng(seed)
    X = np.empty((n, 2 * len(d.q)))
    for i, q in enumerate(d.q):
        X[:, 2 * i] = rng.uniform(-5, 5, n)
        X[:, 2 * i + 1] = rng.normal(0, 2, n)
        if q.name == "theta":
            X[:, 2 * i] = rng.uniform(-1.2, 1.2, n) + np.pi * rng.integers(0, 2, n)
        if q.name == "phi":
            X[:, 2 * i] = rng.uniform(-np.pi, np.pi, n)
    U = rng.uniform(-20, 20, (n, len(d.u)))
    return X, U


def compiled(key: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return evaluate_rhs(getattr(gen, f"{key}_derived_rhs"), x, u, PV)


@pytest.mark.parametrize("key", KEYS)
def test_compiled_rhs_matches_the_sympy_derivation(derivations, key: str) -> None:
    d = derivations[key]
    args = [*d.states, *d.u, *d.params]
    mass = sp.lambdify(args, d.mass, "numpy")
    b = sp.lambdify(args, d.b, "numpy")
    X, U = random_states(d, 100, seed=11)
    for x, u in zip(X, U, strict=True):
        values = [*x, *u, *PV]
        qdd = np.linalg.solve(np.array(mass(*values), dtype=float), np.array(b(*values), dtype=float).ravel())
        dx = compiled(key, x, u)
        assert np.array_equal(dx[0::2], x[1::2])
        assert np.allclose(dx[1::2], qdd, rtol=1e-10, atol=1e-10 * max(1.0, np.max(np.abs(qdd))))


@pytest.mark.parametrize("key", KEYS)
def test_energy_matches_the_sympy_derivation(derivations, key: str) -> None:
    d = derivations[key]
    X, _ = random_states(d, 60, seed=12)
    batch = X.reshape(3, 20, -1)
    E = getattr(gen, f"{key}_energy")(batch, PV)
    assert E.shape == (3, 20)
    ref = sp.lambdify([*d.states, *d.params], d.energy, "numpy")(*np.moveaxis(batch, -1, 0), *PV)
    assert np.allclose(E, ref, rtol=1e-12, atol=1e-12)


def test_energy_is_the_thesis_lyapunov_function() -> None:
    """Energies written out by hand from eqs. 2.24, 3.30 (squared as 3.29 requires), 3.56, 4.41."""
    M, m, l, g = PV
    rng = np.random.default_rng(3)
    x, xd, y, yd, z, zd, th, thd, ph, phd = rng.normal(size=(10, 50))
    c, s, cp, sp_ = np.cos(th), np.sin(th), np.cos(ph), np.sin(ph)
    xp_dot = xd + l * c * thd  # eqs. 2.1c, 3.1d, 4.1d
    yp_dot = yd + l * c * cp * phd - l * s * sp_ * thd  # eqs. 3.1e, 4.1e
    zp_dot = zd - l * s * cp * thd - l * c * sp_ * phd  # eqs. 3.1f, 4.1f
    cases = {
        "x": (
            np.stack([x, xd, th, thd], -1),
            0.5 * M * xd**2 + 0.5 * m * (xp_dot**2 + (l * s * thd) ** 2) + m * g * l * c,  # eq. 2.24, z = 0
        ),
        "xy": (
            np.stack([x, xd, y, yd, th, thd, ph, phd], -1),
            0.5 * M * (xd**2 + yd**2)
            + 0.5 * m * (xp_dot**2 + yp_dot**2 + (zp_dot - zd) ** 2)  # z_dot = 0
            + m * g * l * c * cp,  # eq. 3.30, z = 0
        ),
        "xz": (
            np.stack([x, xd, z, zd, th, thd], -1),
            0.5 * M * (xd**2 + zd**2)
            + 0.5 * m * (xp_dot**2 + (zd - l * s * thd) ** 2)
            + M * g * z
            + m * g * (z + l * c),  # eq. 3.56
        ),
        "xyz": (
            np.stack([x, xd, y, yd, z, zd, th, thd, ph, phd], -1),
            0.5 * M * (xd**2 + yd**2 + zd**2)
            + 0.5 * m * (xp_dot**2 + yp_dot**2 + zp_dot**2)
            + M * g * z
            + m * g * z
            + m * g * l * c * cp,  # eq. 4.41
        ),
    }
    for key, (state, expected) in cases.items():
        assert np.allclose(getattr(gen, f"{key}_energy")(state, PV), expected, rtol=1e-13, atol=1e-12), key


def test_mass_matrix_is_symmetric_positive_definite(derivations) -> None:
    for key in KEYS:
        d = derivations[key]
        assert d.mass == d.mass.T
        mass = sp.lambdify([*d.states, *d.params], d.mass, "numpy")
        X, _ = random_states(d, 20, seed=13)
        for x in X:
            assert np.min(np.linalg.eigvalsh(np.array(mass(*x, *PV), dtype=float))) > 0


def test_emitted_module_is_the_committed_one() -> None:
    """Rerunning the generator reproduces nlcx/plants/generated/ exactly (deterministic output)."""
    assert derive.emit_module() == derive.TARGET.read_text()
    assert derive.emit_init() == derive.INIT.read_text()


@njit(error_model="numpy")
def _numba_powers(a):  # pragma: no cover - compiled
    out = np.empty((2, a.size))
    for i in range(a.size):
        out[0, i] = a[i] ** 2
        out[1, i] = a[i] ** 3
    return out


@njit(error_model="numpy")
def _products(a):  # pragma: no cover - compiled
    out = np.empty((2, a.size))
    for i in range(a.size):
        out[0, i] = a[i] * a[i]
        out[1, i] = a[i] * (a[i] * a[i])
    return out


def test_squares_and_cubes_print_as_numbas_powers() -> None:
    """In the right-hand sides q**2 and q**3 print as products, which vectorise where numba's
    power does not: in their place in an expression, and with the bits of numba's power with
    a literal exponent (random bit patterns, infinities, NaN, subnormals, overflow)."""
    printer = derive._Printer(None, {})
    l, m = sp.symbols("l m", positive=True)
    assert [printer.code(e) for e in (l**2, l**3, l**2 * m, 2 * l**2 * m, m / l**2, l**4)] == [
        "l*l", "l*(l*l)", "(l*l)*m", "2*(l*l)*m", "m/(l*l)", "l**4"
    ]  # fmt: skip
    rng = np.random.default_rng(8)
    a = np.concatenate([rng.integers(0, 2**64, 1_000_000, dtype=np.uint64).view(float), rng.normal(size=100_000),
                        [0.0, -0.0, np.inf, -np.inf, np.nan, 5e-324, 1e-160, 1e103, 1e155, -1e155]])  # fmt: skip
    with np.errstate(all="ignore"):
        assert np.array_equal(_numba_powers(a).view(np.int64), _products(a).view(np.int64))


def test_x_derived_equals_printed_eqs_2_8_to_2_11() -> None:
    rng = np.random.default_rng(4)
    for _ in range(200):
        x = np.array([rng.normal(), rng.normal(0, 2), rng.uniform(-math.pi, math.pi), rng.normal(0, 3)])
        u = np.array([rng.uniform(-20, 20)])
        printed = evaluate_rhs(x_pendulum_rhs, x, u, PV)
        assert np.allclose(compiled("x", x, u), printed, rtol=1e-12, atol=1e-12)


def test_printed_lagrange_equations_hold_except_the_misprinted_ones() -> None:
    """The thesis's own Lagrange equations (2.7, 3.7-3.10, 3.39-3.41, 4.8-4.12) evaluated at the
    derived accelerations: all hold except the four that docs/errata.md lists as misprinted."""
    errata = load_script("errata")
    _, wrong = errata.check_lagrange()
    assert wrong == {"3.9", "3.10", "3.41", "4.11"}


def test_generated_code_reads_the_parameters_in_the_layouts_order(derivations) -> None:
    """The generated right-hand sides read p by position; the order is PARAMS's (pendulum.py)."""
    from nlcx.plants.pendulum import PARAMS

    for d in derivations.values():
        assert tuple(s.name for s in d.params) == PARAMS.fields

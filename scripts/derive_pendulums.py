"""Derive the four pendulums' equations of motion from the thesis's Lagrangians and emit numba code.

Run ``python scripts/derive_pendulums.py`` to (re)write ``nlcx/plants/generated/pendulums.py``
(and the package's ``__init__.py``); ``--check`` only compares and exits 1 on a difference.

For each model the kinetic and potential energy are written as the thesis prints them: the
base (mass M) at (x, y, z), the point mass m at distance l with (eqs. 2.1, 3.1, 4.1)

    x_p = x + l sin(theta),  y_p = y + l cos(theta) sin(phi),  z_p = z + l cos(theta) cos(phi),

velocities eqs. 4.1d-f (2.1c-d and 3.1d-f are their special cases),
K.E. = 1/2 M (x'^2 + y'^2 + z'^2) + 1/2 m (x_p'^2 + y_p'^2 + z_p'^2) (eqs. 2.4a, 3.4a, 3.36a,
4.4a) and P.E. = M g z + m g z_p (eqs. 3.36b, 4.4b; with z fixed at 0 this is the m g z_p of
eqs. 2.4b and 3.4b). The coordinates a model does not have are fixed at zero (phi = 0 for the
planar models, z = 0 for the x and x-y pendulums), which reproduces eqs. 2.5, 3.5 and 3.37.

The Euler-Lagrange equations d/dt(dL/dq') - dL/dq = Q with the generalised forces Q (F_x on x,
F_y on y, F_z on z, none on the angles; eqs. 2.2, 3.2, 3.34, 4.2) are written as

    M(q) q'' = b(q, q', u),   M_ij = d^2 T / dq'_i dq'_j,
    b = Q - (d/dq (dT/dq')) q' + dT/dq - dV/dq,

and are NOT solved symbolically: the emitted right-hand side evaluates the entries of M and
b as scalar expressions (common subexpressions shared via sympy's ``cse``) and solves
M q'' = b with an unrolled LDL^T factorisation written as scalar statements, so it
allocates nothing. Structural zeros of M are skipped. M is symmetric positive definite (for
the spherical models away from cos(theta) = 0, where the coordinates are singular).
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import sympy as sp
from sympy.printing.precedence import PRECEDENCE
from sympy.printing.pycode import PythonCodePrinter

ROOT = Path(__file__).resolve().parent.parent
TARGET = ROOT / "nlcx" / "plants" / "generated" / "pendulums.py"
INIT = ROOT / "nlcx" / "plants" / "generated" / "__init__.py"
COMMAND = "python scripts/derive_pendulums.py"
LINE_LENGTH = 110

# Parameters p = (M, m, l, g) of Table 2.1.
M, m, l, g = sp.symbols("M m l g", positive=True)
PARAMS = (M, m, l, g)
# Generalised coordinates, their rates and the forces (all real scalars).
COORDS = {name: sp.Symbol(name, real=True) for name in ("x", "y", "z", "theta", "phi")}
RATES = {name: sp.Symbol(f"{name}_dot", real=True) for name in COORDS}
FORCES = {name: sp.Symbol(f"F_{name}", real=True) for name in ("x", "y", "z")}
#: Code names of symbols whose own names would clash with the rhs arguments (t, x, u, p, dx).
CODE_NAMES = {"x": "x_pos", "y": "y_pos", "z": "z_pos"}


@dataclass(frozen=True)
class ModelSpec:
    """One pendulum: its generalised coordinates (in the thesis's state order) and forces."""

    key: str
    title: str
    coords: tuple[str, ...]
    #: Axes with an applied force, in input order (F_x, F_y, F_z).
    forced: tuple[str, ...]
    #: Where the thesis writes the model: Lagrangian, energies, Lagrange and state equations.
    source: str
    energy_eqs: str


MODELS: dict[str, ModelSpec] = {
    "x": ModelSpec(
        "x", "x inverted pendulum", ("x", "theta"), ("x",),
        "eqs. 2.1, 2.4-2.6 (Lagrange eqs. 2.2, 2.7)", "eqs. 2.23-2.24 with z = 0",
    ),
    "xy": ModelSpec(
        "xy", "x-y inverted pendulum", ("x", "y", "theta", "phi"), ("x", "y"),
        "eqs. 3.1, 3.4-3.6 (Lagrange eqs. 3.2, 3.7-3.10)", "eqs. 3.29-3.30 with z = 0",
    ),
    "xz": ModelSpec(
        "xz", "x-z inverted pendulum", ("x", "z", "theta"), ("x", "z"),
        "eqs. 3.36-3.38 (Lagrange eqs. 3.34, 3.39-3.41)", "eqs. 3.55-3.56",
    ),
    "xyz": ModelSpec(
        "xyz", "x-y-z inverted pendulum", ("x", "y", "z", "theta", "phi"), ("x", "y", "z"),
        "eqs. 4.1, 4.4-4.5 (Lagrange eqs. 4.2, 4.8-4.12)", "eqs. 4.40-4.41; P.E. of eq. 4.4b, not 4.6",
    ),
}  # fmt: skip


@dataclass(frozen=True)
class Derivation:
    """The sympy expressions of one model (not simplified unless asked)."""

    spec: ModelSpec
    q: tuple[sp.Symbol, ...]
    qd: tuple[sp.Symbol, ...]
    u: tuple[sp.Symbol, ...]
    params: tuple[sp.Symbol, ...]
    #: Mass matrix M(q), n x n.
    mass: sp.Matrix
    #: b(q, q', u) = Q - C(q, q') q' - dV/dq, n x 1.
    b: sp.Matrix
    kinetic: sp.Expr
    potential: sp.Expr

    @property
    def energy(self) -> sp.Expr:
        """E = T + V (the Lyapunov function V of eqs. 2.23, 3.29, 3.55, 4.40)."""
        return self.kinetic + self.potential

    @property
    def states(self) -> tuple[sp.Symbol, ...]:
        """State vector (q1, q1', q2, q2', ...): the thesis's x1..xn order."""
        return tuple(s for pair in zip(self.q, self.qd, strict=True) for s in pair)


def energies(spec: ModelSpec) -> tuple[sp.Expr, sp.Expr]:
    """K.E. and P.E. of eqs. 4.4-4.5 with the model's absent coordinates fixed at 0.

    Also checks that the printed velocities (4.1d-f) are the time derivatives of the
    printed positions (4.1a-c).
    """
    x, y, z, theta, phi = (COORDS[k] for k in ("x", "y", "z", "theta", "phi"))
    xd, yd, zd, thetad, phid = (RATES[k] for k in ("x", "y", "z", "theta", "phi"))
    xp = x + l * sp.sin(theta)  # eq. 4.1a
    yp = y + l * sp.cos(theta) * sp.sin(phi)  # eq. 4.1b
    zp = z + l * sp.cos(theta) * sp.cos(phi)  # eq. 4.1c
    xp_dot = xd + l * sp.cos(theta) * thetad  # eq. 4.1d
    yp_dot = yd + l * sp.cos(theta) * sp.cos(phi) * phid - l * sp.sin(theta) * sp.sin(phi) * thetad  # 4.1e
    zp_dot = zd - l * sp.sin(theta) * sp.cos(phi) * thetad - l * sp.cos(theta) * sp.sin(phi) * phid  # 4.1f
    coords = [COORDS[k] for k in COORDS]
    rates = [RATES[k] for k in COORDS]
    for pos, vel in ((xp, xp_dot), (yp, yp_dot), (zp, zp_dot)):
        chain = sum(sp.diff(pos, c) * r for c, r in zip(coords, rates, strict=True))
        assert sp.simplify(chain - vel) == 0, "printed velocity is not d/dt of the printed position"
    kinetic = sp.Rational(1, 2) * M * (xd**2 + yd**2 + zd**2) + sp.Rational(1, 2) * m * (
        xp_dot**2 + yp_dot**2 + zp_dot**2
    )  # eq. 4.4a / 4.5a
    potential = M * g * z + m * g * zp  # eq. 4.4b / 4.5b
    absent = {COORDS[k]: 0 for k in COORDS if k not in spec.coords}
    absent.update({RATES[k]: 0 for k in COORDS if k not in spec.coords})
    return kinetic.subs(absent), potential.subs(absent)


def derive(key: str, simplify: bool = False) -> Derivation:
    """Mass matrix, b and energies of model ``key`` ("x", "xy", "xz" or "xyz")."""
    spec = MODELS[key]
    q = tuple(COORDS[c] for c in spec.coords)
    qd = tuple(RATES[c] for c in spec.coords)
    u = tuple(FORCES[a] for a in spec.forced)
    kinetic, potential = energies(spec)
    n = len(q)
    momenta = [sp.diff(kinetic, v) for v in qd]
    mass = sp.Matrix(n, n, lambda i, j: sp.diff(momenta[i], qd[j]))
    generalised = [FORCES[c] if c in spec.forced else sp.S.Zero for c in spec.coords]
    b = sp.Matrix(
        [
            generalised[i]
            - sum(sp.diff(momenta[i], q[j]) * qd[j] for j in range(n))
            + sp.diff(kinetic, q[i])
            - sp.diff(potential, q[i])
            for i in range(n)
        ]
    )
    if simplify:
        mass = mass.applyfunc(_simplify)
        b = b.applyfunc(_simplify)
        kinetic = _simplify(kinetic)
        potential = _simplify(potential)
    return Derivation(spec, q, qd, u, PARAMS, mass, b, kinetic, potential)


def _simplify(expr: sp.Expr) -> sp.Expr:
    return sp.trigsimp(sp.expand(expr))


# --------------------------------------------------------------------------- code emission


class _Printer(PythonCodePrinter):
    """Python code with sin/cos from ``module`` (np for arrays) and renames. With ``module``
    None (the compiled right-hand side), sin(q) and cos(q) of a coordinate q print as the
    locals ``sin_q`` and ``cos_q``, and squares and cubes as products (see :meth:`_print_Pow`)."""

    def __init__(self, module: str | None, names: dict[sp.Symbol, str]) -> None:
        super().__init__({"standard": "python3"})
        self.fn_module = module
        self.names = names

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        return self.names.get(expr, expr.name)

    def _print_trig(self, fn: str, expr: sp.Expr) -> str:
        arg = self._print(expr.args[0])
        if self.fn_module is None:
            if not isinstance(expr.args[0], sp.Symbol):
                raise ValueError(f"{fn} of {arg}: the kernel takes sin and cos of coordinates only")
            return f"{fn}_{arg}"
        return f"{self.fn_module}.{fn}({arg})"

    def _print_Pow(self, expr: sp.Pow, rational: bool = False) -> str:
        """q**2 as (q*q) and q**3 as (q*(q*q)) in the compiled right-hand side: numba's power
        with a literal integer exponent blocks vectorisation of the loop over the variants,
        and these products are the multiplications numba's power makes, in its order, so the
        bits are the same (tests/test_derivation.py)."""
        if not self._is_product(expr):
            return super()._print_Pow(expr, rational)
        base = self.parenthesize(expr.base, PRECEDENCE["Mul"])
        square = f"{base}*{base}"
        return f"({square})" if expr.exp == 2 else f"({base}*({square}))"

    def _is_product(self, expr: sp.Expr) -> bool:
        return self.fn_module is None and expr.is_Pow and expr.exp.is_Integer and expr.exp in (2, 3)

    def code(self, expr: sp.Expr) -> str:
        """The printed expression, a square or cube alone without its parentheses."""
        text = self.doprint(expr)
        return text[1:-1] if self._is_product(expr) else text

    def _print_sin(self, expr: sp.Expr) -> str:
        return self._print_trig("sin", expr)

    def _print_cos(self, expr: sp.Expr) -> str:
        return self._print_trig("cos", expr)


def _code_names() -> dict[sp.Symbol, str]:
    return {COORDS[k]: v for k, v in CODE_NAMES.items()}


def _split_top(text: str) -> list[str]:
    """Split an expression at its top-level binary + and - (kept at the head of each part)."""
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif depth == 0 and ch in "+-" and i > 0 and text[i - 1] == " " and text[i + 1 : i + 2] == " ":
            parts.append(text[start:i].rstrip())
            start = i
    parts.append(text[start:])
    return [p for p in parts if p]


def _assign(indent: str, target: str, text: str) -> list[str]:
    """``target = text``, wrapped in parentheses at top-level +/- if the line is too long."""
    line = f"{indent}{target} = {text}"
    if len(line) <= LINE_LENGTH:
        return [line]
    inner = indent + "    "
    lines = [f"{indent}{target} = ("]
    current = ""
    for part in _split_top(text):
        candidate = f"{current} {part}" if current else part
        if current and len(inner) + len(candidate) > LINE_LENGTH:
            lines.append(inner + current)
            current = part
        else:
            current = candidate
    lines.append(inner + current)
    lines.append(f"{indent})")
    if any(len(x) > LINE_LENGTH for x in lines):
        raise ValueError(f"cannot wrap {target} = {text[:60]}...")
    return lines


def _cse(exprs: list[sp.Expr], prefix: str) -> tuple[list[tuple[sp.Symbol, sp.Expr]], list[sp.Expr]]:
    return sp.cse(exprs, symbols=sp.numbered_symbols(prefix), order="canonical")


def _ldl_solve(n: int, zero: list[list[bool]], indent: str) -> list[str]:
    """Scalar statements solving M a = b for a_0..a_{n-1} by LDL^T (M given as m{i}{j}, i >= j).

    ``zero[i][j]`` marks structural zeros of M; fill-in is tracked so that no statement
    multiplies by a known zero.
    """
    lines = [f"{indent}# M q'' = b by LDL^T: M = L D L^T with unit lower-triangular L"]
    nz = [[not zero[i][j] for j in range(n)] for i in range(n)]  # L's nonzero pattern (i > j)
    for j in range(n):
        terms = [f"L{j}{k} * L{j}{k} * d{k}" for k in range(j) if nz[j][k]]
        rhs = " - ".join([f"m{j}{j}", *terms])
        lines += _assign(indent, f"d{j}", rhs)
        lines.append(f"{indent}r{j} = 1.0 / d{j}")
        for i in range(j + 1, n):
            terms = [f"L{i}{k} * L{j}{k} * d{k}" for k in range(j) if nz[i][k] and nz[j][k]]
            if zero[i][j] and not terms:
                nz[i][j] = False
                continue
            nz[i][j] = True
            head = "0.0" if zero[i][j] else f"m{i}{j}"
            body = " - ".join([head, *terms]) if terms else head
            if terms:
                lines += _assign(indent, f"L{i}{j}", f"({body}) * r{j}")
            else:
                lines += _assign(indent, f"L{i}{j}", f"{body} * r{j}")
    lines.append(f"{indent}# forward substitution L z = b, then z / D, then back substitution L^T a = z / D")
    for i in range(n):
        terms = [f"L{i}{k} * z{k}" for k in range(i) if nz[i][k]]
        lines += _assign(indent, f"z{i}", " - ".join([f"b{i}", *terms]))
    for i in reversed(range(n)):
        terms = [f"L{k}{i} * a{k}" for k in range(i + 1, n) if nz[k][i]]
        lines += _assign(indent, f"a{i}", " - ".join([f"z{i} * r{i}", *terms]))
    return lines


def _def(name: str, params: str) -> list[str]:
    """The ``def`` line of a compiled function, its parameters on a line of their own if long."""
    pragma = ":  # pragma: no cover - compiled"
    line = f"def {name}({params}){pragma}"
    return [line] if len(line) <= LINE_LENGTH else [f"def {name}(", f"    {params}", f"){pragma}"]


def _load(indent: str, symbols: list[sp.Symbol], source: dict[sp.Symbol, str], names: dict) -> list[str]:
    return [f"{indent}{names.get(s, s.name)} = {source[s]}" for s in symbols]


def emit_rhs(d: Derivation) -> str:
    """The numba right-hand side ``{key}_derived_rhs(t, x, u, p, dx, nb)`` of one model: its
    column function (the Euler-Lagrange equations of one variant) and the loop over the batch."""
    names = _code_names()
    lower = [(i, j) for i in range(len(d.q)) for j in range(i + 1)]
    zero = [[d.mass[i, j] == 0 for j in range(len(d.q))] for i in range(len(d.q))]
    entries = [d.mass[i, j] for i, j in lower if not zero[i][j]]
    repl, reduced = _cse([*entries, *list(d.b)], "w")
    angles = _trig_arguments([*(e for _, e in repl), *reduced], d.states)
    angle_names = [(names.get(q, q.name), i) for q, i in angles]
    trig = ", ".join(f"sin_{name}, cos_{name}" for name, _ in angle_names)
    return _emit_column(d, names, zero, repl, reduced, trig) + "\n\n" + _emit_batch(d, angle_names, trig)


def _emit_column(
    d: Derivation,
    names: dict[sp.Symbol, str],
    zero: list[list[bool]],
    repl: list[tuple[sp.Symbol, sp.Expr]],
    reduced: list[sp.Expr],
    trig: str,
) -> str:
    """``_{key}_derived_column(b, x, u, p, dx, sin_q, cos_q, ...)``: the accelerations q'' of
    column b, dx[1::2, b], from M(q) q'' = b(q, q', u), given sin and cos of its angles
    (``trig``: those parameters; inlined into the batch loop)."""
    key, n, head = d.spec.key, len(d.q), "    "
    printer = _Printer(None, names)
    nonzero = [(i, j) for i in range(n) for j in range(i + 1) if not zero[i][j]]
    mass_out = dict(zip(nonzero, reduced[: len(nonzero)], strict=True))
    used = set()
    for e in [*(e for _, e in repl), *reduced]:
        used |= e.xreplace({f: sp.Dummy() for f in e.atoms(sp.sin, sp.cos)}).free_symbols
    source = {s: f"p[{i}, b]" for i, s in enumerate(d.params)}
    source.update({s: f"x[{i}, b]" for i, s in enumerate(d.states)})
    source.update({s: f"u[{i}, b]" for i, s in enumerate(d.u)})
    order = [*d.params, *d.states, *d.u]
    lines = [
        '@njit(cache=True, inline="always", error_model="numpy")',
        *_def(f"_{key}_derived_column", f"b, x, u, p, dx, {trig}"),
        f'{head}"""q\'\' = dx[1::2, b] of {key}_derived_rhs for column (variant) b, given sin and cos of its',
        f'{head}angles."""',
    ]
    lines += _load(head, [s for s in order if s in used], source, names)
    for sym, e in repl:
        lines += _assign(head, sym.name, printer.code(e))
    lines.append(f"{head}# mass matrix M(q) (lower triangle, structural zeros omitted)")
    for (i, j), e in mass_out.items():
        lines += _assign(head, f"m{i}{j}", printer.code(e))
    lines.append(f"{head}# b(q, q', u) = Q(u) - C(q, q') q' - dV/dq")
    for i, e in enumerate(reduced[len(nonzero) :]):
        lines += _assign(head, f"b{i}", printer.code(e))
    lines += _ldl_solve(n, zero, head)
    lines += [f"{head}dx[{2 * i + 1}, b] = a{i}" for i in range(n)]
    return "\n".join(lines) + "\n"


def _emit_batch(d: Derivation, angles: list[tuple[str, int]], trig: str) -> str:
    """``{key}_derived_rhs``: the velocities q' copied, then the column function for each of
    the first nb columns, sin and cos of the angles from :mod:`nlcx.kernel.trig` for the whole
    batch at once, one variant at a time below ``COLUMN_ROWS`` variants.

    The copies have a loop of their own: with their stores in it, the loop of the x-y and
    x-y-z pendulums needs more run-time alias checks than LLVM makes, and stays scalar."""
    key, head = d.spec.key, "    "
    ind = head * 2
    column = f"_{key}_derived_column"
    # sin and cos of angle a go to the rows 4a + 1 and 4a + 3 of dx, rows of q'' that the column
    # function writes only after it has read them (its arguments)
    rows = [(4 * a + 1, 4 * a + 3) for a in range(len(angles))]
    if rows and rows[-1][1] > 2 * len(d.q) - 1:
        raise ValueError(f"{key}: {len(angles)} angles need {2 * len(angles)} rows of q'', it has {len(d.q)}")
    batch_trig = ", ".join(f"dx[{s}, b], dx[{c}, b]" for s, c in rows)
    lines = [
        '@hot_njit(cache=True, error_model="numpy")',
        f"def {key}_derived_rhs(t, x, u, p, dx, nb):  # pragma: no cover - compiled",
        f'{head}"""The {d.spec.title} derived from {d.spec.source}.\n',
        f"{head}Column b of x is one variant: state ({', '.join(s.name for s in d.states)}),",
        f"{head}input ({', '.join(s.name for s in d.u)}), p[:, b] = (M, m, l, g). Solves M(q) q'' = b(q, q', u)",
        f"{head}for the first nb columns; the others are neither read nor written.",
        f"{head}sin and cos of the angles from nlcx.kernel.trig: for the whole batch in vector code,",
        f"{head}into rows of dx that receive q'' later, or one at a time for fewer than COLUMN_ROWS",
        f"{head}variants (the same bits either way). Nothing is allocated: compiled without numba's",
        f"{head}reference counting.",
        f'{head}"""',
        f"{head}for b in range(nb):  # the coordinates' derivatives are their rates",
        *(f"{ind}dx[{2 * i}, b] = x[{2 * i + 1}, b]" for i in range(len(d.q))),
        f"{head}if nb < COLUMN_ROWS:",
        f"{ind}for b in range(nb):",
        *(f"{ind}{head}sin_{name}, cos_{name} = sincos(x[{i}, b])" for name, i in angles),
        f"{ind}{head}{column}(b, x, u, p, dx, {trig})",
        f"{ind}return",
        *(f"{head}sincos_column(x[{i}], nb, dx[{s}], dx[{c}])" for (_, i), (s, c) in zip(angles, rows, strict=True)),
        f"{head}for b in range(nb):",
        f"{ind}{column}(b, x, u, p, dx, {batch_trig})",
    ]
    return "\n".join(lines) + "\n"


def _trig_arguments(exprs: list[sp.Expr], states: tuple[sp.Symbol, ...]) -> list[tuple[sp.Symbol, int]]:
    """The states whose sin or cos the expressions take, with their index in the state, in
    state order (each gets one :func:`nlcx.kernel.trig.sincos_column` per call)."""
    args = {f.args[0] for e in exprs for f in e.atoms(sp.sin, sp.cos)}
    unknown = args - set(states)
    if unknown:
        raise ValueError(f"sin/cos of {sorted(map(str, unknown))}: the kernel takes them of states only")
    return [(q, i) for i, q in enumerate(states) if q in args]


def emit_energy(d: Derivation) -> str:
    """The numpy function ``{key}_energy(x, p)``: E = T + V over the last axis of x."""
    key = d.spec.key
    names = _code_names()
    printer = _Printer("np", names)
    repl, (reduced,) = _cse([d.energy], "w")
    used = set(reduced.free_symbols)
    for _, e in repl:
        used |= e.free_symbols
    source = {s: f"p[{i}]" for i, s in enumerate(d.params)}
    source.update({s: f"x[..., {i}]" for i, s in enumerate(d.states)})
    order = [*d.params, *d.states]
    ind = "    "
    lines = [
        "def " + f"{key}_energy(x: np.ndarray, p: Sequence[float]) -> np.ndarray:",
        f'{ind}"""E = K.E. + P.E. of the {d.spec.title} ({d.spec.energy_eqs}).\n\n'
        f"{ind}x holds the state ({', '.join(s.name for s in d.states)}) on its last axis;\n"
        f"{ind}leading (batch, time) axes are kept. p = (M, m, l, g).\n"
        f'{ind}"""',
        f"{ind}x = np.asarray(x, dtype=float)",
    ]
    lines += _load(ind, [s for s in order if s in used], source, names)
    for sym, e in repl:
        lines += _assign(ind, sym.name, printer.doprint(e))
    lines += _assign(ind, "energy", printer.doprint(reduced))
    lines.append(f"{ind}return energy")
    return "\n".join(lines) + "\n"


HEADER = f'''"""Equations of motion of the four inverted pendulums, derived from the thesis's Lagrangians.

GENERATED by ``{COMMAND}`` -- do not edit; rerun the script instead.

Each ``*_derived_rhs(t, x, u, p, dx, nb)`` (numba, ``nlcx.kernel.abi.RHS_SIG``; compiled when
a run first uses it) evaluates, for each of the first nb columns (variants) b of x, the mass
matrix M(q) and b(q, q', u) = Q(u) - C(q, q') q' - dV/dq of the Euler-Lagrange equations and
solves M q'' = b by an unrolled LDL^T factorisation; p[:, b] = (M, m, l, g). Squares are
written as products, which vectorise over the columns (the bits of numba's ``**``). Each
``*_energy(x, p)`` is the total energy T + V, vectorised over leading axes of x.
"""
'''


def emit_module() -> str:
    """The full text of ``nlcx/plants/generated/pendulums.py``."""
    derivations = [derive(k, simplify=True) for k in MODELS]
    parts = [
        HEADER,
        "from __future__ import annotations\n",
        "from collections.abc import Sequence\n",
        "import numpy as np\nfrom numba import njit\n",
        "from nlcx._numba_compat import hot_njit\nfrom nlcx.kernel.trig import COLUMN_ROWS, sincos, sincos_column\n",
    ]
    text = "\n".join(parts)
    for d in derivations:
        text += "\n\n" + emit_rhs(d)
    for d in derivations:
        text += "\n\n" + emit_energy(d)
    text = re.sub(r"[ \t]+\n", "\n", text)
    too_long = [ln for ln in text.splitlines() if len(ln) > LINE_LENGTH]
    if too_long:
        raise ValueError(f"emitted lines longer than {LINE_LENGTH}: {too_long[:2]}")
    return text


def emit_init() -> str:
    """The text of ``nlcx/plants/generated/__init__.py``."""
    return f'"""Code generated by ``{COMMAND}`` (do not edit): see ``pendulums.py``."""\n'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed files only")
    args = parser.parse_args(argv)
    outputs = {TARGET: emit_module(), INIT: emit_init()}
    if args.check:
        stale = [p for p, text in outputs.items() if not p.exists() or p.read_text() != text]
        for p in stale:
            print(f"out of date: {p.relative_to(ROOT)}")
        return 1 if stale else 0
    TARGET.parent.mkdir(parents=True, exist_ok=True)
    for p, text in outputs.items():
        p.write_text(text)
        print(f"wrote {p.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

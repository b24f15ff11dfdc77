"""sin and cos of the pendulums' angles, the same bits on every code path.

The plants' right-hand sides take sin and cos of their angles for every variant of a batch at
every Runge-Kutta stage. libm's ``sin``/``cos`` are scalar calls that the compiler cannot
vectorise, so :func:`sincos_column` evaluates them with the FreeBSD msun (fdlibm) algorithm
written out in plain arithmetic, which the compiler turns into vector code over the batch:

- argument reduction x = n pi/2 + (y0 + y1), pi/2 split in three parts (``e_rem_pio2.c``,
  its second iteration, good to about 118 bits before cancellation);
- the kernels ``__kernel_sin`` and ``__kernel_cos`` (``k_sin.c``, ``k_cos.c``) on
  |y0| <= pi/4 with the tail y1;
- the quadrant n mod 4 picks and signs the results.

Deterministic by construction: the vector loop and its scalar remainder run the same
operations in the same order (no fused multiply-add, no fast-math), so an angle gets the same
bits in a batch of 1 and of 1 000, and from :func:`sincos` (one angle at a time: small
batches, the printed equations). Angles with |x| > :data:`REDUCTION_LIMIT` or not finite go to
libm (the angle decides, not the batch). Accuracy: within 1 ulp of libm and below 1 ulp of the
true value (``tests/test_trig.py``); what it changed: ``docs/assumptions.md`` A30.
"""

from __future__ import annotations

import math

from numba import njit

from nlcx._numba_compat import hot_njit
from nlcx.kernel.signatures import FloatArray

#: Batches of at least this many variants take :func:`sincos_column`; smaller ones call
#: :func:`sincos` per variant. Below it the column's fixed costs (its work array, and no full
#: AVX-512 vector of 8 angles) outweigh what vector code saves; both paths give the same bits.
COLUMN_ROWS = 8
#: Beyond this |x| (rad) the two-part reduction is not trusted; libm takes over.
REDUCTION_LIMIT = 1.0e5
#: Below this |x| (rad; pi/4 = 0.785...) x 2/pi + 1/2 lies in (0, 1), so the reduction is
#: the identity, and :func:`sincos` skips it.
NO_REDUCTION = 0.78
#: Below this |x| sin x = x and cos x = 1 to the last bit (and sin keeps the sign of zero).
TINY = 2.0**-27

INV_PIO2 = 6.36619772367581382433e-01  # 2/pi
PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
PIO2_2 = 6.07710050630396597660e-11  # second 33 bits of pi/2
PIO2_2T = 2.02226624879595063154e-21  # pi/2 - (PIO2_1 + PIO2_2)

# __kernel_sin: sin(x) ~ x + S1 x^3 + ... + S6 x^13 on |x| <= pi/4
S1 = -1.66666666666666324348e-01
S2 = 8.33333333332248946124e-03
S3 = -1.98412698298579493134e-04
S4 = 2.75573137070700676789e-06
S5 = -2.50507602534068634195e-08
S6 = 1.58969099521155010221e-10
# __kernel_cos: cos(x) ~ 1 - x^2/2 + C1 x^4 + ... + C6 x^14 on |x| <= pi/4
C1 = 4.16666666666666019037e-02
C2 = -1.38888888888741095749e-03
C3 = 2.48015872894767294178e-05
C4 = -2.75573143513906633035e-07
C5 = 2.08757232129817482790e-09
C6 = -1.13596475577881948265e-11


@njit(cache=True, inline="always", error_model="numpy")
def _kernel_sin(x: float, y: float) -> float:  # pragma: no cover - compiled
    """sin(x + y) for |x| <= pi/4, y the tail of x (msun k_sin.c)."""
    z = x * x
    w = z * z
    r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6)
    v = z * x
    return x - ((z * (0.5 * y - v * r) - y) - v * S1)


@njit(cache=True, inline="always", error_model="numpy")
def _kernel_cos(x: float, y: float) -> float:  # pragma: no cover - compiled
    """cos(x + y) for |x| <= pi/4, y the tail of x (msun k_cos.c)."""
    z = x * x
    w = z * z
    r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


@njit(cache=True, inline="always", error_model="numpy")
def _sincos_of(x: float, y0: float, y1: float, n: int) -> tuple[float, float]:  # pragma: no cover - compiled
    """(sin x, cos x) from the reduction x = n pi/2 + (y0 + y1), n mod 4 the quadrant."""
    s = _kernel_sin(y0, y1)
    c = _kernel_cos(y0, y1)
    swap = (n & 1) == 1
    sin_x = c if swap else s
    cos_x = s if swap else c
    sin_x = -sin_x if (n & 2) != 0 else sin_x
    cos_x = -cos_x if ((n + 1) & 2) != 0 else cos_x
    tiny = abs(x) < TINY
    return (x if tiny else sin_x), (1.0 if tiny else cos_x)


@njit(cache=True, inline="always", error_model="numpy")
def _sincos_reduced(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """(sin x, cos x) for |x| <= :data:`REDUCTION_LIMIT` in branch-free arithmetic (the
    module docstring); the caller sends larger or non-finite x to libm."""
    fn = math.floor(x * INV_PIO2 + 0.5)
    r = x - fn * PIO2_1
    w = fn * PIO2_2
    head = r - w
    w = fn * PIO2_2T - ((r - head) - w)
    y0 = head - w
    y1 = (head - y0) - w
    return _sincos_of(x, y0, y1, int(fn) & 3)


@hot_njit(cache=True, error_model="numpy")
def sincos_column(
    angles: FloatArray, nb: int, sines: FloatArray, cosines: FloatArray
) -> None:  # pragma: no cover - compiled
    """sines[b] = sin angles[b], cosines[b] = cos angles[b] for the first nb angles.

    The three are contiguous (an angle's row of a plant's (n, B) state, and two rows of its
    (n, B) derivative that it writes later, one entry a variant), so the loop over them reads
    and writes contiguous memory and vectorises; angles outside the reduction's range then
    get libm's values. Nothing is allocated, and the function is compiled without numba's
    reference counting (a noticeable share of a plant's right-hand side otherwise)."""
    for b in range(nb):
        sines[b], cosines[b] = _sincos_reduced(angles[b])
    for b in range(nb):
        a = angles[b]
        if not abs(a) <= REDUCTION_LIMIT:
            sines[b], cosines[b] = math.sin(a), math.cos(a)


@njit(cache=True, inline="always", error_model="numpy")
def sincos(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """(sin x, cos x) of one angle, the same bits as :func:`sincos_column` gives it.

    Below :data:`NO_REDUCTION` the reduction is skipped: there it yields n = 0, y0 = x and
    y1 = +0.0 exactly (fn = 0, and each step subtracts or adds a zero), so the kernels get the
    same arguments. One angle at a time, the reduction's floor, conversion and selects were
    most of the cost (an upright pendulum's angles are all below it)."""
    if abs(x) < NO_REDUCTION:
        return _sincos_of(x, x, 0.0, 0)
    if abs(x) <= REDUCTION_LIMIT:
        return _sincos_reduced(x)
    return math.sin(x), math.cos(x)

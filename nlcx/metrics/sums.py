"""The trapezoidal sums of the metrics, added up as numpy adds up an array.

An integral criterion is a sum of trapezoids, one per step between samples k and k+1 of a
row. numpy sums an array pairwise (``np.add.reduce``: blocks of at most 128 terms, each added
in eight interleaved partial sums, the halves of a longer range summed apart and then added).
:func:`pairwise_sums` adds the terms in that order without forming them as an array, so a sum
here is numpy's to the last bit (tests/test_metrics_kernels.py holds it against ``np.sum``),
on the CPU and, compiled from this source, on the GPU: the two agree bit for bit.

The terms, sample pair (k, k+1), dt = t_{k+1} - t_k, by ``kind``:

- :data:`ERRORS`: e = ref - y, |e| and tau = t - start: ((e_{k+1}^2 + e_k^2) / 2) dt,
  ((|e_{k+1}| + |e_k|) / 2) dt and ((tau_{k+1} |e_{k+1}| + tau_k |e_k|) / 2) dt (ISE, IAE, ITAE);
- :data:`TRAPEZOID`: ((y_{k+1} + y_k) / 2) dt (the integral of y);
- :data:`INPUT`: ((u_{k+1}^2 + u_k^2) / 2) dt and |u_{k+1} - u_k| (effort, total variation).

The ranges still to be added are kept on a small stack (:func:`stack`): the depth grows with
the logarithm of the row's length, 64 levels hold any row. Only compiled code calls these
functions: they are compiled without the wrappers that would let Python call them
(:func:`nlcx._numba_compat.inner_njit`).

:func:`pairwise_sums` takes ``kind`` as an int64 (callers pass ``np.int64(ERRORS)``, ...: a
literal would compile it once per kind) and calls :func:`_block_sums` with each kind as a
constant, so numba compiles :func:`_block_sums` and :func:`_terms` once per kind, with the
other kinds' branches removed: the block's loop then runs in vector code, several times faster
than with a ``kind`` known only at run time. :func:`_terms` is a compiled function of its own, which
LLVM inlines into the block's loop; inlined by numba (``inline="always"``) at each of its
eighteen call sites, the block would be typed eighteen times over and take several times longer
to compile, for the same machine code.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from nlcx._numba_compat import inner_njit
from nlcx.kernel.signatures import FloatArray, IntArray, Sums

ERRORS, TRAPEZOID, INPUT = 0, 1, 2
#: Terms numpy adds one by one, and the most it adds in eight partial sums.
_UNROLL, _BLOCK = 8, 128
#: Levels of the stack: a range of n terms is halved until it has at most _BLOCK terms.
DEPTH = 64


def stack() -> tuple[np.ndarray, np.ndarray]:
    """The work space of :func:`pairwise_sums`: (ranges (DEPTH, 3) int64, partial sums (DEPTH, 3))."""
    return np.zeros((DEPTH, 3), dtype=np.int64), np.zeros((DEPTH, 3))


@inner_njit(cache=True, error_model="numpy")
def _terms(
    kind: int, t: FloatArray, y: FloatArray, ref: FloatArray, start: float, k: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """The terms of sample pair (k, k+1) for ``kind`` (module docstring); unused ones 0."""
    dt = t[k + 1] - t[k]
    if kind == ERRORS:
        e0, e1 = ref[k] - y[k], ref[k + 1] - y[k + 1]
        a0, a1 = abs(e0), abs(e1)
        weighted = (((t[k + 1] - start) * a1 + (t[k] - start) * a0) * 0.5) * dt
        return ((e1 * e1 + e0 * e0) * 0.5) * dt, ((a1 + a0) * 0.5) * dt, weighted
    if kind == TRAPEZOID:
        return ((y[k + 1] + y[k]) * 0.5) * dt, 0.0, 0.0
    u0, u1 = y[k], y[k + 1]
    return ((u1 * u1 + u0 * u0) * 0.5) * dt, abs(u1 - u0), 0.0


@inner_njit(cache=True, error_model="numpy")
def _block_sums(
    kind: int, t: FloatArray, y: FloatArray, ref: FloatArray, start: float, lo: int, n: int
) -> Sums:  # pragma: no cover - compiled
    """The sums of the terms lo .. lo+n-1 (n <= 128) as numpy adds a block: one by one below
    eight terms, else in eight interleaved partial sums ((r0 + r1) + (r2 + r3)) + ((r4 + r5) +
    (r6 + r7)) and the rest one by one."""
    if n < _UNROLL:
        s0, s1, s2 = 0.0, 0.0, 0.0
        for k in range(lo, lo + n):
            a, b, c = _terms(kind, t, y, ref, start, k)
            s0 += a
            s1 += b
            s2 += c
        return s0, s1, s2
    p0, q0, r0 = _terms(kind, t, y, ref, start, lo)
    p1, q1, r1 = _terms(kind, t, y, ref, start, lo + 1)
    p2, q2, r2 = _terms(kind, t, y, ref, start, lo + 2)
    p3, q3, r3 = _terms(kind, t, y, ref, start, lo + 3)
    p4, q4, r4 = _terms(kind, t, y, ref, start, lo + 4)
    p5, q5, r5 = _terms(kind, t, y, ref, start, lo + 5)
    p6, q6, r6 = _terms(kind, t, y, ref, start, lo + 6)
    p7, q7, r7 = _terms(kind, t, y, ref, start, lo + 7)
    i = _UNROLL
    whole = n - n % _UNROLL
    while i < whole:
        k = lo + i
        a, b, c = _terms(kind, t, y, ref, start, k)
        p0, q0, r0 = p0 + a, q0 + b, r0 + c
        a, b, c = _terms(kind, t, y, ref, start, k + 1)
        p1, q1, r1 = p1 + a, q1 + b, r1 + c
        a, b, c = _terms(kind, t, y, ref, start, k + 2)
        p2, q2, r2 = p2 + a, q2 + b, r2 + c
        a, b, c = _terms(kind, t, y, ref, start, k + 3)
        p3, q3, r3 = p3 + a, q3 + b, r3 + c
        a, b, c = _terms(kind, t, y, ref, start, k + 4)
        p4, q4, r4 = p4 + a, q4 + b, r4 + c
        a, b, c = _terms(kind, t, y, ref, start, k + 5)
        p5, q5, r5 = p5 + a, q5 + b, r5 + c
        a, b, c = _terms(kind, t, y, ref, start, k + 6)
        p6, q6, r6 = p6 + a, q6 + b, r6 + c
        a, b, c = _terms(kind, t, y, ref, start, k + 7)
        p7, q7, r7 = p7 + a, q7 + b, r7 + c
        i += _UNROLL
    s0 = ((p0 + p1) + (p2 + p3)) + ((p4 + p5) + (p6 + p7))
    s1 = ((q0 + q1) + (q2 + q3)) + ((q4 + q5) + (q6 + q7))
    s2 = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        a, b, c = _terms(kind, t, y, ref, start, lo + i)
        s0 += a
        s1 += b
        s2 += c
        i += 1
    return s0, s1, s2


@njit(cache=True, inline="always", error_model="numpy")
def _left_half(n: int) -> int:  # pragma: no cover - compiled
    """The terms of the first half of a range numpy splits: n/2, down to a multiple of eight."""
    half = n // 2
    return half - half % _UNROLL


@inner_njit(cache=True, error_model="numpy")
def pairwise_sums(
    kind: int,
    t: FloatArray,
    y: FloatArray,
    ref: FloatArray,
    start: float,
    lo: int,
    n: int,
    ranges: IntArray,
    partial: FloatArray,
) -> Sums:  # pragma: no cover - compiled
    """The sums of the terms lo .. lo+n-1 of ``kind`` (the module docstring), each as
    ``np.sum`` adds the array of its terms (an empty sum is 0). ``ranges`` and ``partial`` are
    the work space (:func:`stack`): a range waiting for its halves holds (first term, number of
    terms, halves done) and the sums of its first half."""
    top = 0
    ranges[0, 0], ranges[0, 1], ranges[0, 2] = lo, n, 0
    while True:
        count = ranges[top, 1]
        if count > _BLOCK:  # halve: the first half next
            ranges[top + 1, 0], ranges[top + 1, 1], ranges[top + 1, 2] = ranges[top, 0], _left_half(count), 0
            top += 1
            continue
        lo_block = ranges[top, 0]
        if kind == ERRORS:  # each kind's block sums compiled apart (a constant kind: vector code)
            s0, s1, s2 = _block_sums(ERRORS, t, y, ref, start, lo_block, count)
        elif kind == TRAPEZOID:
            s0, s1, s2 = _block_sums(TRAPEZOID, t, y, ref, start, lo_block, count)
        else:
            s0, s1, s2 = _block_sums(INPUT, t, y, ref, start, lo_block, count)
        while True:  # hand the sums to the range waiting for them
            top -= 1
            if top < 0:
                return 0.0 + s0, 0.0 + s1, 0.0 + s2  # np.add.reduce starts from its identity, 0
            if ranges[top, 2] == 0:  # the first half is done: keep it, do the second
                partial[top, 0], partial[top, 1], partial[top, 2] = s0, s1, s2
                ranges[top, 2] = 1
                half = _left_half(ranges[top, 1])
                top += 1
                ranges[top, 0], ranges[top, 1], ranges[top, 2] = ranges[top - 1, 0] + half, ranges[top - 1, 1] - half, 0
                break
            s0, s1, s2 = partial[top, 0] + s0, partial[top, 1] + s1, partial[top, 2] + s2

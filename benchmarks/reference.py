"""The limit reference of benchmark (b): the same closed loop, hand-written.

The x inverted pendulum (eqs. 2.8-2.11 as nlcx derives them from the Lagrangian) under two
error-AGS PID loops (eqs. 2.20-2.22 on |e|; F = -PID_theta + PID_x), the unit step in x at
t = 0, classic RK4 at dt with the force held over the step, every variant of a batch
integrated on its own in plain scalar code: the state, the loop states and the parameters
live in local variables, the right-hand side and the schedules are written out, sin, cos and
exp are libm's (nlcx's kernel takes sin and cos from :mod:`nlcx.kernel.trig`, within 1 ulp of
libm's, so the two trajectories differ by rounding). A run stops when |theta| exceeds its bound
or a state is not finite, as nlcx's does. Like nlcx, it records the state and the input at every sample (the metrics are
computed from them); ``record=False`` measures the loop alone.

It is not part of nlcx: it exists to say how fast this one loop can be simulated on this
machine, so that nlcx's speed is quoted as a ratio to it, measured in the same run. Its PID and
plant are its own hand-written copies, kept only as the independent check they are: nothing
here imports nlcx's PID or plant code, and ``tests/test_reference_loops.py`` holds the loops
against nlcx's runs (to the bit where they use nlcx's sin and cos).

:func:`simulate_nlcx_pid` is the same loop with its PID reading nlcx's packed parameter and
state rows (through nlcx's layout declarations) and nlcx's sin and cos (one angle at a time),
so that it computes nlcx's bits: it measures how much of the distance between nlcx's kernel and
the limit is the kernel's design (every variant in lock step, states in arrays, sin and cos in
vector code, plant and controller called as compiled-function values).
:func:`simulate_lockstep` is the limit's loop stepped as nlcx's kernel steps a batch, every
variant together, with nlcx's sin and cos: nlcx's bits at the speed a kernel with the plant and
the PID compiled into it would have.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit

from nlcx import compiled_cache

compiled_cache.ready()  # before nlcx's compiled functions are loaded from numba's cache

from nlcx._numba_compat import hot_njit  # noqa: E402
from nlcx.controllers.pid import DIRECT_ERROR_AGS, FORMS, H, I, L, S, structure_of  # noqa: E402
from nlcx.controllers.schedules import EA, ERROR_AGS  # noqa: E402
from nlcx.kernel.trig import _sincos_reduced, sincos  # noqa: E402
from nlcx.layout import Layout  # noqa: E402

# numba keys this module's cache on this file alone, but its loops inline nlcx's sin and cos and
# read nlcx's layout offsets as constants: a change to nlcx would otherwise leave the old code in
# the cache (and in the timings)
compiled_cache.ensure_consistent(Path(__file__).resolve().parent, depends=(compiled_cache.PACKAGE,))

#: Where :func:`_rhs` takes sin and cos from.
LIBM, NLCX, NLCX_VECTOR = 0, 1, 2
#: An error-AGS loop's parameters, in this order (Table 2.2 ranges, section 2.3 rates).
AGS = ("kp_min", "kp_max", "ki_min", "ki_max", "kd_min", "kd_max", "kp_rate", "ki_rate", "kd_rate")


@njit(cache=True, error_model="numpy", inline="always")
def _ags(s, a):  # pragma: no cover - compiled
    """(k_p, k_i, k_d) of eqs. 2.20-2.22 at s = |e|; one exponential per distinct rate."""
    a_p = math.exp(-a[6] * s)
    a_i = a_p if a[7] == a[6] else math.exp(-a[7] * s)
    if a[8] == a[6]:
        a_d = a_p
    elif a[8] == a[7]:
        a_d = a_i
    else:
        a_d = math.exp(-a[8] * s)
    return a[1] - (a[1] - a[0]) * a_p, a[2] - (a[2] - a[3]) * a_i, a[5] - (a[5] - a[4]) * a_d


@njit(cache=True, error_model="numpy", inline="always")
def _rhs(M, m, l, g, th, thd, F, trig):  # pragma: no cover - compiled
    """(x'', theta'') of the x pendulum, the mass matrix solved as nlcx's generated code does;
    sin and cos from libm (``trig`` = :data:`LIBM`), nlcx's one angle at a time
    (:func:`nlcx.kernel.trig.sincos`, :data:`NLCX`) or nlcx's reduction without branches
    (:data:`NLCX_VECTOR`, the same bits for |theta| <= 1e5 rad, where nlcx's vector code uses it)."""
    if trig == NLCX:
        sin_th, cos_th = sincos(th)
    elif trig == NLCX_VECTOR:
        sin_th, cos_th = _sincos_reduced(th)
    else:
        sin_th, cos_th = math.sin(th), math.cos(th)
    w0 = l * m
    w1 = w0 * sin_th
    m00 = M + m
    m10 = w0 * cos_th
    m11 = l**2 * m
    b0 = F + thd**2 * w1
    b1 = g * w1
    r0 = 1.0 / m00
    L10 = m10 * r0
    r1 = 1.0 / (m11 - L10 * L10 * m00)
    a1 = (b1 - L10 * b0) * r1
    return b0 * r0 - L10 * a1, a1


@njit(cache=True, error_model="numpy", inline="always")
def _rk4(M, m, l, g, x, xd, th, thd, F, dt, trig):  # pragma: no cover - compiled
    """One classic RK4 step of size dt with F held: the state at t + dt (sin and cos by ``trig``)."""
    a1, t1 = _rhs(M, m, l, g, th, thd, F, trig)
    a2, t2 = _rhs(M, m, l, g, th + 0.5 * dt * thd, thd + 0.5 * dt * t1, F, trig)
    a3, t3 = _rhs(M, m, l, g, th + 0.5 * dt * (thd + 0.5 * dt * t1), thd + 0.5 * dt * t2, F, trig)
    th4 = th + dt * (thd + 0.5 * dt * t2)
    a4, t4 = _rhs(M, m, l, g, th4, thd + dt * t3, F, trig)
    v2, v3, v4 = xd + 0.5 * dt * a1, xd + 0.5 * dt * a2, xd + dt * a3
    w2, w3, w4 = thd + 0.5 * dt * t1, thd + 0.5 * dt * t2, thd + dt * t3
    return (
        x + dt / 6.0 * (xd + 2.0 * (v2 + v3) + v4),
        xd + dt / 6.0 * (a1 + 2.0 * (a2 + a3) + a4),
        th + dt / 6.0 * (thd + 2.0 * (w2 + w3) + w4),
        thd + dt / 6.0 * (t1 + 2.0 * (t2 + t3) + t4),
    )


@njit(cache=True, error_model="numpy", inline="always")
def _stops(x, xd, th, thd, bound):  # pragma: no cover - compiled
    """Whether a run stops here: |theta| past its bound or a state not finite."""
    return not (abs(th) <= bound and math.isfinite(x) and math.isfinite(xd) and math.isfinite(thd))


@njit(cache=True, error_model="numpy")
def simulate(p, theta_loop, x_loop, dt, n_steps, bound, X, U, n_valid, record):  # pragma: no cover - compiled
    """Every variant b (p[b] = M, m, l, g) from rest to t = n_steps dt; X (B, K+1, 4) and U
    (B, K+1) written when ``record``; n_valid[b] the samples before the run stopped."""
    for b in range(p.shape[0]):
        M, m, l, g = p[b, 0], p[b, 1], p[b, 2], p[b, 3]
        x, xd, th, thd = 0.0, 0.0, 0.0, 0.0
        i_th, i_x, e_th_prev, e_x_prev = 0.0, 0.0, 0.0, 0.0
        n_valid[b] = n_steps + 1
        for k in range(n_steps + 1):
            e_th = 0.0 - th
            e_x = 1.0 - x
            if k == 0:
                e_th_prev, e_x_prev = e_th, e_x
            d_th = (e_th - e_th_prev) / dt
            d_x = (e_x - e_x_prev) / dt
            kp, ki, kd = _ags(abs(e_th), theta_loop)
            i_th += e_th * dt
            F = -(kp * e_th + i_th * ki + kd * d_th)
            kp, ki, kd = _ags(abs(e_x), x_loop)
            i_x += e_x * dt
            F += kp * e_x + i_x * ki + kd * d_x
            e_th_prev, e_x_prev = e_th, e_x
            if record:
                X[b, k, 0], X[b, k, 1], X[b, k, 2], X[b, k, 3] = x, xd, th, thd
                U[b, k] = F
            if k == n_steps:
                break
            x, xd, th, thd = _rk4(M, m, l, g, x, xd, th, thd, F, dt, LIBM)
            if _stops(x, xd, th, thd, bound):
                n_valid[b] = k + 1
                break


#: The rows of :func:`simulate_lockstep`'s work array: one quantity over the batch per row.
LOCKSTEP_ROWS = Layout(
    "LockstepRows",
    ("x", "x_dot", "theta", "theta_dot", "i_theta", "i_x", "e_theta_prev", "e_x_prev", "M", "m", "l", "g"),
)
Q = LOCKSTEP_ROWS.at


@njit(cache=True, error_model="numpy")
def _leave(nb, vid, stopped, n_valid, samples, q):  # pragma: no cover - compiled
    """Move the stopped variants behind the active ones: a stopped one trades places with the
    last active one in q (a column per variant) and gets its number of valid samples; returns
    the number still active."""
    b = 0
    while b < nb:
        if not stopped[b]:
            b += 1
            continue
        n_valid[vid[b]] = samples
        nb -= 1
        for i in range(q.shape[0]):
            q[i, b] = q[i, nb]
        vid[b], stopped[b] = vid[nb], stopped[nb]
    return nb


@njit(cache=True, error_model="numpy")
def simulate_lockstep(p, theta_loop, x_loop, dt, n_steps, bound, X, U, n_valid):  # pragma: no cover - compiled
    """:func:`simulate`'s loop (the written-out PID and plant) with every variant of the batch
    stepped together, as nlcx's kernel steps them: at each sample the PID of every active
    variant, their records, then one RK4 step of each; every quantity an array over the batch
    (a row of q, :data:`LOCKSTEP_ROWS`); a variant that stops trades places with the last active
    one. The step has no branch (sin and cos by nlcx's reduction, not its libm fallback beyond
    1e5 rad, which no angle of these runs comes near), so the compiler steps several variants at
    once in vector code; the PID's exponentials stay libm's calls.

    It computes nlcx's bits (``tests/test_reference_loops.py`` and the benchmark check) and
    measures what nlcx's lock-step kernel would cost if the plant and the controller were
    compiled into it instead of called as compiled-function values with their parameters and
    states in packed arrays."""
    n_batch = p.shape[0]
    q = np.zeros((len(Q), n_batch))
    for b in range(n_batch):
        q[Q.M, b], q[Q.m, b], q[Q.l, b], q[Q.g, b] = p[b, 0], p[b, 1], p[b, 2], p[b, 3]
        n_valid[b] = n_steps + 1
    vid, stopped, F = np.arange(n_batch), np.zeros(n_batch, dtype=np.bool_), np.empty(n_batch)
    x, xd, th, thd = q[Q.x], q[Q.x_dot], q[Q.theta], q[Q.theta_dot]
    i_th, i_x, e_th_prev, e_x_prev = q[Q.i_theta], q[Q.i_x], q[Q.e_theta_prev], q[Q.e_x_prev]
    M, m, l, g = q[Q.M], q[Q.m], q[Q.l], q[Q.g]
    nb = n_batch
    for k in range(n_steps + 1):
        for b in range(nb):
            e_th = 0.0 - th[b]
            e_x = 1.0 - x[b]
            if k == 0:
                e_th_prev[b], e_x_prev[b] = e_th, e_x
            kp, ki, kd = _ags(abs(e_th), theta_loop)
            i_th[b] += e_th * dt
            f = -(kp * e_th + i_th[b] * ki + kd * ((e_th - e_th_prev[b]) / dt))
            kp, ki, kd = _ags(abs(e_x), x_loop)
            i_x[b] += e_x * dt
            F[b] = f + (kp * e_x + i_x[b] * ki + kd * ((e_x - e_x_prev[b]) / dt))
            e_th_prev[b], e_x_prev[b] = e_th, e_x
            v = vid[b]
            X[v, k, 0], X[v, k, 1], X[v, k, 2], X[v, k, 3] = x[b], xd[b], th[b], thd[b]
            U[v, k] = F[b]
        if k == n_steps:
            break
        n_stop = 0
        for b in range(nb):  # no branch: vector code
            x[b], xd[b], th[b], thd[b] = _rk4(M[b], m[b], l[b], g[b], x[b], xd[b], th[b], thd[b], F[b], dt,
                                              NLCX_VECTOR)  # fmt: skip
            stopped[b] = _stops(x[b], xd[b], th[b], thd[b], bound)
            n_stop += stopped[b]
        if n_stop > 0:
            nb = _leave(nb, vid, stopped, n_valid, k + 1, q)
            if nb == 0:
                break


@hot_njit(cache=True, error_model="numpy", inline="always")
def _pid_row(dt, y, r, cp, cs, row):  # pragma: no cover - compiled
    """The PID of :func:`simulate` on row ``row`` of nlcx's packed parameters cp and loop
    states cs (nlcx's layouts, :func:`packed_pid`): per loop the error-AGS gains of
    :func:`_ags`, a backward difference of the error, the integral gain outside the integral,
    the parallel form, updated every step, one input, no saturation; the outputs y and
    references r as tuples. Returns u_0. Compiled, like its caller, without numba's reference
    counting: with it, the inlined body would count its arrays at every call."""
    u0 = cp[row, len(H) + I.bias]
    base = len(H) + len(I) * 1
    for i in range(int(cp[row, H.n_loops])):
        h = base + len(L) * i
        c = len(S) * i
        y_i = y[int(cp[row, h + L.y_index])] * cp[row, h + L.scale]
        r_i = r[int(cp[row, h + L.r_index])] * cp[row, h + L.scale]
        e = r_i - y_i
        if cs[row, c + S.started] == 0.0:
            cs[row, c + S.e_prev], cs[row, c + S.started] = e, 1.0
        d = (e - cs[row, c + S.e_prev]) / dt
        o = int(cp[row, h + L.schedule_offset])
        kp, ki, kd = _ags(abs(e * cp[row, o + EA.error_scale]), cp[row, o : o + len(AGS)])
        cs[row, c + S.integral] += e * dt
        u0 += cp[row, h + L.sign] * (kp * (cp[row, h + L.setpoint_weight] * r_i - y_i) + cs[row, c + S.integral] * ki
                                     + kd * d)  # fmt: skip
        cs[row, c + S.e_prev] = e
    return u0


@hot_njit(cache=True, error_model="numpy")
def simulate_nlcx_pid(p, pid, ref, dt, n_steps, bound, X, U, n_valid):  # pragma: no cover - compiled
    """:func:`simulate` with its PID (:func:`_pid_row`) reading nlcx's packed rows: ``pid`` =
    (cp, cs) of nlcx's controllers (:func:`packed_pid`), ``ref`` (K+1, 2) the references of x
    and theta.

    The plant state stays in local variables, the controller's in nlcx's arrays. What
    separates this loop from nlcx's kernel is only that design (one variant at a time, the
    plant state in registers, plant and controller compiled into the loop) against the
    kernel's (every variant in lock step, states in arrays, plant and controller called as
    compiled-function values, sin and cos of the batch's angles in vector code): it measures
    what the kernel would gain by it."""
    cp, cs = pid
    for b in range(p.shape[0]):
        M, m, l, g = p[b, 0], p[b, 1], p[b, 2], p[b, 3]
        x, xd, th, thd = 0.0, 0.0, 0.0, 0.0
        n_valid[b] = n_steps + 1
        for k in range(n_steps + 1):
            F = _pid_row(dt, (x, th), (ref[k, 0], ref[k, 1]), cp, cs, b)
            X[b, k, 0], X[b, k, 1], X[b, k, 2], X[b, k, 3] = x, xd, th, thd
            U[b, k] = F
            if not math.isfinite(F):
                n_valid[b] = k + 1
                break
            if k == n_steps:
                break
            x, xd, th, thd = _rk4(M, m, l, g, x, xd, th, thd, F, dt, NLCX)
            if _stops(x, xd, th, thd, bound):
                n_valid[b] = k + 1
                break


def packed_pid(controllers: list) -> tuple:
    """(cp, cs) of nlcx PIDs, one row each, as the kernel hands them to the controller: the
    ``pid`` argument of :func:`simulate_nlcx_pid`. ValueError unless each has the structure
    :func:`_pid_row` is written for."""
    for controller in controllers:
        s = structure_of(controller.cp)
        written_for = (
            s.n_inputs == 1 and not s.discrete and not s.saturated and set(s.direct) == {DIRECT_ERROR_AGS}
            and not any(s.filtered + s.on_measurement + s.inside) and set(s.form) == {FORMS["parallel"]}
            and all(controller.cp[o + EA.on_abs_error] == 1.0 for o in s.offset)
        )  # fmt: skip
        if not written_for or ERROR_AGS.fields[: len(AGS)] != AGS:
            raise ValueError(f"the reference's PID is not written for the loop structure {s}")
    return np.stack([c.cp for c in controllers]), np.stack([c.cs0 for c in controllers])


def loop_parameters(schedule: dict) -> np.ndarray:
    """An error-AGS schedule of a config (kp/ki/kd ranges, rate) as :data:`AGS`."""
    ends = [schedule[g][end] for g in ("kp", "ki", "kd") for end in ("min", "max")]
    return np.array([*ends, *(schedule["rate"][g] for g in ("kp", "ki", "kd"))], dtype=float)

"""The compiled simulation kernel: one code path for single runs and sweeps.

Plants, controllers and gain schedules are numba-compiled functions with the fixed
signatures below. They are passed to :func:`simulate` as first-class function values, so a
single compiled (and disk-cached) kernel serves every plant and controller, including those
registered by third-party packages. Every per-variant quantity carries a leading batch axis
``b``; an array whose batch (or time) axis has length 1 is broadcast over that axis.

Signatures (all arrays are contiguous float64 vectors):

``rhs(t, x, u, p, dx)``
    Plant right-hand side: writes dx/dt = f(t, x, u; p) into ``dx``.
``schedule(t, e, edot, sp, gains)``
    Gain schedule: writes (k_p, k_i, k_d) into ``gains`` from time, error, error rate and
    the loop's schedule parameters ``sp``.
``controller(t, dt, x, y, r, cp, cs, u, log, schedules)``
    Controller sampled at t: reads measured outputs ``y`` (and, if it is a full-information
    controller, the plant state ``x``) and references ``r``, updates its
    state ``cs`` in place, writes the plant input ``u`` (held constant over the step: zero-
    order hold) and the values it wants recorded into ``log``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numba import njit, types
from numba.core.errors import NumbaExperimentalFeatureWarning

warnings.filterwarnings("ignore", category=NumbaExperimentalFeatureWarning)

F64 = types.float64
VEC = types.float64[::1]
MAT = types.float64[:, ::1]
ARR3 = types.float64[:, :, ::1]
ARR4 = types.float64[:, :, :, ::1]
IVEC = types.int64[::1]

#: Plant right-hand side ``rhs(t, x, u, p, dx)``.
RHS_SIG = types.void(F64, VEC, VEC, VEC, VEC)
#: Gain schedule ``schedule(t, e, edot, sp, gains)``.
SCHEDULE_SIG = types.void(F64, F64, F64, VEC, VEC)
#: Number of gain-schedule slots handed to every controller (registered schedules + padding).
SCHEDULE_SLOTS = 16
ScheduleTuple = types.UniTuple(types.FunctionType(SCHEDULE_SIG), SCHEDULE_SLOTS)
#: Controller step ``controller(t, dt, x, y, r, cp, cs, u, log, schedules)``.
CONTROLLER_SIG = types.void(F64, F64, VEC, VEC, VEC, VEC, VEC, VEC, VEC, ScheduleTuple)

RhsFn = types.FunctionType(RHS_SIG)
ControllerFn = types.FunctionType(CONTROLLER_SIG)

#: Friction parameters per input: model (0 none, 1 simple, 2 exponential), mu_s, mu_c,
#: viscous coefficient, normal force F_N, Stribeck velocity, form factor, velocity-state
#: index, position-state index.
FRICTION_FIELDS = 9
FRICTION_NONE = 0
FRICTION_SIMPLE = 1
FRICTION_EXPONENTIAL = 2
_SLIP = 1
_STUCK = 2

#: Run status codes written by :func:`simulate`.
STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_BOUND = 2

SIMULATE_SIG = types.void(
    RhsFn,  # rhs
    ControllerFn,  # controller
    ScheduleTuple,  # schedules
    MAT,  # rk_a (s, s) Butcher matrix
    VEC,  # rk_b (s,) weights
    MAT,  # x0 (B, n)
    MAT,  # p (B|1, n_p) plant parameters
    MAT,  # C (n_y, n) output matrix, y = C x
    MAT,  # cp (B, n_cp) controller parameters
    MAT,  # cs0 (B, n_cs) initial controller state
    ARR3,  # ref (B|1, K+1|1, n_r) reference at the sampling instants
    ARR4,  # dist (B|1, K|1, s, n_d) disturbance at the stage times t_k + c_i dt
    MAT,  # dist_map (n, n_d): dx += dist_map @ d
    ARR3,  # noise_y (B|1, K+1|1, n_y) added to the measured outputs
    ARR3,  # noise_u (B|1, K+1|1, n_u) added to the controller output
    ARR3,  # fric (B|1, n_u, FRICTION_FIELDS) friction of each input's axis (model 0: none)
    MAT,  # bounds (B|1, n) |x_i| above bounds[i] stops the run
    F64,  # dt
    ARR3,  # X out (B, K+1, n)
    ARR3,  # U out (B, K+1, n_u)
    ARR3,  # LOG out (B, K+1, n_log)
    ARR3,  # FRICTION out (B, K+1, n_u) friction force on each input's axis at t_k
    IVEC,  # status out (B,)
    IVEC,  # n_valid out (B,)
    IVEC,  # fail_index out (B,) i < n: state i failed; n + j: input j non-finite; -1: none
)


@njit(cache=True, inline="always", error_model="numpy")
def _row(arr_len: int, b: int) -> int:
    """Index into an axis that is either per-variant (length B) or broadcast (length 1)."""
    return b if arr_len > 1 else 0


@njit(cache=True, inline="always", error_model="numpy")
def _add_disturbance(dist_row, dist_map, dx):  # pragma: no cover - compiled
    """dx += dist_map @ d."""
    n_d = dist_row.shape[0]
    if n_d > 0:
        for i in range(dx.shape[0]):
            acc = 0.0
            for j in range(n_d):
                acc += dist_map[i, j] * dist_row[j]
            dx[i] += acc


@njit(cache=True, inline="always", error_model="numpy")
def _derivative(rhs, t, x, u, p, dist_row, dist_map, dx):  # pragma: no cover - compiled
    """dx = f(t, x, u; p) + dist_map @ d (eqs. 2.13/2.15: d enters the state derivatives)."""
    rhs(t, x, u, p, dx)
    n_d = dist_row.shape[0]
    if n_d > 0:
        for i in range(dx.shape[0]):
            acc = 0.0
            for j in range(n_d):
                acc += dist_map[i, j] * dist_row[j]
            dx[i] += acc


@njit(cache=True, error_model="numpy")
def slip_friction(fric_row, v, direction):  # pragma: no cover - compiled
    """Friction while sliding in ``direction`` at velocity v (Appendix A).

    simple:      F = -mu_c F_N sgn - eps v
    exponential: F = -[mu_c + (mu_s - mu_c) exp(-(|v|/v_s)^gamma)] F_N sgn - eps v
    The sign is the direction of the slip, fixed over a step, so the Runge-Kutta stages
    never chatter on sgn(v).
    """
    model = int(fric_row[0])
    mu_s, mu_c, eps, f_n = fric_row[1], fric_row[2], fric_row[3], fric_row[4]
    if model == FRICTION_SIMPLE:
        mu = mu_c
    else:
        mu = mu_c + (mu_s - mu_c) * math.exp(-((abs(v) / fric_row[5]) ** fric_row[6]))
    return -mu * f_n * direction - eps * v


@njit(cache=True, error_model="numpy")
def _solve_small(A, b, n):  # pragma: no cover - compiled
    """Solve A[:n, :n] z = b[:n] in place (Gaussian elimination, partial pivoting)."""
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(A[r, col]) > abs(A[piv, col]):
                piv = r
        if piv != col:
            for c in range(n):
                A[col, c], A[piv, c] = A[piv, c], A[col, c]
            b[col], b[piv] = b[piv], b[col]
        for r in range(col + 1, n):
            factor = A[r, col] / A[col, col]
            for c in range(col, n):
                A[r, c] -= factor * A[col, c]
            b[r] -= factor * b[col]
    for col in range(n - 1, -1, -1):
        acc = b[col]
        for c in range(col + 1, n):
            acc -= A[col, c] * b[c]
        b[col] = acc / A[col, col]


@njit(cache=True, error_model="numpy")
def _friction_forces(
    rhs, t, x, u, p, dist_row, dist_map, fric_b, mode, direction, f_out, work, A, rhs_s, dx
):  # pragma: no cover - compiled
    """Friction force on every input's axis at state x (written to f_out).

    Sliding axes get :func:`slip_friction`. Stuck axes get the force that keeps their
    acceleration exactly zero: accelerations are affine in the generalised forces, so with
    a0 the accelerations of the stuck axes under the other forces and B their response to
    unit forces on the stuck axes, f_S = -B^{-1} a0 (solved jointly when several stick).
    """
    n_u = u.shape[0]
    n_stuck = 0
    for j in range(n_u):
        f_out[j] = 0.0
        if mode[j] == _SLIP:
            vi = int(fric_b[j, 7])
            f_out[j] = slip_friction(fric_b[j], x[vi], direction[j])
        elif mode[j] == _STUCK:
            n_stuck += 1
    if n_stuck == 0:
        return
    for j in range(n_u):
        work[j] = u[j] + f_out[j]
    _derivative(rhs, t, x, work, p, dist_row, dist_map, dx)
    k = 0
    for j in range(n_u):
        if mode[j] == _STUCK:
            rhs_s[k] = -dx[int(fric_b[j, 7])]
            k += 1
    col = 0
    for jc in range(n_u):
        if mode[jc] != _STUCK:
            continue
        work[jc] += 1.0
        _derivative(rhs, t, x, work, p, dist_row, dist_map, dx)
        work[jc] -= 1.0
        row = 0
        for jr in range(n_u):
            if mode[jr] == _STUCK:
                A[row, col] = dx[int(fric_b[jr, 7])] + rhs_s[row]
                row += 1
        col += 1
    _solve_small(A, rhs_s, n_stuck)
    k = 0
    for j in range(n_u):
        if mode[j] == _STUCK:
            f_out[j] = rhs_s[k]
            k += 1


@njit(cache=True, error_model="numpy")
def _update_friction_modes(
    rhs, t, x, u, p, dist_row, dist_map, fric_b, mode, direction, f_tmp, work, A, rhs_s, dx
):  # pragma: no cover - compiled
    """Breakaway at the start of a step: a stuck axis whose holding force would exceed
    mu_s F_N starts to slide in the direction of the net force (Appendix A's static case)."""
    for _ in range(u.shape[0]):
        _friction_forces(rhs, t, x, u, p, dist_row, dist_map, fric_b, mode, direction, f_tmp, work, A, rhs_s, dx)
        released = False
        for j in range(u.shape[0]):
            if mode[j] == _STUCK and abs(f_tmp[j]) > fric_b[j, 1] * fric_b[j, 4]:
                mode[j] = _SLIP
                direction[j] = -1.0 if f_tmp[j] > 0 else 1.0
                released = True
        if not released:
            return


@njit(cache=True, error_model="numpy")
def _disturbance_at(drow, c, position, out):  # pragma: no cover - compiled
    """d at fraction ``position`` of the step, interpolated linearly between the stage nodes c."""
    n_stage = c.shape[0]
    lo, hi = 0, 0
    for s in range(n_stage):
        if c[s] <= position and c[s] >= c[lo]:
            lo = s
        if c[s] >= position and (c[hi] < position or c[s] <= c[hi]):
            hi = s
    if c[hi] < position:
        hi = lo
    w = 0.0 if c[hi] == c[lo] else (position - c[lo]) / (c[hi] - c[lo])
    for j in range(out.shape[0]):
        out[j] = (1.0 - w) * drow[lo, j] + w * drow[hi, j]


@njit(cache=True, inline="always", error_model="numpy")
def _rk_step(
    rhs,
    t,
    h,
    frac0,
    h_frac,
    x_in,
    x_out,
    u,
    pb,
    drow,
    c,
    dist_map,
    fb,
    mode,
    direction,
    has_friction,
    rk_a,
    rk_b,
    k_stage,
    xs,
    f,
    u_total,
    work,
    A,
    rhs_s,
    dx,
    d_tmp,
    classic,
):  # pragma: no cover - compiled
    """One explicit Runge-Kutta step of size h from x_in at t (u held) into x_out.

    The step covers the fraction [frac0, frac0 + h_frac] of the sampling step; the
    disturbance is exact at the stage nodes of a full step and interpolated between them
    for a partial step (one that ends where a sliding axis stops).
    """
    n = x_in.shape[0]
    n_stage = rk_b.shape[0]
    partial = frac0 != 0.0 or h_frac != 1.0
    if classic and not partial and not has_friction:
        # the classic RK4 unrolled (the common case: no partial step, no friction)
        rhs(t, x_in, u, pb, k_stage[0])
        _add_disturbance(drow[0], dist_map, k_stage[0])
        for i in range(n):
            xs[i] = x_in[i] + 0.5 * h * k_stage[0, i]
        rhs(t + 0.5 * h, xs, u, pb, k_stage[1])
        _add_disturbance(drow[1], dist_map, k_stage[1])
        for i in range(n):
            xs[i] = x_in[i] + 0.5 * h * k_stage[1, i]
        rhs(t + 0.5 * h, xs, u, pb, k_stage[2])
        _add_disturbance(drow[2], dist_map, k_stage[2])
        for i in range(n):
            xs[i] = x_in[i] + h * k_stage[2, i]
        rhs(t + h, xs, u, pb, k_stage[3])
        _add_disturbance(drow[3], dist_map, k_stage[3])
        for i in range(n):
            x_out[i] = x_in[i] + h / 6.0 * (k_stage[0, i] + 2.0 * (k_stage[1, i] + k_stage[2, i]) + k_stage[3, i])
        return
    for s in range(n_stage):
        xs[:] = x_in
        for j in range(s):
            if rk_a[s, j] != 0.0:
                for i in range(n):
                    xs[i] += h * rk_a[s, j] * k_stage[j, i]
        ts = t + c[s] * h
        if partial:
            _disturbance_at(drow, c, frac0 + c[s] * h_frac, d_tmp)
            d_s = d_tmp
        else:
            d_s = drow[s]
        if has_friction:
            _friction_forces(rhs, ts, xs, u, pb, d_s, dist_map, fb, mode, direction, f, work, A, rhs_s, dx)
            for j in range(u.shape[0]):
                u_total[j] = u[j] + f[j]
            _derivative(rhs, ts, xs, u_total, pb, d_s, dist_map, k_stage[s])
        else:
            _derivative(rhs, ts, xs, u, pb, d_s, dist_map, k_stage[s])
    x_out[:] = x_in
    for s in range(n_stage):
        for i in range(n):
            x_out[i] += h * rk_b[s] * k_stage[s, i]


@njit(SIMULATE_SIG, cache=True, error_model="numpy")
def simulate(
    rhs,
    controller,
    schedules,
    rk_a,
    rk_b,
    x0,
    p,
    C,
    cp,
    cs0,
    ref,
    dist,
    dist_map,
    noise_y,
    noise_u,
    fric,
    bounds,
    dt,
    X,
    U,
    LOG,
    FRICTION,
    status,
    n_valid,
    fail_index,
):  # pragma: no cover - compiled
    """Integrate a batch of closed loops with an explicit Runge-Kutta method.

    At every sampling instant t_k = k dt the controller reads y_k = C x_k (+ noise) and
    sets u_k, held constant (zero-order hold) while the plant is integrated to t_{k+1}
    with the Butcher tableau (rk_a, rk_b); stage i is evaluated at t_k + c_i dt with
    c_i = sum_j rk_a[i, j]. Friction (Appendix A) acts on the axis of each input: a sliding
    axis whose velocity reaches zero within a step is stopped there and sticks until its
    holding force exceeds mu_s F_N. A run whose state becomes non-finite or leaves
    ``bounds`` stops early: its status is set and the remaining samples are left untouched.
    """
    n_batch = x0.shape[0]
    n = x0.shape[1]
    n_stage = rk_b.shape[0]
    n_y = C.shape[0]
    n_u = U.shape[2]
    n_steps = X.shape[1] - 1
    c = np.zeros(n_stage)
    for i in range(n_stage):
        for j in range(n_stage):
            c[i] += rk_a[i, j]
    classic = (
        n_stage == 4
        and rk_a[1, 0] == 0.5 and rk_a[2, 1] == 0.5 and rk_a[3, 2] == 1.0
        and rk_a[2, 0] == 0.0 and rk_a[3, 0] == 0.0 and rk_a[3, 1] == 0.0
        and rk_b[0] == 1.0 / 6.0 and rk_b[1] == 2.0 / 6.0 and rk_b[2] == 2.0 / 6.0 and rk_b[3] == 1.0 / 6.0
    )  # fmt: skip
    k_stage = np.empty((n_stage, n))
    x = np.empty(n)
    xs = np.empty(n)
    y = np.empty(n_y)
    u = np.empty(n_u)
    u_total = np.empty(n_u)
    f = np.empty(n_u)
    mode = np.zeros(n_u, dtype=np.int64)
    direction = np.zeros(n_u)
    work = np.empty(n_u)
    A = np.empty((n_u, n_u))
    rhs_s = np.empty(n_u)
    dx = np.empty(n)
    x_new = np.empty(n)
    x_mid = np.empty(n)
    hold = np.zeros(n_u)
    d_tmp = np.empty(dist.shape[3])
    for b in range(n_batch):
        pb = p[_row(p.shape[0], b)]
        cs = cs0[b].copy()
        cpb = cp[b]
        rb = ref[_row(ref.shape[0], b)]
        db = dist[_row(dist.shape[0], b)]
        nyb = noise_y[_row(noise_y.shape[0], b)]
        nub = noise_u[_row(noise_u.shape[0], b)]
        fb = fric[_row(fric.shape[0], b)]
        bb = bounds[_row(bounds.shape[0], b)]
        x[:] = x0[b]
        has_friction = False
        for j in range(n_u):
            mode[j] = 0
            if int(fb[j, 0]) != FRICTION_NONE:
                has_friction = True
                v0 = x[int(fb[j, 7])]
                mode[j] = _STUCK if v0 == 0.0 else _SLIP
                direction[j] = 1.0 if v0 > 0.0 else -1.0
                hold[j] = x[int(fb[j, 8])]
        status[b] = STATUS_OK
        fail_index[b] = -1
        n_valid[b] = n_steps + 1
        for k in range(n_steps + 1):
            t = k * dt
            X[b, k] = x
            for i in range(n_y):
                acc = 0.0
                for j in range(n):
                    acc += C[i, j] * x[j]
                y[i] = acc + nyb[_row(nyb.shape[0], k), i]
            u[:] = 0.0
            controller(t, dt, x, y, rb[_row(rb.shape[0], k)], cpb, cs, u, LOG[b, k], schedules)
            for i in range(n_u):
                u[i] += nub[_row(nub.shape[0], k), i]
            U[b, k] = u
            bad_u = -1
            for i in range(n_u):
                if not np.isfinite(u[i]):
                    bad_u = i
                    break
            if bad_u >= 0:
                status[b] = STATUS_NONFINITE
                fail_index[b] = n + bad_u
                n_valid[b] = k + 1
                break
            drow = db[_row(db.shape[0], k)]
            if has_friction:
                _update_friction_modes(rhs, t, x, u, pb, drow[0], dist_map, fb, mode, direction, f, work, A, rhs_s, dx)
                _friction_forces(rhs, t, x, u, pb, drow[0], dist_map, fb, mode, direction, f, work, A, rhs_s, dx)
                FRICTION[b, k] = f
            else:
                FRICTION[b, k] = 0.0
            if k == n_steps:
                break
            _rk_step(
                rhs,
                t,
                dt,
                0.0,
                1.0,
                x,
                x_new,
                u,
                pb,
                drow,
                c,
                dist_map,
                fb,
                mode,
                direction,
                has_friction,
                rk_a,
                rk_b,
                k_stage,
                xs,
                f,
                u_total,
                work,
                A,
                rhs_s,
                dx,
                d_tmp,
                classic,
            )
            if has_friction:
                # event: a sliding axis whose velocity reaches zero inside the step stops there
                frac = 1.0
                for j in range(n_u):
                    vi = int(fb[j, 7])
                    if mode[j] == _SLIP and x_new[vi] * direction[j] <= 0.0 and x[vi] != x_new[vi]:
                        frac = min(frac, x[vi] / (x[vi] - x_new[vi]))
                if frac < 1.0:
                    h1 = frac * dt
                    _rk_step(
                        rhs,
                        t,
                        h1,
                        0.0,
                        frac,
                        x,
                        x_mid,
                        u,
                        pb,
                        drow,
                        c,
                        dist_map,
                        fb,
                        mode,
                        direction,
                        has_friction,
                        rk_a,
                        rk_b,
                        k_stage,
                        xs,
                        f,
                        u_total,
                        work,
                        A,
                        rhs_s,
                        dx,
                        d_tmp,
                        classic,
                    )
                    for j in range(n_u):
                        vi = int(fb[j, 7])
                        if mode[j] == _SLIP and x_new[vi] * direction[j] <= 0.0:
                            x_mid[vi] = 0.0
                            mode[j] = _STUCK
                            hold[j] = x_mid[int(fb[j, 8])]
                    _disturbance_at(drow, c, frac, d_tmp)
                    _update_friction_modes(
                        rhs, t + h1, x_mid, u, pb, d_tmp, dist_map, fb, mode, direction, f, work, A, rhs_s, dx
                    )
                    _rk_step(
                        rhs,
                        t + h1,
                        dt - h1,
                        frac,
                        1.0 - frac,
                        x_mid,
                        x_new,
                        u,
                        pb,
                        drow,
                        c,
                        dist_map,
                        fb,
                        mode,
                        direction,
                        has_friction,
                        rk_a,
                        rk_b,
                        k_stage,
                        xs,
                        f,
                        u_total,
                        work,
                        A,
                        rhs_s,
                        dx,
                        d_tmp,
                        classic,
                    )
                for j in range(n_u):
                    vi = int(fb[j, 7])
                    if mode[j] == _SLIP and x_new[vi] * direction[j] <= 0.0:  # a second stop: rare
                        mode[j] = _STUCK
                        hold[j] = x_new[int(fb[j, 8])]
                    if mode[j] == _STUCK:
                        x_new[vi] = 0.0
                        x_new[int(fb[j, 8])] = hold[j]
            x[:] = x_new
            bad = -1
            code = STATUS_OK
            for i in range(n):
                if not np.isfinite(x[i]):
                    bad = i
                    code = STATUS_NONFINITE
                    break
                if abs(x[i]) > bb[i]:
                    bad = i
                    code = STATUS_BOUND
                    break
            if bad >= 0:
                status[b] = code
                fail_index[b] = bad
                n_valid[b] = k + 1
                break

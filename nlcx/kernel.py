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
``controller(t, dt, y, r, cp, cs, u, log, schedules)``
    Controller sampled at t: reads measured outputs ``y`` and references ``r``, updates its
    state ``cs`` in place, writes the plant input ``u`` (held constant over the step: zero-
    order hold) and the values it wants recorded into ``log``.
"""

from __future__ import annotations

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
#: Controller step ``controller(t, dt, y, r, cp, cs, u, log, schedules)``.
CONTROLLER_SIG = types.void(F64, F64, VEC, VEC, VEC, VEC, VEC, VEC, ScheduleTuple)

RhsFn = types.FunctionType(RHS_SIG)
ControllerFn = types.FunctionType(CONTROLLER_SIG)

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
    VEC,  # bounds (n,) |x_i| above bounds[i] stops the run
    F64,  # dt
    ARR3,  # X out (B, K+1, n)
    ARR3,  # U out (B, K+1, n_u)
    ARR3,  # LOG out (B, K+1, n_log)
    IVEC,  # status out (B,)
    IVEC,  # n_valid out (B,)
    IVEC,  # fail_index out (B,) i < n: state i failed; n + j: input j non-finite; -1: none
)


@njit(cache=True)
def _row(arr_len: int, b: int) -> int:
    """Index into an axis that is either per-variant (length B) or broadcast (length 1)."""
    return b if arr_len > 1 else 0


@njit(cache=True)
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


@njit(SIMULATE_SIG, cache=True)
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
    bounds,
    dt,
    X,
    U,
    LOG,
    status,
    n_valid,
    fail_index,
):  # pragma: no cover - compiled
    """Integrate a batch of closed loops with an explicit Runge-Kutta method.

    At every sampling instant t_k = k dt the controller reads y_k = C x_k (+ noise) and
    sets u_k, held constant (zero-order hold) while the plant is integrated to t_{k+1}
    with the Butcher tableau (rk_a, rk_b); stage i is evaluated at t_k + c_i dt with
    c_i = sum_j rk_a[i, j]. A run whose state becomes non-finite or leaves ``bounds``
    stops early: its status is set and the remaining samples are left untouched (NaN).
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
    k_stage = np.empty((n_stage, n))
    x = np.empty(n)
    xs = np.empty(n)
    y = np.empty(n_y)
    u = np.empty(n_u)
    for b in range(n_batch):
        pb = p[_row(p.shape[0], b)]
        cs = cs0[b].copy()
        cpb = cp[b]
        rb = ref[_row(ref.shape[0], b)]
        db = dist[_row(dist.shape[0], b)]
        nyb = noise_y[_row(noise_y.shape[0], b)]
        nub = noise_u[_row(noise_u.shape[0], b)]
        x[:] = x0[b]
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
            controller(t, dt, y, rb[_row(rb.shape[0], k)], cpb, cs, u, LOG[b, k], schedules)
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
            if k == n_steps:
                break
            drow = db[_row(db.shape[0], k)]
            for s in range(n_stage):
                xs[:] = x
                for j in range(s):
                    if rk_a[s, j] != 0.0:
                        for i in range(n):
                            xs[i] += dt * rk_a[s, j] * k_stage[j, i]
                _derivative(rhs, t + c[s] * dt, xs, u, pb, drow[s], dist_map, k_stage[s])
            for s in range(n_stage):
                for i in range(n):
                    x[i] += dt * rk_b[s] * k_stage[s, i]
            bad = -1
            code = STATUS_OK
            for i in range(n):
                if not np.isfinite(x[i]):
                    bad = i
                    code = STATUS_NONFINITE
                    break
                if abs(x[i]) > bounds[i]:
                    bad = i
                    code = STATUS_BOUND
                    break
            if bad >= 0:
                status[b] = code
                fail_index[b] = bad
                n_valid[b] = k + 1
                break

"""The compiled simulation kernel: one code path for single runs and sweeps.

Plants, controllers and gain schedules are numba-compiled functions with the fixed
signatures below. They are passed to :func:`simulate` as first-class function values, so a
single compiled (and disk-cached) kernel serves every plant and controller, including those
registered by third-party packages.

The kernel runs a batch of closed loops in lock step: every sampling instant, one call of
the controller and one call of the right-hand side per Runge-Kutta stage serve every
variant of the batch. Plant and controller functions therefore take 2-D arrays whose rows
are the variants. A single trajectory is a chain of dependent operations (each stage needs
the one before); stepping many variants together lets the processor overlap independent
chains, and the cost of a call is shared by the whole batch.

Signatures (arrays are contiguous float64; row ``b`` of every 2-D array is variant ``b``):

``rhs(t, x, u, p, dx)``
    Plant right-hand side: ``dx[b] = f(t, x[b], u[b]; p[b])`` for every row ``b`` of ``x``.
``schedule(t, e, edot, p, row, offset) -> (k_p, k_i, k_d)``
    Gain schedule: the gains at time t for error e and error rate edot, from the schedule
    parameters stored in ``p[row]`` from column ``offset`` on.
``controller(t, dt, x, y, r, cp, cs, u, log, schedules)``
    Controller sampled at t, for every row: reads measured outputs ``y`` (and, if it is a
    full-information controller, the plant state ``x``) and references ``r``, updates its
    state ``cs`` in place, writes the plant input ``u`` (held constant over the step: zero-
    order hold) and the values it wants recorded into ``log``.

Hot-loop rules (they decide the speed, see benchmarks/): no array view is made per step and
per variant (a view handed to a compiled-function value costs a reference-count round
trip), and a function that calls a compiled-function value does so inside its loop over
the rows, so its own reference counting is paid once per call, not once per variant.
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
I64 = types.int64

#: Plant right-hand side ``rhs(t, x, u, p, dx)`` over the rows of x.
RHS_SIG = types.void(F64, MAT, MAT, MAT, MAT)
#: Gain schedule ``schedule(t, e, edot, p, row, offset) -> (k_p, k_i, k_d)``.
SCHEDULE_SIG = types.UniTuple(F64, 3)(F64, F64, F64, MAT, I64, I64)
#: Most stages of a Runge-Kutta tableau the kernel integrates with.
MAX_STAGES = 4
#: Number of gain-schedule slots handed to every controller (registered schedules + padding).
SCHEDULE_SLOTS = 16
ScheduleTuple = types.UniTuple(types.FunctionType(SCHEDULE_SIG), SCHEDULE_SLOTS)
#: Controller step ``controller(t, dt, x, y, r, cp, cs, u, log, schedules)`` over the rows.
CONTROLLER_SIG = types.void(F64, F64, MAT, MAT, MAT, MAT, MAT, MAT, MAT, ScheduleTuple)

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
    ARR3,  # LOG out (B, K+1|1, n_log); time length 1: logs not recorded
    ARR3,  # FRICTION out (B, K+1|1, n_u) friction force on each input's axis at t_k (1: not recorded)
    IVEC,  # status out (B,)
    IVEC,  # n_valid out (B,)
    IVEC,  # fail_index out (B,) i < n: state i failed; n + j: input j non-finite; -1: none
)


@njit(cache=True, inline="always", error_model="numpy")
def _row(arr_len: int, b: int) -> int:
    """Index into an axis that is either per-variant (length B) or broadcast (length 1)."""
    return b if arr_len > 1 else 0


# --------------------------------------------------------------- one variant (friction path)


@njit(cache=True, error_model="numpy")
def _derivative(rhs, t, x, u, dist_row, dist_map, dx, one):  # pragma: no cover - compiled
    """dx = f(t, x, u; p) + dist_map @ d for one variant (eqs. 2.13/2.15: d enters the
    state derivatives). ``one`` = (x, u, p, dx) scratch rows of shape (1, .); p is set."""
    x1, u1, p1, dx1 = one
    for i in range(x.shape[0]):
        x1[0, i] = x[i]
    for j in range(u.shape[0]):
        u1[0, j] = u[j]
    rhs(t, x1, u1, p1, dx1)
    n_d = dist_row.shape[0]
    for i in range(dx.shape[0]):
        dx[i] = dx1[0, i]
        if n_d > 0:
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
    rhs, t, x, u, dist_row, dist_map, fric_b, mode, direction, f_out, work, A, rhs_s, dx, one
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
    _derivative(rhs, t, x, work, dist_row, dist_map, dx, one)
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
        _derivative(rhs, t, x, work, dist_row, dist_map, dx, one)
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
    rhs, t, x, u, dist_row, dist_map, fric_b, mode, direction, f_tmp, work, A, rhs_s, dx, one
):  # pragma: no cover - compiled
    """Breakaway at the start of a step: a stuck axis whose holding force would exceed
    mu_s F_N starts to slide in the direction of the net force (Appendix A's static case)."""
    for _ in range(u.shape[0]):
        _friction_forces(rhs, t, x, u, dist_row, dist_map, fric_b, mode, direction, f_tmp, work, A, rhs_s, dx, one)
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


@njit(cache=True, error_model="numpy")
def _rk_step_one(
    rhs, t, h, frac0, h_frac, x_in, x_out, u, drow, c, dist_map, fb, mode, direction, rk_a, rk_b, scratch
):  # pragma: no cover - compiled
    """One explicit Runge-Kutta step of one variant with friction, size h from x_in at t
    (u held) into x_out.

    The step covers the fraction [frac0, frac0 + h_frac] of the sampling step; the
    disturbance is exact at the stage nodes of a full step and interpolated between them
    for a partial step (one that ends where a sliding axis stops). ``scratch`` is the
    friction path's work space, see :func:`_step_with_friction`.
    """
    k_stage, xs, f, u_total, work, A, rhs_s, dx, d_tmp, one = scratch
    n = x_in.shape[0]
    n_stage = rk_b.shape[0]
    partial = frac0 != 0.0 or h_frac != 1.0
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
        _friction_forces(rhs, ts, xs, u, d_s, dist_map, fb, mode, direction, f, work, A, rhs_s, dx, one)
        for j in range(u.shape[0]):
            u_total[j] = u[j] + f[j]
        _derivative(rhs, ts, xs, u_total, d_s, dist_map, k_stage[s], one)
    x_out[:] = x_in
    for s in range(n_stage):
        for i in range(n):
            x_out[i] += h * rk_b[s] * k_stage[s, i]


@njit(cache=True, error_model="numpy")
def _step_with_friction(
    rhs, t, dt, x, x_new, x_mid, u, drow, c, dist_map, fb, mode, direction, hold, rk_a, rk_b, scratch
):  # pragma: no cover - compiled
    """One sampling step of one variant with friction (Appendix A): a sliding axis whose
    velocity reaches zero inside the step is stopped there (the step is split at that
    instant); a stuck axis is held at its position until it breaks away.

    ``scratch`` = (k_stage (s, n), xs (n,), f, u_total, work (n_u,), A (n_u, n_u), rhs_s (n_u,),
    dx (n,), d_tmp (n_d,), one): work space allocated once per :func:`simulate` call."""
    n_u = u.shape[0]
    _rk_step_one(rhs, t, dt, 0.0, 1.0, x, x_new, u, drow, c, dist_map, fb, mode, direction, rk_a, rk_b, scratch)
    frac = 1.0
    for j in range(n_u):
        vi = int(fb[j, 7])
        if mode[j] == _SLIP and x_new[vi] * direction[j] <= 0.0 and x[vi] != x_new[vi]:
            frac = min(frac, x[vi] / (x[vi] - x_new[vi]))
    if frac < 1.0:
        h1 = frac * dt
        _rk_step_one(rhs, t, h1, 0.0, frac, x, x_mid, u, drow, c, dist_map, fb, mode, direction, rk_a, rk_b, scratch)
        for j in range(n_u):
            vi = int(fb[j, 7])
            if mode[j] == _SLIP and x_new[vi] * direction[j] <= 0.0:
                x_mid[vi] = 0.0
                mode[j] = _STUCK
                hold[j] = x_mid[int(fb[j, 8])]
        _, _, f, _, work, A, rhs_s, dx, d_tmp, one = scratch
        _disturbance_at(drow, c, frac, d_tmp)
        _update_friction_modes(rhs, t + h1, x_mid, u, d_tmp, dist_map, fb, mode, direction, f, work, A, rhs_s, dx, one)
        _rk_step_one(
            rhs,
            t + h1,
            dt - h1,
            frac,
            1.0 - frac,
            x_mid,
            x_new,
            u,
            drow,
            c,
            dist_map,
            fb,
            mode,
            direction,
            rk_a,
            rk_b,
            scratch,
        )
    for j in range(n_u):
        vi = int(fb[j, 7])
        if mode[j] == _SLIP and x_new[vi] * direction[j] <= 0.0:  # a second stop: rare
            mode[j] = _STUCK
            hold[j] = x_new[int(fb[j, 8])]
        if mode[j] == _STUCK:
            x_new[vi] = 0.0
            x_new[int(fb[j, 8])] = hold[j]


# ------------------------------------------------------------------------ the whole batch


@njit(cache=True, error_model="numpy")
def _add_disturbances(dx, dist, vid, kd, stage, dist_map):  # pragma: no cover - compiled
    """dx[b] += dist_map @ dist[variant of b, kd, stage] for every active row."""
    n_d = dist.shape[3]
    if n_d == 0:
        return
    n = dx.shape[1]
    for b in range(dx.shape[0]):
        bd = _row(dist.shape[0], vid[b])
        for i in range(n):
            acc = 0.0
            for j in range(n_d):
                acc += dist_map[i, j] * dist[bd, kd, stage, j]
            dx[b, i] += acc


@njit(cache=True, error_model="numpy")
def _rk_step_batch(rhs, t, h, x, x_out, u, p, dist, vid, kd, dist_map, rk_a, rk_b, c, stages, xs):  # pragma: no cover
    """One explicit Runge-Kutta step of size h for every row, any tableau of at most
    :data:`MAX_STAGES` stages (u held, no friction). ``stages`` holds one (B, n) array per stage."""
    nb, n = x.shape
    n_stage = rk_b.shape[0]
    for s in range(n_stage):
        for b in range(nb):
            for i in range(n):
                acc = x[b, i]
                for j in range(s):
                    if rk_a[s, j] != 0.0:
                        acc += h * rk_a[s, j] * stages[j][b, i]
                xs[b, i] = acc
        rhs(t + c[s] * h, xs, u, p, stages[s])
        _add_disturbances(stages[s], dist, vid, kd, s, dist_map)
    for b in range(nb):
        for i in range(n):
            acc = x[b, i]
            for s in range(n_stage):
                acc += h * rk_b[s] * stages[s][b, i]
            x_out[b, i] = acc


@njit(cache=True, error_model="numpy")
def _swap_variants(i, j, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode):  # pragma: no cover
    """Exchange the working rows i and j (two variants' state, parameters and bookkeeping)."""
    if i == j:
        return
    vid[i], vid[j] = vid[j], vid[i]
    stopped[i], stopped[j] = stopped[j], stopped[i]
    for a in (x, pw, cpw, cs, log, bw, direction, hold):
        _swap_rows(a, i, j)
    _swap_rows3(fw, i, j)
    for c in range(mode.shape[1]):
        mode[i, c], mode[j, c] = mode[j, c], mode[i, c]


@njit(cache=True, error_model="numpy")
def _swap_rows(a, i, j):  # pragma: no cover - compiled
    """Exchange rows i and j of a 2-D array."""
    for c in range(a.shape[1]):
        a[i, c], a[j, c] = a[j, c], a[i, c]


@njit(cache=True, error_model="numpy")
def _swap_rows3(a, i, j):  # pragma: no cover - compiled
    """Exchange rows i and j of a 3-D array."""
    for c in range(a.shape[1]):
        for d in range(a.shape[2]):
            a[i, c, d], a[j, c, d] = a[j, c, d], a[i, c, d]


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
    """Integrate a batch of closed loops in lock step with an explicit Runge-Kutta method.

    At every sampling instant t_k = k dt each controller reads y_k = C x_k (+ noise) and
    sets u_k, held constant (zero-order hold) while its plant is integrated to t_{k+1}
    with the Butcher tableau (rk_a, rk_b); stage i is evaluated at t_k + c_i dt with
    c_i = sum_j rk_a[i, j]. Friction (Appendix A) acts on the axis of each input: a sliding
    axis whose velocity reaches zero within a step is stopped there and sticks until its
    holding force exceeds mu_s F_N (such variants are stepped one by one). A variant whose
    state becomes non-finite or leaves ``bounds`` stops: its status is set, the remaining
    samples are left untouched and it leaves the batch (the active variants are kept in
    the leading rows of the working arrays; ``vid`` maps a row to its variant).
    """
    n_batch, n = x0.shape
    n_stage = rk_b.shape[0]
    n_y = C.shape[0]
    n_u = U.shape[2]
    n_r = ref.shape[2]
    n_log = LOG.shape[2]
    n_steps = X.shape[1] - 1
    record = LOG.shape[1] == n_steps + 1
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
    # y_i = x_j where row i of C is the unit vector e_j (exact: the other terms are 0 x_k)
    picked = np.full(n_y, -1)
    for i in range(n_y):
        for j in range(n):
            if C[i, j] == 1.0 and picked[i] == -1:
                picked[i] = j
            elif C[i, j] != 0.0:
                picked[i] = -2
    for i in range(n_y):
        if picked[i] == -2:
            picked[i] = -1
    # per-row working state (rows are permuted when a variant leaves the batch)
    # rows: the variants without friction first (stepped together), then those with friction
    # (stepped one by one); a variant that stops moves behind the active rows
    has_friction = np.zeros(n_batch, dtype=np.bool_)
    for v in range(n_batch):
        fv = fric[_row(fric.shape[0], v)]
        for j in range(n_u):
            if int(fv[j, 0]) != FRICTION_NONE:
                has_friction[v] = True
    vid = np.empty(n_batch, dtype=np.int64)
    n_free = 0
    for v in range(n_batch):
        if not has_friction[v]:
            vid[n_free] = v
            n_free += 1
    b = n_free
    for v in range(n_batch):
        if has_friction[v]:
            vid[b] = v
            b += 1
    x = np.empty((n_batch, n))
    pw = np.empty((n_batch, p.shape[1]))
    cpw = np.empty((n_batch, cp.shape[1]))
    cs = np.empty((n_batch, cs0.shape[1]))
    fw = np.empty((n_batch, n_u, FRICTION_FIELDS))
    bw = np.empty((n_batch, n))
    for b in range(n_batch):
        v = vid[b]
        x[b] = x0[v]
        pw[b] = p[_row(p.shape[0], v)]
        cpw[b] = cp[v]
        cs[b] = cs0[v]
        fw[b] = fric[_row(fric.shape[0], v)]
        bw[b] = bounds[_row(bounds.shape[0], v)]
    y = np.empty((n_batch, n_y))
    r = np.empty((n_batch, n_r))
    u = np.empty((n_batch, n_u))
    log = np.full((n_batch, n_log), np.nan)
    x_new = np.empty((n_batch, n))
    xs = np.empty((n_batch, n))
    k1, k2, k3, k4 = np.empty((n_batch, n)), np.empty((n_batch, n)), np.empty((n_batch, n)), np.empty((n_batch, n))
    mode = np.zeros((n_batch, n_u), dtype=np.int64)
    direction = np.zeros((n_batch, n_u))
    hold = np.zeros((n_batch, n_u))
    for b in range(n_batch):
        for j in range(n_u):
            if int(fw[b, j, 0]) != FRICTION_NONE:
                v0 = x[b, int(fw[b, j, 7])]
                mode[b, j] = _STUCK if v0 == 0.0 else _SLIP
                direction[b, j] = 1.0 if v0 > 0.0 else -1.0
                hold[b, j] = x[b, int(fw[b, j, 8])]
        status[b] = STATUS_OK
        fail_index[b] = -1
        n_valid[b] = n_steps + 1
    # scratch of the one-variant friction path
    one = (np.empty((1, n)), np.empty((1, n_u)), np.empty((1, p.shape[1])), np.empty((1, n)))
    xo = np.empty(n)
    xo_new = np.empty(n)
    xo_mid = np.empty(n)
    uo = np.empty(n_u)
    k_stage = np.empty((n_stage, n))
    xso = np.empty(n)
    f = np.empty(n_u)
    u_total = np.empty(n_u)
    work = np.empty(n_u)
    A = np.empty((n_u, n_u))
    rhs_s = np.empty(n_u)
    dxo = np.empty(n)
    d_tmp = np.empty(dist.shape[3])
    scratch = (k_stage, xso, f, u_total, work, A, rhs_s, dxo, d_tmp, one)
    stopped = np.zeros(n_batch, dtype=np.bool_)
    nb = n_batch
    # views on the active rows (the controller's) and on the frictionless ones (stepped
    # together), remade only when a variant leaves
    yv, rv, uv, xv, cpv, csv, logv = y, r, u, x, cpw, cs, log
    xr, xnr, xsr, ur, pr = x[:n_free], x_new[:n_free], xs[:n_free], u[:n_free], pw[:n_free]
    k1r, k2r, k3r, k4r = k1[:n_free], k2[:n_free], k3[:n_free], k4[:n_free]
    # flat views: the rows stepped together are the leading rows, so the first n_free * n entries
    size = n_batch * n
    xf, xsf, xnf = x.reshape(size), xs.reshape(size), x_new.reshape(size)
    k1f, k2f, k3f, k4f = k1.reshape(size), k2.reshape(size), k3.reshape(size), k4.reshape(size)
    for k in range(n_steps + 1):
        t = k * dt
        kny = _row(noise_y.shape[1], k)
        kr = _row(ref.shape[1], k)
        for b in range(nb):
            v = vid[b]
            for i in range(n):
                X[v, k, i] = x[b, i]
            bny = _row(noise_y.shape[0], v)
            for i in range(n_y):
                if picked[i] >= 0:  # a row of C that selects one state
                    acc = x[b, picked[i]]
                else:
                    acc = 0.0
                    for j in range(n):
                        acc += C[i, j] * x[b, j]
                y[b, i] = acc + noise_y[bny, kny, i]
            br = _row(ref.shape[0], v)
            for i in range(n_r):
                r[b, i] = ref[br, kr, i]
            for j in range(n_u):
                u[b, j] = 0.0
        controller(t, dt, xv, yv, rv, cpv, csv, uv, logv, schedules)
        knu = _row(noise_u.shape[1], k)
        kd = _row(dist.shape[1], k)
        n_stop = 0
        for b in range(nb):
            v = vid[b]
            if record:
                for i in range(n_log):
                    LOG[v, k, i] = log[b, i]
            bnu = _row(noise_u.shape[0], v)
            bad_u = -1
            for j in range(n_u):
                u[b, j] += noise_u[bnu, knu, j]
                U[v, k, j] = u[b, j]
                if bad_u < 0 and not np.isfinite(u[b, j]):
                    bad_u = j
            if bad_u >= 0:
                status[v] = STATUS_NONFINITE
                fail_index[v] = n + bad_u
                n_valid[v] = k + 1
                stopped[b] = True
                n_stop += 1
                continue
            if b >= n_free:
                for i in range(n):
                    xo[i] = x[b, i]
                for j in range(n_u):
                    uo[j] = u[b, j]
                for i in range(pw.shape[1]):
                    one[2][0, i] = pw[b, i]
                drow = dist[_row(dist.shape[0], v), kd]
                _update_friction_modes(
                    rhs, t, xo, uo, drow[0], dist_map, fw[b], mode[b], direction[b], f, work, A, rhs_s, dxo, one
                )
                if record:  # the force at t_k, only to be recorded (the step evaluates its own)
                    _friction_forces(
                        rhs, t, xo, uo, drow[0], dist_map, fw[b], mode[b], direction[b], f, work, A, rhs_s, dxo, one
                    )
                    for j in range(n_u):
                        FRICTION[v, k, j] = f[j]
            elif record:
                for j in range(n_u):
                    FRICTION[v, k, j] = 0.0
        if k < n_steps and nb > n_stop:
            if n_free > 0 and classic:  # the classic RK4 written out (the common case)
                rhs(t, xr, ur, pr, k1r)
                _add_disturbances(k1r, dist, vid, kd, 0, dist_map)
                for q in range(n_free * n):  # flat over the rows: vectorisable
                    xsf[q] = xf[q] + 0.5 * dt * k1f[q]
                rhs(t + 0.5 * dt, xsr, ur, pr, k2r)
                _add_disturbances(k2r, dist, vid, kd, 1, dist_map)
                for q in range(n_free * n):
                    xsf[q] = xf[q] + 0.5 * dt * k2f[q]
                rhs(t + 0.5 * dt, xsr, ur, pr, k3r)
                _add_disturbances(k3r, dist, vid, kd, 2, dist_map)
                for q in range(n_free * n):
                    xsf[q] = xf[q] + dt * k3f[q]
                rhs(t + dt, xsr, ur, pr, k4r)
                _add_disturbances(k4r, dist, vid, kd, 3, dist_map)
                for q in range(n_free * n):
                    xnf[q] = xf[q] + dt / 6.0 * (k1f[q] + 2.0 * (k2f[q] + k3f[q]) + k4f[q])
            elif n_free > 0:
                _rk_step_batch(
                    rhs, t, dt, xr, xnr, ur, pr, dist, vid, kd, dist_map, rk_a, rk_b, c, (k1r, k2r, k3r, k4r), xsr
                )
            if nb > n_free:
                for b in range(n_free, nb):
                    if stopped[b]:
                        continue
                    v = vid[b]
                    for i in range(n):
                        xo[i] = x[b, i]
                    for j in range(n_u):
                        uo[j] = u[b, j]
                    for i in range(pw.shape[1]):
                        one[2][0, i] = pw[b, i]
                    _step_with_friction(
                        rhs,
                        t,
                        dt,
                        xo,
                        xo_new,
                        xo_mid,
                        uo,
                        dist[_row(dist.shape[0], v), kd],
                        c,
                        dist_map,
                        fw[b],
                        mode[b],
                        direction[b],
                        hold[b],
                        rk_a,
                        rk_b,
                        scratch,
                    )
                    for i in range(n):
                        x_new[b, i] = xo_new[i]
            for b in range(nb):
                if stopped[b]:
                    continue
                v = vid[b]
                bad = -1
                code = STATUS_OK
                for i in range(n):
                    x[b, i] = x_new[b, i]
                    if bad >= 0:
                        continue
                    if not np.isfinite(x[b, i]):
                        bad = i
                        code = STATUS_NONFINITE
                    elif abs(x[b, i]) > bw[b, i]:
                        bad = i
                        code = STATUS_BOUND
                if bad >= 0:
                    status[v] = code
                    fail_index[v] = bad
                    n_valid[v] = k + 1
                    stopped[b] = True
                    n_stop += 1
        if n_stop > 0:
            # move the stopped variants behind the active ones, keeping the frictionless rows
            # in front: a stopped frictionless row trades places with the last frictionless
            # row, which then trades with the last active row
            b = 0
            while b < nb:
                if not stopped[b]:
                    b += 1
                    continue
                if b < n_free:
                    _swap_variants(b, n_free - 1, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode)
                    _swap_variants(n_free - 1, nb - 1, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode)
                    n_free -= 1
                else:
                    _swap_variants(b, nb - 1, vid, stopped, x, pw, cpw, cs, log, bw, direction, hold, fw, mode)
                nb -= 1
            if nb == 0:
                break
            yv, rv, uv, xv, cpv, csv, logv = y[:nb], r[:nb], u[:nb], x[:nb], cpw[:nb], cs[:nb], log[:nb]
            xr, xnr, xsr, ur, pr = x[:n_free], x_new[:n_free], xs[:n_free], u[:n_free], pw[:n_free]
            k1r, k2r, k3r, k4r = k1[:n_free], k2[:n_free], k3[:n_free], k4[:n_free]

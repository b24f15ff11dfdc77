"""The H2 and H-infinity preview servo's compiled step (thesis section 5.5, eq. 5.21) and the
layout of its parameter, state and log rows."""

from __future__ import annotations

import numpy as np
from numba import njit

from nlcx._numba_compat import hot_njit
from nlcx.kernel.signatures import Callbacks, FloatArray
from nlcx.layout import Layout

#: Head of the parameter row cp: plant order n, inputs m, preview length h, integrator (0/1),
#: sample time Ts, the output's equilibrium y*; then x* (n), u* (m), c (n), Kx (m x n),
#: Kv (m), Kd (m x (h+1)).
PREVIEW = Layout("Preview", ("n", "m", "h", "integrator", "sample_time", "y_eq"))
#: Head of the state cs: sample counter, error integral v; then per input the held u, the
#: preview and the feedback terms (m each).
PREVIEW_STATE = Layout("PreviewState", ("counter", "integral"))
#: What the controller logs per input (then the integral, once).
PREVIEW_LOG = Layout("PreviewLog", ("u", "preview", "feedback"))
P = PREVIEW.at
S = PREVIEW_STATE.at
G = PREVIEW_LOG.at
HEADER = PREVIEW.size
STATE_HEAD = PREVIEW_STATE.size
LOG_SIZE = PREVIEW_LOG.size


@njit(cache=True, error_model="numpy")
def _preview_row(
    t: float, dt: float, x: FloatArray, r: FloatArray, cp: FloatArray, cs: FloatArray, u: FloatArray, log: FloatArray
) -> None:  # pragma: no cover - compiled
    """Preview servo (eq. 5.21) for one variant, sampled every Ts = N dt and held in between.

    cp: a PREVIEW head, then x* (n), u* (m), c (n), Kx (m x n), Kv (m), Kd (m x (h+1)).
    cs: a PREVIEW_STATE head, then u (m), preview term (m), feedback term (m).
    r: r(t), r(t + Ts), ..., r(t + h Ts).
    """
    n = int(cp[P.n])
    m = int(cp[P.m])
    nd = int(cp[P.h]) + 1
    integ = cp[P.integrator] != 0.0
    Ts = cp[P.sample_time]
    y_eq = cp[P.y_eq]
    o_x = HEADER
    o_u = o_x + n
    o_c = o_u + m
    o_kx = o_c + n
    o_kv = o_kx + m * n
    o_kd = o_kv + m
    o_pv = STATE_HEAD + m
    o_fb = o_pv + m
    ratio = Ts / dt
    n_sub = round(ratio)
    valid = n_sub >= 1 and abs(ratio - n_sub) <= 1e-6 * ratio
    if cs[S.counter] == 0.0:
        for j in range(m):
            fb = 0.0
            for i in range(n):
                fb += cp[o_kx + j * n + i] * (x[i] - cp[o_x + i])
            if integ:
                fb += cp[o_kv + j] * cs[S.integral]
            pv = 0.0
            for i in range(nd):
                pv += cp[o_kd + j * nd + i] * (r[i] - y_eq)
            cs[STATE_HEAD + j] = cp[o_u + j] + fb + pv if valid else np.nan
            cs[o_pv + j] = pv
            cs[o_fb + j] = fb
        if integ:
            e = -r[0]
            for i in range(n):
                e += cp[o_c + i] * x[i]
            cs[S.integral] += Ts * e
    cs[S.counter] += 1.0
    if cs[S.counter] >= n_sub:
        cs[S.counter] = 0.0
    for j in range(m):
        u[j] = cs[STATE_HEAD + j]
        log[LOG_SIZE * j + G.u] = cs[STATE_HEAD + j]
        log[LOG_SIZE * j + G.preview] = cs[o_pv + j]
        log[LOG_SIZE * j + G.feedback] = cs[o_fb + j]
    log[LOG_SIZE * m] = cs[S.integral]


@hot_njit(cache=True, error_model="numpy")
def preview_step(
    t: float,
    dt: float,
    x: FloatArray,
    y: FloatArray,
    r: FloatArray,
    cp: FloatArray,
    cs: FloatArray,
    u: FloatArray,
    log: FloatArray,
    callbacks: Callbacks,
) -> None:  # pragma: no cover - compiled
    """The preview servo (eq. 5.21), every row (full state information: it reads x)."""
    for b in range(x.shape[0]):
        _preview_row(t, dt, x[b], r[b], cp[b], cs[b], u[b], log[b])

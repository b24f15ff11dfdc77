"""H2 and H-infinity preview servo (thesis section 5.5, eqs. 5.21-5.22, Figs. 5.18-5.19).

The controller knows the reference h samples ahead and applies (eq. 5.21)

    u(k) = u* + K_x xhat(k) + sum_{i=0..h} K_di d(k + i)

at the controller samples t = k Ts, holding u in between (zero-order hold). Here
xhat = [x - x*; v] is the plant state (full information) measured from the operating point
(x*, u*), extended by the integral of the tracking error v, and d(k + i) = r(t + i Ts) - y*
are the previewed reference samples, read from time-shifted reference channels.

Design model (Katayama / Takaba): the linearised plant, ZOH-discretised at Ts,
x(k+1) = A x + B u (+ B delta), is augmented with the error integrator and a shift register
of the h + 1 previewed samples; the newest sample enters from the exogenous input
w(k) = d(k + h + 1):

    xi(k)   = [x(k); v(k); d(k); d(k+1); ...; d(k+h)]
    x(k+1)  = A x(k) + B u(k) + B delta(k)                  (delta: optional input disturbance)
    v(k+1)  = v(k) + Ts (c x(k) - d(k))                     (only with an integral weight)
    d(k+i)  <- d(k+i+1),  d(k+h+1) = w(k)                   (shift register)
    z(k)    = [sqrt(q) (c x(k) - d(k)); sqrt(q_I) v(k); sqrt(r) u(k)]

and J = sum ||z||^2 (eq. 5.22). The integrator makes a constant reference (and a constant
input disturbance) tracked with zero steady-state error: in any stable steady state v is
constant, hence c x = d.

* H2: u = K xi with K from the discrete algebraic Riccati equation (DARE) of (Phi, G_u).
* H-infinity (full information, u = K xi): the game Riccati equation
  X = Q + Phi' X Phi - Phi' X G (Rt + G' X G)^-1 G' X Phi with G = [G_u G_w] and
  Rt = blockdiag(r I, -gamma^2 I), solved for a given gamma with the indefinite DARE and
  accepted only if X >= 0, gamma^2 I - G_w' X G_w > 0 and the closed loop is stable; then
  ||T_zw||_inf < gamma. gamma_min is found by bisection and the design is made at
  gamma_factor * gamma_min.

Everything here is numpy/scipy (no slycot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.linalg
from numba import njit
from pydantic import Field

from nlcx._numba_compat import hot_njit
from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel, check_sample_time
from nlcx.errors import ConfigError
from nlcx.layout import Layout
from nlcx.plants.base import Plant, equilibrium_input, linearize
from nlcx.validation import join

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


# --------------------------------------------------------------------------- design model


@dataclass(frozen=True)
class DiscreteModel:
    """x(k+1) = A x + B u, y = c x (deviations from the operating point), sampled at Ts."""

    A: np.ndarray
    B: np.ndarray
    c: np.ndarray  # (n,) row of the tracked output
    Ts: float
    x_eq: np.ndarray
    u_eq: np.ndarray
    y_eq: float


def zoh(Ac: np.ndarray, Bc: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation via the matrix exponential of [[A, B], [0, 0]] Ts."""
    n, m = Bc.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = Ac
    M[:n, n:] = Bc
    E = scipy.linalg.expm(M * Ts)
    return E[:n, :n].copy(), E[:n, n:].copy()


def companion_matrices(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the controllable canonical form with monic denominator coefficients a_0..a_{n-1}."""
    n = a.size
    A = np.zeros((n, n))
    A[:-1, 1:] = np.eye(n - 1)
    A[-1, :] = -np.asarray(a, dtype=float)
    B = np.zeros((n, 1))
    B[-1, 0] = 1.0
    return A, B


def _is_transfer_function(plant: Plant) -> bool:
    from nlcx.plants.transfer_function import companion_rhs

    return plant.rhs is companion_rhs


def linear_model(plant: Plant, Ts: float, output: int = 0, path: str = "controller") -> DiscreteModel:
    """Discrete linear model of ``plant`` at sample time Ts, tracking output ``output``.

    A transfer-function plant is exactly linear: its canonical (A, B) about the origin
    (x* = 0, u* = 0). Any other plant is linearised numerically about its initial state with
    the equilibrium input; if no input holds the initial state there, about the zero state.
    """
    c = np.asarray(plant.C[output], dtype=float).copy()
    n, m = len(plant.states), len(plant.inputs)
    if _is_transfer_function(plant):
        x_eq, u_eq = np.zeros(n), np.zeros(m)
        Ac, Bc = companion_matrices(np.asarray(plant.p, dtype=float))
    else:
        x_eq = np.asarray(plant.x0, dtype=float).copy()
        try:
            u_eq = equilibrium_input(plant, x_eq)
        except ConfigError:
            x_eq = np.zeros(n)
            try:
                u_eq = equilibrium_input(plant, x_eq)
            except ConfigError:
                raise ConfigError(
                    path,
                    plant.name,
                    "no input holds the plant at its initial or zero state: nothing to linearise about",
                ) from None
        Ac, Bc, _ = linearize(plant, x_eq, u_eq, relative=True)
    A, B = zoh(Ac, Bc, Ts)
    return DiscreteModel(A=A, B=B, c=c, Ts=Ts, x_eq=x_eq, u_eq=u_eq, y_eq=float(c @ x_eq))


@dataclass(frozen=True)
class Augmented:
    """xi(k+1) = Phi xi + Gu u + Gw w, z = Cz xi + Dz u (Cz' Dz = 0), w = [d(k+h+1); delta]."""

    Phi: np.ndarray
    Gu: np.ndarray
    Gw: np.ndarray
    Cz: np.ndarray
    Dz: np.ndarray
    n: int
    m: int
    h: int
    integrator: bool

    @property
    def Q(self) -> np.ndarray:
        return self.Cz.T @ self.Cz

    @property
    def R(self) -> np.ndarray:
        return self.Dz.T @ self.Dz

    @property
    def n_x(self) -> int:
        """Width of xhat = [x; v]."""
        return self.n + int(self.integrator)


def augment(
    model: DiscreteModel,
    h: int,
    q: float,
    r: float,
    integral: float | None = None,
    disturbance: bool = False,
) -> Augmented:
    """The preview servo's design model (see the module docstring)."""
    A, B, c, Ts = model.A, model.B, model.c, model.Ts
    n, m = B.shape
    n_i = 1 if integral else 0
    nd = h + 1
    N = n + n_i + nd
    Phi = np.zeros((N, N))
    Phi[:n, :n] = A
    if n_i:
        Phi[n, :n] = Ts * c
        Phi[n, n] = 1.0
        Phi[n, n + 1] = -Ts
    o = n + n_i
    Phi[o : o + h, o + 1 : o + nd] = np.eye(h)  # d(k+i) <- d(k+i+1)
    Gu = np.zeros((N, m))
    Gu[:n] = B
    n_w = 1 + (m if disturbance else 0)
    Gw = np.zeros((N, n_w))
    Gw[N - 1, 0] = 1.0
    if disturbance:
        Gw[:n, 1:] = B
    rows = 1 + n_i + m
    Cz = np.zeros((rows, N))
    Cz[0, :n] = math.sqrt(q) * c
    Cz[0, o] = -math.sqrt(q)
    if integral:
        Cz[1, n] = math.sqrt(integral)
    Dz = np.zeros((rows, m))
    Dz[1 + n_i :, :] = math.sqrt(r) * np.eye(m)
    return Augmented(Phi=Phi, Gu=Gu, Gw=Gw, Cz=Cz, Dz=Dz, n=n, m=m, h=h, integrator=bool(n_i))


# --------------------------------------------------------------------------- synthesis


def spectral_radius(M: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M)))) if M.size else 0.0


def h2_design(aug: Augmented) -> tuple[np.ndarray, np.ndarray]:
    """(K, X): the LQ / H2 state feedback u = K xi minimising sum ||z||^2, from the DARE."""
    X = scipy.linalg.solve_discrete_are(aug.Phi, aug.Gu, aug.Q, aug.R)
    X = (X + X.T) / 2
    K = -np.linalg.solve(aug.R + aug.Gu.T @ X @ aug.Gu, aug.Gu.T @ X @ aug.Phi)
    return K, X


@dataclass(frozen=True)
class HinfSolution:
    """The game Riccati equation at one gamma and whether it certifies ||T_zw||_inf < gamma."""

    gamma: float
    feasible: bool
    reason: str
    X: np.ndarray | None = None
    K: np.ndarray | None = None
    residual: float = math.inf


def riccati_residual(aug: Augmented, X: np.ndarray, gamma: float) -> float:
    """||X - Q - Phi'XPhi + Phi'XG (Rt + G'XG)^-1 G'XPhi|| / max(1, ||X||)."""
    G = np.hstack([aug.Gu, aug.Gw])
    Rt = scipy.linalg.block_diag(aug.R, -(gamma**2) * np.eye(aug.Gw.shape[1]))
    Phi = aug.Phi
    res = X - aug.Q - Phi.T @ X @ Phi + Phi.T @ X @ G @ np.linalg.solve(Rt + G.T @ X @ G, G.T @ X @ Phi)
    return float(np.max(np.abs(res)) / max(1.0, np.max(np.abs(X))))


def hinf_riccati(aug: Augmented, gamma: float, tol: float = 1e-9) -> HinfSolution:
    """Solve the H-infinity game Riccati equation for ``gamma`` and check its conditions.

    Feasible iff the (indefinite) DARE has a stabilising solution X with X >= 0,
    gamma^2 I - Gw' X Gw > 0 and u = K xi stabilising, K = first block of
    -(Rt + G'XG)^-1 G'X Phi. Then the full-information closed loop has ||T_zw||_inf < gamma.
    """
    m, n_w = aug.m, aug.Gw.shape[1]
    G = np.hstack([aug.Gu, aug.Gw])
    Rt = scipy.linalg.block_diag(aug.R, -(gamma**2) * np.eye(n_w))
    try:
        with np.errstate(all="ignore"):
            X = scipy.linalg.solve_discrete_are(aug.Phi, G, aug.Q, Rt)
    except (np.linalg.LinAlgError, ValueError) as exc:
        return HinfSolution(gamma, False, f"Riccati equation has no stabilising solution ({exc})")
    if not np.all(np.isfinite(X)):
        return HinfSolution(gamma, False, "Riccati solution is not finite")
    X = (X + X.T) / 2
    scale = max(1.0, float(np.max(np.abs(X))))
    if float(np.min(np.linalg.eigvalsh(X))) < -tol * scale:
        return HinfSolution(gamma, False, "Riccati solution is not positive semidefinite", X=X)
    W = gamma**2 * np.eye(n_w) - aug.Gw.T @ X @ aug.Gw
    if float(np.min(np.linalg.eigvalsh((W + W.T) / 2))) <= tol * gamma**2:
        return HinfSolution(gamma, False, "gamma^2 I - Gw' X Gw is not positive definite", X=X)
    try:
        KK = -np.linalg.solve(Rt + G.T @ X @ G, G.T @ X @ aug.Phi)
    except np.linalg.LinAlgError:
        return HinfSolution(gamma, False, "singular Riccati gain", X=X)
    K = KK[:m]
    if spectral_radius(aug.Phi + G @ KK) >= 1.0 or spectral_radius(aug.Phi + aug.Gu @ K) >= 1.0:
        return HinfSolution(gamma, False, "closed loop is not stable", X=X, K=K)
    residual = riccati_residual(aug, X, gamma)
    if residual > 1e-6:
        return HinfSolution(gamma, False, f"inaccurate Riccati solution (residual {residual:.2e})", X=X, K=K)
    return HinfSolution(gamma, True, "", X=X, K=K, residual=residual)


def gamma_min(aug: Augmented, tol: float = 1e-4, gamma_start: float = 1.0, max_iter: int = 200) -> float:
    """Smallest feasible gamma (to relative tolerance ``tol``) by bisection.

    The returned value is the upper end of the final bracket, so it is feasible; gamma below
    it by more than ``tol`` (relative) is not.
    """
    hi = gamma_start
    lo = 0.0
    for _ in range(80):
        if hinf_riccati(aug, hi).feasible:
            break
        lo, hi = hi, 2.0 * hi
    else:
        raise ValueError("no feasible gamma found (is the plant stabilisable?)")
    if lo == 0.0:
        # shrink until infeasible to get a finite lower end
        for _ in range(80):
            trial = hi / 2.0
            if not hinf_riccati(aug, trial).feasible:
                lo = trial
                break
            hi = trial
    for _ in range(max_iter):
        if hi - lo <= tol * hi:
            break
        mid = math.sqrt(lo * hi) if lo > 0 else hi / 2.0
        if hinf_riccati(aug, mid).feasible:
            hi = mid
        else:
            lo = mid
    return hi


@dataclass(frozen=True)
class PreviewDesign:
    """The designed gains: u = u* + Kx xhat + sum Kd[:, i] d(k+i), xhat = [x - x*; v]."""

    design: str
    model: DiscreteModel
    aug: Augmented
    K: np.ndarray
    X: np.ndarray
    gamma: float = math.nan
    gamma_min: float = math.nan

    @property
    def Kx(self) -> np.ndarray:
        """Gain on xhat = [x - x*; v] (m x (n + integrator))."""
        return self.K[:, : self.aug.n_x]

    @property
    def Kd(self) -> np.ndarray:
        """Preview gains K_d0 .. K_dh (m x (h + 1))."""
        return self.K[:, self.aug.n_x :]

    def closed_loop(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Acl, Bw, Ccl) of the closed loop w -> z."""
        a = self.aug
        return a.Phi + a.Gu @ self.K, a.Gw, a.Cz + a.Dz @ self.K


def design_preview(
    model: DiscreteModel,
    *,
    design: str = "hinf",
    h: int = 10,
    q: float = 1.0,
    r: float = 0.1,
    integral: float | None = 1.0,
    disturbance: bool = False,
    gamma_tolerance: float = 1e-4,
    gamma_factor: float = 1.05,
) -> PreviewDesign:
    """H2 or H-infinity preview gains for ``model`` (see the module docstring)."""
    aug = augment(model, h, q, r, integral, disturbance)
    if design == "h2":
        K, X = h2_design(aug)
        return PreviewDesign("h2", model, aug, K, X)
    g_min = gamma_min(aug, gamma_tolerance)
    gamma = gamma_factor * g_min
    sol = hinf_riccati(aug, gamma)
    if not sol.feasible:  # pragma: no cover - feasibility is monotone in gamma
        raise ValueError(f"H-infinity design infeasible at gamma = {gamma:.6g}: {sol.reason}")
    assert sol.K is not None and sol.X is not None
    return PreviewDesign("hinf", model, aug, sol.K, sol.X, gamma=gamma, gamma_min=g_min)


# --------------------------------------------------------------------------- run time


@njit(cache=True, error_model="numpy")
def _preview_row(t, dt, x, r, cp, cs, u, log):  # pragma: no cover - compiled
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
def preview_step(t, dt, x, y, r, cp, cs, u, log, callbacks):  # pragma: no cover - compiled
    """The preview servo (eq. 5.21), every row (full state information: it reads x)."""
    for b in range(x.shape[0]):
        _preview_row(t, dt, x[b], r[b], cp[b], cs[b], u[b], log[b])


class PreviewConfig(ControllerConfig):
    kind: Literal["preview"] = Field(
        "preview", description="registered name of this controller; selects the model that validates this section"
    )
    design: Literal["h2", "hinf"] = Field(
        "hinf", description="h2: LQ design; hinf: H-infinity design (game Riccati equation, bisection on gamma)"
    )
    preview: int = Field(
        10,
        ge=0,
        le=1000,
        description="preview length h: the controller reads r(t), r(t + T_s), ..., r(t + h T_s)",
        json_schema_extra={"unit": "samples"},
    )
    sample_time: float = Field(
        0.1,
        gt=0,
        description="controller sample time T_s, a whole number of simulation steps dt",
        json_schema_extra={"unit": "s"},
    )
    q: float = Field(
        1.0,
        gt=0,
        description=(
            "weight of the squared tracking error (c x - d)^2, d the reference's deviation from the operating point"
        ),
    )
    r: float = Field(
        0.1, gt=0, description="weight of the squared control effort u^2 (deviation from the equilibrium input)"
    )
    integral: float | None = Field(
        1.0,
        ge=0,
        description="weight of the squared error integral v^2; 0 or null: no integrator (no zero-offset guarantee)",
    )
    disturbance: bool = Field(
        False,
        description="add an input-disturbance channel (entering like u) to the H-infinity design's exogenous input",
    )
    gamma_tolerance: float = Field(1e-4, gt=0, lt=1, description="relative tolerance of the bisection on gamma")
    gamma_factor: float = Field(
        1.05, ge=1, description="the H-infinity design is made at gamma_factor * gamma_min (a numerical margin)"
    )
    signal: str | None = Field(
        None, description="plant output tracked (default: the plant's single output); its reference is previewed"
    )


class Preview(ControllerModel):
    """H2 / H-infinity preview servo with full state information (thesis section 5.5)."""

    Config = PreviewConfig
    step = staticmethod(preview_step)

    @staticmethod
    def tracked_output(cfg: PreviewConfig, plant: Plant, path: str) -> int:
        outputs = plant.output_names
        if cfg.signal is None:
            if len(outputs) != 1:
                raise ConfigError(
                    join(path, "signal"), None, f"{plant.name} has several outputs; name one of: {', '.join(outputs)}"
                )
            return 0
        if cfg.signal not in outputs:
            raise ConfigError(
                join(path, "signal"), cfg.signal, f"not an output of {plant.name}; allowed: {', '.join(outputs)}"
            )
        return outputs.index(cfg.signal)

    def design(self, cfg: PreviewConfig, plant: Plant, path: str = "controller") -> PreviewDesign:
        """The gains for ``plant`` under ``cfg``."""
        out = self.tracked_output(cfg, plant, path)
        model = linear_model(plant, cfg.sample_time, out, path)
        try:
            return design_preview(
                model,
                design=cfg.design,
                h=cfg.preview,
                q=cfg.q,
                r=cfg.r,
                integral=cfg.integral or None,
                disturbance=cfg.disturbance,
                gamma_tolerance=cfg.gamma_tolerance,
                gamma_factor=cfg.gamma_factor,
            )
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise ConfigError(
                join(path, "design"), cfg.design, f"no stabilising preview controller for {plant.name}: {exc}"
            ) from None

    def build(
        self, label: str, cfg: PreviewConfig, plant: Plant, path: str, dt: float | None = None
    ) -> ControllerInstance:
        if dt is not None:
            check_sample_time(cfg.sample_time, dt, path)
        d = self.design(cfg, plant, path)
        model, aug = d.model, d.aug
        n, m, h = aug.n, aug.m, aug.h
        Kv = d.Kx[:, n] if aug.integrator else np.zeros(m)
        cp = np.concatenate(
            [
                PREVIEW.pack(n=n, m=m, h=h, integrator=aug.integrator, sample_time=cfg.sample_time, y_eq=model.y_eq),
                model.x_eq,
                model.u_eq,
                model.c,
                d.Kx[:, :n].ravel(),
                Kv,
                d.Kd.ravel(),
            ]
        ).astype(float)
        signal = plant.output_names[self.tracked_output(cfg, plant, path)]
        log_names: list[str] = []
        log_units: list[str] = []
        for name in plant.input_names:
            suffix = "" if m == 1 else f".{name}"
            unit = plant.unit_of(name)
            log_names += [f"u{suffix}", f"preview{suffix}", f"feedback{suffix}"]
            log_units += [unit, unit, unit]
        unit_y = plant.unit_of(signal)
        log_names.append("integral")
        log_units.append(f"{unit_y}*s" if unit_y else "s")
        config = cfg.model_dump()
        records: dict[str, Any] = {"design": cfg.design, "preview": h, "sample_time": cfg.sample_time}
        if cfg.design == "hinf":
            records.update(gamma=d.gamma, gamma_min=d.gamma_min)
        records.update({f"Kx[{i}]": float(v) for i, v in enumerate(np.ravel(d.Kx))})
        records.update({f"Kd[{i}]": float(v) for i, v in enumerate(np.ravel(d.Kd))})
        return ControllerInstance(
            label=label,
            kind="preview",
            step=self.step,
            cp=np.ascontiguousarray(cp),
            cs0=np.zeros(STATE_HEAD + LOG_SIZE * m),
            reference_signals=(signal,) * (h + 1),
            reference_offsets=tuple(i * cfg.sample_time for i in range(h + 1)),
            log_names=tuple(log_names),
            log_units=tuple(log_units),
            config=config,
            records=records,
        )

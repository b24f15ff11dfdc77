"""The H2 and H-infinity preview servo's design (thesis section 5.5, eqs. 5.21-5.22): the
plant's discrete linear model, the preview design model and the Riccati syntheses.

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

import numpy as np
import scipy.linalg

from nlcx.errors import ConfigError
from nlcx.plants.base import Plant, equilibrium_input, linearize

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

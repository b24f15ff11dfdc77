"""ANFIS training (section 5.4.3): first-order Takagi-Sugeno, 2 inputs, 1 output, Jang's hybrid rule.

The network (Jang, 1993) has ``n`` membership functions per input and a grid partition, so
n^2 rules; rule r = i n + j fires with w_r = mu_{1,i}(x1) mu_{2,j}(x2) and proposes
f_r = p_r x1 + q_r x2 + r_r; the output is sum_r w_r f_r / sum_r w_r. The PID gains k_p,
k_i, k_d of the thesis's ANFIS controller are three such models of (e, de/dt).

Membership functions: the generalised bell mu = 1 / (1 + |(x - c) / a|^(2 b)) (default;
MATLAB's ``genfis1`` and Jang's paper) or the Gaussian mu = exp(-((x - c) / a)^2 / 2).
Initialisation (deterministic, as ``genfis1``): centres evenly spaced over the input's data
range [lo, hi]; adjacent functions cross at 1/2 midway between centres, i.e. bell
a = (hi - lo) / (2 (n - 1)), b = 2, Gaussian a = (hi - lo) / ((n - 1) 2 sqrt(2 ln 2))
(with n = 1: the centre in the middle and a = (hi - lo) / 2).

Hybrid learning, one epoch = one forward and one backward pass over the whole data:

- forward: premise fixed, the consequents (p, q, r) of all rules are the least-squares
  solution of the linear system (``numpy.linalg.lstsq``, minimum norm if rank deficient;
  inputs scaled to [0, 1] for conditioning);
- backward: consequents fixed, the premise parameters take one gradient step on
  E = 1/2 sum (y_hat - y)^2. The step has length k in the premise space scaled by the input
  ranges (Jang's eta = k / ||dE/dtheta||, applied to centres and widths in units of the input
  range and to the bell slopes as they are), with Jang's step-size rule: k grows by
  ``increase`` (1.1) after four consecutive reductions of the error. Initial k = 0.01, as
  MATLAB's ``anfis``.

``safeguard=True`` (default) accepts an epoch only if the root-mean-square error after its
forward pass does not exceed the current one; otherwise the premise step is undone and k is
halved. The per-epoch RMSE history is then non-increasing. ``safeguard=False`` is Jang's
rule verbatim (k also shrinks by ``decrease`` (0.9) after two consecutive up-down swings of
the error) and returns, as MATLAB does, the parameters of the epoch with the lowest error.
With ``batch_size`` the backward pass takes one step per shuffled minibatch (shuffled by
``numpy.random.default_rng(seed)``); the forward pass always uses all the data. Training is
otherwise deterministic, so the same data, options and seed give identical parameters.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from nlcx.layout import Layout

if TYPE_CHECKING:
    from pydantic import BaseModel

N_INPUTS = 2
#: Head of a packed model: MF kind (index in MF_KINDS), MFs per input, the inputs' ranges.
MODEL = Layout("AnfisModel", ("mf", "n_mfs", "x1_min", "x1_max", "x2_min", "x2_max"))
#: One rule's first-order consequent f = p x1 + q x2 + r.
CONSEQUENT = Layout("AnfisConsequent", ("p", "q", "r"))

MF_KINDS: tuple[str, ...] = ("gbell", "gauss")
#: Smallest width, as a fraction of the input range, and smallest bell slope b.
_MIN_WIDTH = 1e-3
_MIN_SLOPE = 0.5
#: With the safeguard, the step-size factor after a rejected epoch.
_REJECT = 0.5


@dataclass
class AnfisModel:
    """A first-order TS ANFIS with two inputs and a grid partition of ``n`` MFs per input."""

    #: "gbell" or "gauss".
    mf: str
    #: (2, n): MF centres c of input 1 (row 0) and input 2 (row 1).
    centres: np.ndarray
    #: (2, n): bell half-widths a, or Gaussian standard deviations.
    widths: np.ndarray
    #: (2, n): bell slopes b (ignored by the Gaussian; kept as 2 for a fixed layout).
    slopes: np.ndarray
    #: (n^2, 3): (p, q, r) of rule i n + j (MF i of input 1, MF j of input 2): f = p x1 + q x2 + r.
    consequents: np.ndarray
    #: (2, 2): [min, max] of each input (the training data's, unless given).
    ranges: np.ndarray

    def __post_init__(self) -> None:
        if self.mf not in MF_KINDS:
            raise ValueError(f"unknown membership function {self.mf!r}; allowed: {', '.join(MF_KINDS)}")
        self.centres = np.array(self.centres, dtype=float).reshape(2, -1)
        n = self.centres.shape[1]
        self.widths = np.array(self.widths, dtype=float).reshape(2, n)
        self.slopes = np.array(self.slopes, dtype=float).reshape(2, n)
        self.consequents = np.array(self.consequents, dtype=float).reshape(n * n, 3)
        self.ranges = np.array(self.ranges, dtype=float).reshape(2, 2)

    @property
    def n_mfs(self) -> int:
        return int(self.centres.shape[1])

    # ------------------------------------------------------------------ evaluation

    def memberships(self, X: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """mu_{1,i}(x1) and mu_{2,j}(x2), each (N, n)."""
        X = _as_inputs(X)
        first, second = (_mf(self.mf, X[:, d, None], self.centres[d], self.widths[d], self.slopes[d]) for d in range(2))
        return first, second

    def rule_outputs(self, X: npt.ArrayLike) -> np.ndarray:
        """f_r = p_r x1 + q_r x2 + r_r, (N, n^2)."""
        X = _as_inputs(X)
        c = self.consequents
        return X[:, 0, None] * c[:, 0] + X[:, 1, None] * c[:, 1] + c[:, 2]

    def predict(self, X: npt.ArrayLike, clip: bool = False) -> np.ndarray:
        """The ANFIS output at every row (x1, x2) of X, (N,). ``clip``: inputs clipped to ``ranges``."""
        inputs = _as_inputs(X)
        if clip:
            inputs = np.clip(inputs, self.ranges[:, 0], self.ranges[:, 1])
        mu1, mu2 = self.memberships(inputs)
        w = (mu1[:, :, None] * mu2[:, None, :]).reshape(len(inputs), -1)
        f = self.rule_outputs(inputs)
        den = w.sum(axis=1)
        num = (w * f).sum(axis=1)
        # no rule fires (only far outside the data): the plain mean of the rule outputs
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), f.mean(axis=1))

    # -------------------------------------------------------------------- packing

    def to_vector(self) -> np.ndarray:
        """A :data:`MODEL` head, then centres (2n), widths (2n), slopes (2n) of the input MFs
        (x1's n, then x2's) and the n^2 rules' :data:`CONSEQUENT` blocks (p, q, r)."""
        (x1_min, x1_max), (x2_min, x2_max) = self.ranges
        head = MODEL.pack(
            mf=MF_KINDS.index(self.mf), n_mfs=self.n_mfs, x1_min=x1_min, x1_max=x1_max, x2_min=x2_min, x2_max=x2_max
        )
        return np.concatenate(
            [
                head,
                self.centres.ravel(),
                self.widths.ravel(),
                self.slopes.ravel(),
                self.consequents.ravel(),
            ]
        )

    @classmethod
    def from_vector(cls, v: npt.ArrayLike) -> AnfisModel:
        v = np.asarray(v, dtype=float)
        head = MODEL.unpack(v)
        n = int(head["n_mfs"])
        if v.size != vector_size(n):
            raise ValueError(f"an ANFIS vector with {n} MFs per input has {vector_size(n)} entries, not {v.size}")
        o = MODEL.size
        block = N_INPUTS * n
        centres, widths, slopes = (v[o + k * block : o + (k + 1) * block] for k in range(3))
        ranges = [head["x1_min"], head["x1_max"], head["x2_min"], head["x2_max"]]
        return cls(MF_KINDS[int(head["mf"])], centres, widths, slopes, v[o + 3 * block :], np.array(ranges))

    def to_config(self) -> dict[str, object]:
        """The model as the ``anfis`` schedule's per-gain configuration (lists of floats)."""
        return {
            "mf": self.mf,
            "n_mfs": self.n_mfs,
            "ranges": self.ranges.tolist(),
            "centres": self.centres.ravel().tolist(),
            "widths": self.widths.ravel().tolist(),
            "slopes": self.slopes.ravel().tolist(),
            "consequents": self.consequents.ravel().tolist(),
        }

    @classmethod
    def from_config(cls, cfg: Mapping[str, object] | BaseModel) -> AnfisModel:
        """From :meth:`to_config`'s mapping (or a pydantic model with the same fields)."""

        def get(key: str) -> Any:  # a field of either form, of the type the model's field has
            return cfg.get(key) if isinstance(cfg, dict) else getattr(cfg, key)

        n = int(get("n_mfs"))
        slopes = get("slopes")
        if slopes is None:
            slopes = [2.0] * (2 * n)
        return cls(get("mf"), get("centres"), get("widths"), slopes, get("consequents"), get("ranges"))

    def copy(self) -> AnfisModel:
        return AnfisModel(
            self.mf,
            self.centres.copy(),
            self.widths.copy(),
            self.slopes.copy(),
            self.consequents.copy(),
            self.ranges.copy(),
        )


def vector_size(n_mfs: int) -> int:
    """Length of :meth:`AnfisModel.to_vector` with ``n_mfs`` MFs per input."""
    return MODEL.size + 3 * N_INPUTS * n_mfs + CONSEQUENT.size * n_mfs * n_mfs


def _as_inputs(X: npt.ArrayLike) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim == 1 and X.size == 2:
        X = X[None, :]
    if X.ndim != 2 or X.shape[1] != 2:
        raise ValueError(f"ANFIS inputs must have shape (N, 2), not {X.shape}")
    return X


def _mf(kind: str, x: np.ndarray, c: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    z = (x - c) / a
    if kind == "gbell":
        return 1.0 / (1.0 + np.abs(z) ** (2.0 * b))
    return np.exp(-0.5 * z * z)


def _mf_grads(kind: str, x: np.ndarray, c: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
    """mu and d mu / d(c, a, b), each (N, n)."""
    z = (x - c) / a
    if kind == "gbell":
        az = np.abs(z)
        mu = 1.0 / (1.0 + az ** (2.0 * b))
        m1 = mu * (1.0 - mu)
        with np.errstate(divide="ignore", invalid="ignore"):
            dc = np.where(az > 0, 2.0 * b * m1 / (x - c), 0.0)
            db = np.where(az > 0, -2.0 * m1 * np.log(np.where(az > 0, az, 1.0)), 0.0)
        da = 2.0 * b * m1 / a
        return mu, dc, da, db
    mu = np.exp(-0.5 * z * z)
    return mu, mu * z / a, mu * z * z / a, np.zeros_like(mu)


# ------------------------------------------------------------------------------ training


def initial_model(
    X: npt.ArrayLike, n_mfs: int = 3, mf: str = "gbell", ranges: npt.ArrayLike | None = None
) -> AnfisModel:
    """Premise from the data ranges (evenly spaced centres), zero consequents."""
    if mf not in MF_KINDS:
        raise ValueError(f"unknown membership function {mf!r}; allowed: {', '.join(MF_KINDS)}")
    if n_mfs < 1:
        raise ValueError("n_mfs must be at least 1")
    X = _as_inputs(X)
    rng_ = np.array([X.min(axis=0), X.max(axis=0)]).T if ranges is None else np.asarray(ranges, dtype=float)
    rng_ = rng_.reshape(2, 2)
    centres = np.empty((2, n_mfs))
    widths = np.empty((2, n_mfs))
    for d in range(2):
        lo, hi = rng_[d]
        span = hi - lo if hi > lo else 1.0
        if n_mfs == 1:
            centres[d] = 0.5 * (lo + hi)
            half = 0.5 * span
        else:
            centres[d] = np.linspace(lo, hi, n_mfs)
            half = span / (2 * (n_mfs - 1))  # MFs cross at 1/2 midway between centres
        widths[d] = half if mf == "gbell" else half / math.sqrt(2.0 * math.log(2.0))
    slopes = np.full((2, n_mfs), 2.0)
    return AnfisModel(mf, centres, widths, slopes, np.zeros((n_mfs * n_mfs, 3)), rng_)


def _scales(model: AnfisModel) -> tuple[np.ndarray, np.ndarray]:
    lo = model.ranges[:, 0]
    span = model.ranges[:, 1] - lo
    return lo, np.where(span > 0, span, 1.0)


def normalized_firing(model: AnfisModel, X: npt.ArrayLike) -> np.ndarray:
    """w_r / sum w, (N, n^2)."""
    mu1, mu2 = model.memberships(X)
    w = (mu1[:, :, None] * mu2[:, None, :]).reshape(len(mu1), -1)
    den = w.sum(axis=1, keepdims=True)
    return np.where(den > 0, w / np.where(den > 0, den, 1.0), 1.0 / w.shape[1])


def fit_consequents(model: AnfisModel, X: npt.ArrayLike, y: npt.ArrayLike) -> AnfisModel:
    """Forward pass: the least-squares consequents with the premise of ``model`` fixed (in place)."""
    X = _as_inputs(X)
    y = np.asarray(y, dtype=float).ravel()
    lo, span = _scales(model)
    Xn = (X - lo) / span
    wbar = normalized_firing(model, X)
    A = np.concatenate([wbar[:, :, None] * Xn[:, None, :], wbar[:, :, None]], axis=2).reshape(len(X), -1)
    theta = np.linalg.lstsq(A, y, rcond=None)[0].reshape(-1, 3)
    # back to the original inputs: pn (x1 - lo1) / s1 + qn (x2 - lo2) / s2 + rn
    p, q = theta[:, 0] / span[0], theta[:, 1] / span[1]
    model.consequents = np.column_stack([p, q, theta[:, 2] - p * lo[0] - q * lo[1]])
    return model


def premise_gradient(model: AnfisModel, X: npt.ArrayLike, y: npt.ArrayLike) -> np.ndarray:
    """dE/d(centres, widths, slopes) of E = 1/2 sum (y_hat - y)^2, consequents fixed: (3, 2, n)."""
    X = _as_inputs(X)
    y = np.asarray(y, dtype=float).ravel()
    n = model.n_mfs
    g1 = _mf_grads(model.mf, X[:, 0, None], model.centres[0], model.widths[0], model.slopes[0])
    g2 = _mf_grads(model.mf, X[:, 1, None], model.centres[1], model.widths[1], model.slopes[1])
    mu1, mu2 = g1[0], g2[0]
    W = mu1[:, :, None] * mu2[:, None, :]  # (N, n, n)
    S = W.sum(axis=(1, 2))
    F = model.rule_outputs(X).reshape(-1, n, n)
    yhat = (W * F).sum(axis=(1, 2)) / S
    G = (F - yhat[:, None, None]) / S[:, None, None]  # d y_hat / d w_ij
    err = (yhat - y)[:, None]
    dmu1 = err * (G * mu2[:, None, :]).sum(axis=2)  # dE / d mu_1i, (N, n)
    dmu2 = err * (G * mu1[:, :, None]).sum(axis=1)
    grad = np.empty((3, 2, n))
    for k in range(3):
        grad[k, 0] = (dmu1 * g1[k + 1]).sum(axis=0)
        grad[k, 1] = (dmu2 * g2[k + 1]).sum(axis=0)
    return grad


def rmse(model: AnfisModel, X: npt.ArrayLike, y: npt.ArrayLike) -> float:
    return float(np.sqrt(np.mean((model.predict(X) - np.asarray(y, dtype=float).ravel()) ** 2)))


def _premise_step(model: AnfisModel, X: np.ndarray, y: np.ndarray, k: float) -> AnfisModel:
    """One backward step of length k in range-scaled premise space; a new model."""
    _, span = _scales(model)
    scale = np.stack([np.broadcast_to(span[:, None], model.centres.shape)] * 2 + [np.ones_like(model.slopes)])
    if model.mf == "gauss":
        scale[2] = 0.0  # no slopes
    g = premise_gradient(model, X, y) * scale  # gradient in scaled coordinates
    norm = float(np.sqrt(np.sum(g * g)))
    new = model.copy()
    if not np.isfinite(norm) or norm == 0.0:
        return new
    step = -k * g / norm * scale  # back to the original units
    new.centres = model.centres + step[0]
    new.widths = np.maximum(model.widths + step[1], _MIN_WIDTH * span[:, None])
    new.slopes = np.maximum(model.slopes + step[2], _MIN_SLOPE) if model.mf == "gbell" else model.slopes.copy()
    return new


def train_anfis(
    X: npt.ArrayLike,
    y: npt.ArrayLike,
    n_mfs: int = 3,
    epochs: int = 100,
    seed: int = 0,
    mf: str = "gbell",
    step_size: float = 0.01,
    increase: float = 1.1,
    decrease: float = 0.9,
    safeguard: bool = True,
    batch_size: int | None = None,
    ranges: npt.ArrayLike | None = None,
) -> tuple[AnfisModel, list[float]]:
    """Train a 2-input ANFIS on (X (N, 2), y (N,)) by Jang's hybrid rule.

    Returns the model and the training RMSE history: entry 0 after the initial forward pass,
    entry k after epoch k (``epochs + 1`` entries; non-increasing with ``safeguard``).
    """
    X = _as_inputs(X)
    y = np.asarray(y, dtype=float).ravel()
    if len(y) != len(X):
        raise ValueError(f"X has {len(X)} rows but y has {len(y)} values")
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
        raise ValueError("training data must be finite")
    rng = np.random.default_rng(seed)
    model = fit_consequents(initial_model(X, n_mfs, mf, ranges), X, y)
    err = rmse(model, X, y)
    history = [err]
    best, best_err = model, err
    k = step_size
    errors = [err]  # every epoch's error, for the step-size rule
    for _ in range(epochs):
        trial = model
        if batch_size is None or batch_size >= len(X):
            trial = _premise_step(trial, X, y, k)
        else:
            order = rng.permutation(len(X))
            for start in range(0, len(X), batch_size):
                idx = order[start : start + batch_size]
                trial = _premise_step(trial, X[idx], y[idx], k)
        trial = fit_consequents(trial, X, y)
        trial_err = rmse(trial, X, y)
        if safeguard:
            if trial_err <= err:
                model, err = trial, trial_err
                errors.append(err)
                if len(errors) >= 5 and all(np.diff(errors[-5:]) < 0):
                    k *= increase
            else:
                k *= _REJECT
                errors = [err]
            history.append(err)
            continue
        model, err = trial, trial_err
        errors.append(err)
        history.append(err)
        if err < best_err:
            best, best_err = model, err
        d = np.diff(errors[-5:])
        if len(d) == 4 and np.all(d < 0):
            k *= increase
        elif len(d) == 4 and np.all(d[:-1] * d[1:] < 0):  # two up-down (or down-up) swings
            k *= decrease
    return (model if safeguard else best), history


def anfis_schedule(
    X: npt.ArrayLike,
    gains: npt.ArrayLike,
    clip: Mapping[str, object] | None = None,
    clip_inputs: bool = True,
    **train: Any,
) -> tuple[dict[str, object], dict[str, list[float]]]:
    """Train k_p, k_i, k_d models on (e, de/dt) -> gains (N, 3): the ``anfis`` schedule config and histories."""
    gains = np.asarray(gains, dtype=float)
    cfg: dict[str, object] = {"kind": "anfis", "clip_inputs": clip_inputs}
    histories = {}
    for col, name in enumerate(("kp", "ki", "kd")):
        model, history = train_anfis(X, gains[:, col], **train)
        cfg[name] = model.to_config()
        histories[name] = history
    if clip:
        cfg["clip"] = clip
    return cfg, histories

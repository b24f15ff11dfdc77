"""ANFIS gain schedule of section 5.4.3: three trained Takagi-Sugeno models (e, de/dt) -> k_p, k_i, k_d.

Each gain is a first-order TS ANFIS with two inputs, ``n_mfs`` generalised-bell or Gaussian
membership functions per input and n_mfs^2 rules (:mod:`nlcx.tuning.anfis` trains them and
writes this configuration with :meth:`nlcx.tuning.anfis.AnfisModel.to_config`):

    kind: anfis
    kp: {mf: gbell, n_mfs: 3, ranges: [[e_min, e_max], [de_min, de_max]],
         centres: [...2 n...], widths: [...2 n...], slopes: [...2 n...], consequents: [...3 n^2...]}
    ki: {...}
    kd: {...}
    clip_inputs: true            # (e, de/dt) clipped to each model's ranges before evaluation
    clip: {kp: {min: 0, max: 5}} # optional clipping of a gain

``centres``, ``widths`` and ``slopes`` list input 1 (e) first, then input 2 (de/dt);
``consequents`` lists (p, q, r) of rule i n + j (MF i of e, MF j of de/dt), f = p e + q de/dt + r.
A TS model extrapolates linearly beyond its training data, so by default the inputs are
clipped to the models' ranges (the data they were trained on). The compiled schedule gives
:meth:`AnfisModel.predict` (with ``clip=clip_inputs``) to rounding.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from nlcx.controllers.schedules import GainRange, ScheduleConfig, ScheduleModel
from nlcx.kernel.abi import CALLBACK_SIG
from nlcx.tuning.anfis import AnfisModel

GAINS: tuple[str, ...] = ("kp", "ki", "kd")


class AnfisModelConfig(BaseModel):
    """One trained ANFIS model (:meth:`nlcx.tuning.anfis.AnfisModel.to_config`)."""

    model_config = ConfigDict(extra="forbid")
    mf: Literal["gbell", "gauss"] = "gbell"
    n_mfs: int = Field(ge=1, le=50)
    #: [[x1 min, x1 max], [x2 min, x2 max]]: the inputs' training ranges.
    ranges: tuple[tuple[float, float], tuple[float, float]]
    centres: list[float]
    widths: list[float]
    #: Bell slopes b (ignored by Gaussians; default 2).
    slopes: list[float] | None = None
    consequents: list[float]

    @field_validator("ranges")
    @classmethod
    def _ordered(cls, value: tuple[tuple[float, float], ...]) -> tuple[tuple[float, float], ...]:
        for lo, hi in value:
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"each range must be finite [min, max] with min <= max, not [{lo:g}, {hi:g}]")
        return value

    @model_validator(mode="after")
    def _sizes(self) -> AnfisModelConfig:
        n = self.n_mfs
        expected = {"centres": 2 * n, "widths": 2 * n, "slopes": 2 * n, "consequents": 3 * n * n}
        for key, size in expected.items():
            values = getattr(self, key)
            if values is None:
                continue
            if len(values) != size:
                raise ValueError(f"{key} has {len(values)} values; {n} MFs per input need {size}")
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"{key} must be finite")
        if any(w <= 0 for w in self.widths):
            raise ValueError("widths must be positive")
        return self


class ANFISConfig(ScheduleConfig):
    kind: Literal["anfis"] = "anfis"
    kp: AnfisModelConfig
    ki: AnfisModelConfig
    kd: AnfisModelConfig
    #: Clip (e, de/dt) to each model's training ranges before evaluating it.
    clip_inputs: bool = True
    #: Optional clipping of gains to [min, max], by gain name.
    clip: dict[Literal["kp", "ki", "kd"], GainRange] = Field(default_factory=dict)

    @field_validator("clip")
    @classmethod
    def _clip_ordered(cls, value: dict[str, GainRange]) -> dict[str, GainRange]:
        for name, rng in value.items():
            if not rng.min <= rng.max:
                raise ValueError(f"{name}: min {rng.min:g} must not exceed max {rng.max:g}")
        return value


@njit(cache=True, error_model="numpy")
def _mf(kind, x, c, a, b):  # pragma: no cover - compiled
    z = (x - c) / a
    if kind == 0.0:
        return 1.0 / (1.0 + abs(z) ** (2.0 * b))
    return math.exp(-0.5 * z * z)


@njit(cache=True, error_model="numpy")
def anfis_eval(sp, off, x1, x2, clip):  # pragma: no cover - compiled
    """The TS model packed at sp[off:] (:meth:`AnfisModel.to_vector` layout) at (x1, x2)."""
    kind = sp[off]
    n = int(sp[off + 1])
    if clip:
        x1 = min(max(x1, sp[off + 2]), sp[off + 3])
        x2 = min(max(x2, sp[off + 4]), sp[off + 5])
    cb = off + 6
    ab = cb + 2 * n
    bb = ab + 2 * n
    pb = bb + 2 * n
    num = 0.0
    den = 0.0
    fsum = 0.0
    for i in range(n):
        m1 = _mf(kind, x1, sp[cb + i], sp[ab + i], sp[bb + i])
        for j in range(n):
            m2 = _mf(kind, x2, sp[cb + n + j], sp[ab + n + j], sp[bb + n + j])
            w = m1 * m2
            r = pb + 3 * (i * n + j)
            f = sp[r] * x1 + sp[r + 1] * x2 + sp[r + 2]
            num += w * f
            den += w
            fsum += f
    if den > 0.0:
        return num / den
    return fsum / (n * n)  # no rule fires: the mean rule output, as AnfisModel.predict


@njit(cache=True, error_model="numpy")
def _anfis_gain(p, o, which, e, edot, clip):  # pragma: no cover - compiled
    """Gain ``which`` (0 k_p, 1 k_i, 2 k_d) of the packed schedule at p[o:] (one row), clipped if set."""
    g = anfis_eval(p, o + int(p[o + 10 + which]), e, edot, clip)
    h = o + 1 + 3 * which
    if p[h] != 0.0:
        g = min(max(g, p[h + 1]), p[h + 2])
    return g


@njit(CALLBACK_SIG, cache=True, error_model="numpy")
def anfis_gains(t, e, edot, p, row, o):  # pragma: no cover - compiled
    """p[row, o:] = (clip inputs, 3 x (clip?, min, max), 3 model offsets, 3 packed models)."""
    sp = p[row]
    clip = sp[o] != 0.0
    kp = _anfis_gain(sp, o, 0, e, edot, clip)
    ki = _anfis_gain(sp, o, 1, e, edot, clip)
    kd = _anfis_gain(sp, o, 2, e, edot, clip)
    return kp, ki, kd


def models(cfg: ANFISConfig) -> dict[str, AnfisModel]:
    """The three configured models, by gain name."""
    return {name: AnfisModel.from_config(getattr(cfg, name)) for name in GAINS}


class ANFIS(ScheduleModel):
    """ANFIS (first-order Takagi-Sugeno) gain schedule, section 5.4.3."""

    Config = ANFISConfig
    gains = staticmethod(anfis_gains)

    def pack(self, cfg: ANFISConfig) -> np.ndarray:
        head = [1.0 if cfg.clip_inputs else 0.0]
        for name in GAINS:
            rng = cfg.clip.get(name)
            head += [0.0, 0.0, 0.0] if rng is None else [1.0, rng.min, rng.max]
        vectors = [m.to_vector() for m in models(cfg).values()]
        offsets = np.cumsum([13] + [v.size for v in vectors[:-1]])
        return np.concatenate([np.array(head + list(offsets), dtype=float), *vectors])


def anfis_surface(cfg: ANFISConfig | dict[str, Any], e: Any, edot: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k_p, k_i, k_d) at every (e, de/dt) (broadcast arrays), by :meth:`AnfisModel.predict`."""
    cfg = cfg if isinstance(cfg, ANFISConfig) else ANFISConfig.model_validate({"kind": "anfis", **cfg})
    e, edot = np.broadcast_arrays(np.asarray(e, dtype=float), np.asarray(edot, dtype=float))
    X = np.column_stack([e.ravel(), edot.ravel()])
    out = []
    for name, model in models(cfg).items():
        k = model.predict(X, clip=cfg.clip_inputs)
        rng = cfg.clip.get(name)
        if rng is not None:
            k = np.clip(k, rng.min, rng.max)
        out.append(k.reshape(e.shape))
    return out[0], out[1], out[2]

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
from typing import Literal, TypeAlias

import numpy as np
from numba import njit
from numpy.typing import ArrayLike
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from nlcx._numba_compat import hot_njit
from nlcx.controllers.schedules import GainRange, ScheduleConfig, ScheduleModel
from nlcx.kernel.signatures import FloatArray
from nlcx.layout import Layout
from nlcx.tuning.anfis import CONSEQUENT, MODEL, N_INPUTS, AnfisModel

#: A gain's name.
GainName: TypeAlias = Literal["kp", "ki", "kd"]
GAINS: tuple[GainName, ...] = ("kp", "ki", "kd")
#: One gain's clipping: whether, and to [min, max] (the fuzzy teacher's range).
CLIP = Layout("GainClip", ("clip", "min", "max"))
#: Head of the schedule block: clip the inputs to the training ranges?, each gain's CLIP
#: block, then where each gain's packed model starts (relative to the block).
ANFIS_HEAD = Layout(
    "AnfisHead",
    ("clip_inputs", *(f"{g}_{f}" for g in GAINS for f in CLIP.fields), *(f"{g}_model" for g in GAINS)),
)
A = ANFIS_HEAD.at
C = CLIP.at
M = MODEL.at
TS = CONSEQUENT.at
MODEL_SIZE = MODEL.size
CLIP_SIZE = CLIP.size
CONSEQUENT_SIZE = CONSEQUENT.size


class AnfisModelConfig(BaseModel):
    """One trained ANFIS model (:meth:`nlcx.tuning.anfis.AnfisModel.to_config`)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    mf: Literal["gbell", "gauss"] = Field("gbell", description="membership functions: generalised bell or Gaussian")
    n_mfs: int = Field(ge=1, le=50, description="membership functions per input")
    ranges: tuple[tuple[float, float], tuple[float, float]] = Field(
        description="[[x1 min, x1 max], [x2 min, x2 max]]: the inputs' (e, de/dt) training ranges"
    )
    centres: list[float] = Field(description="centres of the membership functions, those of x1 then of x2")
    widths: list[float] = Field(description="widths of the membership functions, in the order of centres")
    slopes: list[float] | None = Field(
        None, description="bell slopes b, in the order of centres (ignored by Gaussians; default 2)"
    )
    consequents: list[float] = Field(
        description="first-order Takagi-Sugeno consequents (p, q, r) of every rule, rule by rule"
    )

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
    kind: Literal["anfis"] = Field(
        "anfis", description="registered name of this gain schedule; selects the model that validates this section"
    )
    kp: AnfisModelConfig = Field(description="the trained model of k_p (written by the anfis tuner)")
    ki: AnfisModelConfig = Field(description="the trained model of k_i")
    kd: AnfisModelConfig = Field(description="the trained model of k_d")
    clip_inputs: bool = Field(True, description="clip (e, de/dt) to each model's training ranges before evaluating it")
    clip: dict[GainName, GainRange] = Field(
        default_factory=dict, description="optional clipping of gains to [min, max], by gain name"
    )

    @field_validator("clip")
    @classmethod
    def _clip_ordered(cls, value: dict[str, GainRange]) -> dict[str, GainRange]:
        for name, rng in value.items():
            if not rng.min <= rng.max:
                raise ValueError(f"{name}: min {rng.min:g} must not exceed max {rng.max:g}")
        return value


@njit(cache=True, error_model="numpy")
def _mf(kind: int, x: float, c: float, a: float, b: float) -> float:  # pragma: no cover - compiled
    z = (x - c) / a
    if kind == 0.0:
        return 1.0 / (1.0 + abs(z) ** (2.0 * b))
    return math.exp(-0.5 * z * z)


@njit(cache=True, error_model="numpy")
def anfis_eval(sp: FloatArray, off: int, x1: float, x2: float, clip: float) -> float:  # pragma: no cover - compiled
    """The TS model packed at sp[off:] (:meth:`AnfisModel.to_vector` layout) at (x1, x2)."""
    kind = sp[off + M.mf]
    n = int(sp[off + M.n_mfs])
    if clip:
        x1 = min(max(x1, sp[off + M.x1_min]), sp[off + M.x1_max])
        x2 = min(max(x2, sp[off + M.x2_min]), sp[off + M.x2_max])
    cb = off + MODEL_SIZE
    ab = cb + N_INPUTS * n
    bb = ab + N_INPUTS * n
    pb = bb + N_INPUTS * n
    num = 0.0
    den = 0.0
    fsum = 0.0
    for i in range(n):
        m1 = _mf(kind, x1, sp[cb + i], sp[ab + i], sp[bb + i])
        for j in range(n):
            m2 = _mf(kind, x2, sp[cb + n + j], sp[ab + n + j], sp[bb + n + j])
            w = m1 * m2
            r = pb + CONSEQUENT_SIZE * (i * n + j)
            f = sp[r + TS.p] * x1 + sp[r + TS.q] * x2 + sp[r + TS.r]
            num += w * f
            den += w
            fsum += f
    if den > 0.0:
        return num / den
    return fsum / (n * n)  # no rule fires: the mean rule output, as AnfisModel.predict


@njit(cache=True, error_model="numpy")
def _anfis_gain(
    p: FloatArray, o: int, which: int, e: float, edot: float, clip: float
) -> float:  # pragma: no cover - compiled
    """Gain ``which`` (0 k_p, 1 k_i, 2 k_d) of the packed schedule at p[o:] (one row), clipped if set."""
    g = anfis_eval(p, o + int(p[o + A.kp_model + which]), e, edot, clip)
    h = o + A.kp_clip + CLIP_SIZE * which
    if p[h + C.clip] != 0.0:
        g = min(max(g, p[h + C.min]), p[h + C.max])
    return g


@hot_njit(cache=True, error_model="numpy")
def anfis_gains(
    t: float, e: float, edot: float, p: FloatArray, row: int, o: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Eq. 5.12-5.14's gains from three TS models: p[row, o:] = an :data:`ANFIS_HEAD` (its
    model offsets relative to o), then the three packed models (:data:`MODEL` layout)."""
    sp = p[row]
    clip = sp[o + A.clip_inputs] != 0.0
    kp = _anfis_gain(sp, o, 0, e, edot, clip)
    ki = _anfis_gain(sp, o, 1, e, edot, clip)
    kd = _anfis_gain(sp, o, 2, e, edot, clip)
    return kp, ki, kd


def models(cfg: ANFISConfig) -> dict[GainName, AnfisModel]:
    """The three configured models, by gain name."""
    return {name: AnfisModel.from_config(getattr(cfg, name)) for name in GAINS}


class ANFIS(ScheduleModel):
    """ANFIS (first-order Takagi-Sugeno) gain schedule, section 5.4.3."""

    Config = ANFISConfig
    gains = staticmethod(anfis_gains)

    def pack(self, cfg: ANFISConfig) -> np.ndarray:
        vectors = [m.to_vector() for m in models(cfg).values()]
        offsets = np.cumsum([ANFIS_HEAD.size] + [v.size for v in vectors[:-1]])
        head: dict[str, float] = {"clip_inputs": cfg.clip_inputs}
        for name, offset in zip(GAINS, offsets, strict=True):
            rng = cfg.clip.get(name)
            head |= {f"{name}_clip": rng is not None, f"{name}_model": offset}
            head |= {f"{name}_min": rng.min, f"{name}_max": rng.max} if rng else {f"{name}_min": 0, f"{name}_max": 0}
        return np.concatenate([ANFIS_HEAD.pack(head), *vectors])


def anfis_surface(
    cfg: ANFISConfig | dict[str, object], e: ArrayLike, edot: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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

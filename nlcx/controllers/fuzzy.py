"""Fuzzy self-tuning PID gain schedule of section 5.4.1 (eqs. 5.12-5.14, Tables 5.2-5.7, 25 rules).

A two-input, three-output Mamdani system maps the error e = r - y and its rate de/dt to the
scaled gains k_p1, k_i1, k_d1 in [0, 1]; eqs. 5.12-5.14 inverted give the PID gains

    k_p = kp_min + k_p1 (kp_max - kp_min),   likewise k_i and k_d.

The schedule's configuration, its fuzzy sets and how their printed ranges are read are
:mod:`nlcx.controllers.fuzzy_config`'s; the compiled inference is
:mod:`nlcx.controllers.fuzzy_step`'s. Here: the plugin, which packs the tables the compiled
schedule reads (:meth:`Fuzzy.pack`), and the same inference vectorised with numpy
(:func:`fuzzy_surface`), for control-surface plots and tests.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from nlcx.controllers.fuzzy_config import OUTPUT_UNIVERSE, OUTPUTS, SET_NAMES, FuzzyConfig, as_config, membership
from nlcx.controllers.fuzzy_step import FUZZY_HEAD, N_OUTPUTS, N_SETS, OUTPUT_GRID, RANGE, fuzzy_gains
from nlcx.controllers.schedules import ScheduleModel, gain_ranges

__all__ = ["Fuzzy", "FuzzyConfig", "fuzzy_gains", "fuzzy_surface", "membership"]


def _tables(cfg: FuzzyConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Output grid z (n,), output memberships (3, 5, n) and rule table (3, 5, 5) of set indices."""
    z = np.linspace(*OUTPUT_UNIVERSE, cfg.resolution)
    mu = np.array([list(membership(cfg, out, z).values()) for out in OUTPUTS])
    rule = np.array([[SET_NAMES.index(s) for s in row] for row in cfg.rules])
    return z, mu, np.stack([rule] * len(OUTPUTS))


class Fuzzy(ScheduleModel):
    """Fuzzy self-tuning PID (Mamdani, 25 rules), section 5.4.1."""

    Config = FuzzyConfig
    gains = staticmethod(fuzzy_gains)

    def pack(self, cfg: FuzzyConfig) -> np.ndarray:
        z, mu, rules = _tables(cfg)
        (emin, emax), (dmin, dmax) = cfg.universes.e, cfg.universes.de_dt
        head = FUZZY_HEAD.pack(
            resolution=cfg.resolution, piecewise=cfg.centroid == "piecewise_linear",
            e_min=emin, e_max=emax, de_min=dmin, de_max=dmax,
        )  # fmt: skip
        ranges = [*cfg.sets.ranges("e"), *cfg.sets.ranges("de_dt"), *np.reshape(gain_ranges(cfg), (-1, 2))]
        sp = np.concatenate(
            [head, *(RANGE.pack(lower=lo, upper=hi) for lo, hi in ranges), rules.ravel().astype(float), z, mu.ravel()]
        )
        assert sp.size == OUTPUT_GRID + cfg.resolution * (1 + N_OUTPUTS * N_SETS)
        return sp


# ------------------------------------------------------------------ vectorised (numpy) surface


def fuzzy_surface(
    cfg: FuzzyConfig | dict[str, object], e: ArrayLike, edot: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k_p, k_i, k_d) at every (e, de/dt) (broadcast arrays), for control-surface plots and tests."""
    cfg = as_config(cfg)
    e, edot = np.broadcast_arrays(np.asarray(e, dtype=float), np.asarray(edot, dtype=float))
    shape = e.shape
    x = np.clip(e.ravel(), *cfg.universes.e)
    v = np.clip(edot.ravel(), *cfg.universes.de_dt)
    me = np.array(list(membership(cfg, "e", x).values()))  # (5, N)
    md = np.array(list(membership(cfg, "de_dt", v).values()))
    fire = np.minimum(me[:, None, :], md[None, :, :])  # (5 e, 5 de, N)
    z, mu, rules = _tables(cfg)
    ranges = (cfg.kp, cfg.ki, cfg.kd)
    out = []
    for o in range(len(OUTPUTS)):
        agg = np.zeros((x.size, z.size))
        for s in range(len(SET_NAMES)):
            mask = rules[o] == s
            if not mask.any():
                continue
            w = fire[mask].max(axis=0)  # W_s, (N,)
            agg = np.maximum(agg, np.minimum(w[:, None], mu[o, s][None, :]))
        if cfg.centroid == "discrete":
            num, den = agg @ z, agg.sum(axis=1)
        else:
            y1, y2 = agg[:, :-1], agg[:, 1:]
            h = np.diff(z)
            area = 0.5 * h * (y1 + y2)
            num = (h * h * (y1 + 2.0 * y2) / 6.0 + z[:-1] * area).sum(axis=1)
            den = area.sum(axis=1)
        k1 = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.5 * (z[0] + z[-1]))
        g = ranges[o]
        out.append((g.min + k1 * (g.max - g.min)).reshape(shape))
    return out[0], out[1], out[2]

"""Fuzzy self-tuning PID (section 5.4.1): tables, membership shapes, inference against scikit-fuzzy."""

from __future__ import annotations

import copy
import csv
from importlib.resources import files

import numpy as np
import pytest
import skfuzzy as fuzz

from nlcx import config, engine
from nlcx.controllers.fuzzy import Fuzzy, FuzzyConfig, fuzzy_gains, fuzzy_surface, membership
from nlcx.controllers.fuzzy_config import (
    DE_DT_UNIVERSE,
    E_UNIVERSE,
    OUTPUT_UNIVERSE,
    OUTPUTS,
    RULES,
    SET_NAMES,
    TABLE_SETS,
    VARIABLES,
)
from nlcx.errors import ConfigError
from nlcx.thesis.membership import membership_figure
from nlcx.validation import validate_model

GAINS = {"kp": {"min": 1.0, "max": 2.0}, "ki": {"min": 1.0, "max": 2.5}, "kd": {"min": 0.05, "max": 0.2}}
DATA = files("nlcx.thesis") / "data"
UNIVERSES = {"e": E_UNIVERSE, "de_dt": DE_DT_UNIVERSE} | {out: OUTPUT_UNIVERSE for out in OUTPUTS}

#: Section 5.4.1, rules 1-25 as printed: (e, de/dt, k_p1 = k_i1 = k_d1).
PRINTED_RULES = [
    ("NB", "NB", "NB"), ("NS", "NB", "NB"), ("ZE", "NB", "NS"), ("PS", "NB", "NS"), ("PB", "NB", "ZE"),
    ("NB", "NS", "NB"), ("NS", "NS", "NS"), ("ZE", "NS", "NS"), ("PS", "NS", "ZE"), ("PB", "NS", "PS"),
    ("NB", "ZE", "NS"), ("NS", "ZE", "NS"), ("ZE", "ZE", "ZE"), ("PS", "ZE", "PS"), ("PB", "ZE", "PS"),
    ("NB", "PS", "NS"), ("NS", "PS", "ZE"), ("ZE", "PS", "PS"), ("PS", "PS", "PS"), ("PB", "PS", "PB"),
    ("NB", "PB", "ZE"), ("NS", "PB", "PS"), ("ZE", "PB", "PS"), ("PS", "PB", "PB"), ("PB", "PB", "PB"),
]  # fmt: skip


def cfg_of(**extra) -> FuzzyConfig:
    return FuzzyConfig(**GAINS, **extra)


def compiled(sp: np.ndarray, e: float, edot: float) -> np.ndarray:
    """The compiled schedule, its tables placed in row 1 after unrelated parameters (offset 3)."""
    row = np.concatenate([[7.0, -1.0, 2.0], sp])
    p = np.stack([np.full_like(row, 5.0), row])
    return np.array(fuzzy_gains(0.0, float(e), float(edot), p, 1, 3))


# ------------------------------------------------------------------ tables and rules


def test_module_constants_are_the_thesis_extracts() -> None:
    """Tables 5.2-5.7 and the rule grid, as transcribed in nlcx/thesis/data."""
    with (DATA / "cstr_fuzzy_sets.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 25
    for row in rows:
        assert TABLE_SETS[row["variable"]][row["set"]] == (float(row["lower"]), float(row["upper"]))
        assert (row["shape"] == "trapezoidal") == (row["set"] in ("NB", "PB"))
    with (DATA / "cstr_fuzzy_universes.csv").open() as fh:
        uni = {r["name"]: (float(r["min"]), float(r["max"])) for r in csv.DictReader(fh)}
    assert uni["e"] == E_UNIVERSE and uni["de_dt"] == DE_DT_UNIVERSE and uni["kp1 ki1 kd1"] == OUTPUT_UNIVERSE
    with (DATA / "cstr_fuzzy_rules.csv").open() as fh:
        grid = [r for r in csv.reader(line for line in fh if not line.startswith("#"))]
    assert grid[0][1:] == list(SET_NAMES)
    assert [tuple(r[1:]) for r in grid[1:]] == list(RULES)
    assert [r[0] for r in grid[1:]] == list(SET_NAMES)


def test_printed_rules_are_the_default_grid() -> None:
    rules = cfg_of().rules
    for n, (e, de, out) in enumerate(PRINTED_RULES, start=1):
        assert rules[SET_NAMES.index(e)][SET_NAMES.index(de)] == out, f"rule {n}"
        assert SET_NAMES[(n - 1) % 5] == e and SET_NAMES[(n - 1) // 5] == de  # the documented numbering
    assert rules[2][2] == "ZE" and rules[0][0] == "NB" and rules[4][4] == "PB"  # rules 13, 1, 25


def test_a_single_rule_firing_gives_the_centroid_of_its_set() -> None:
    """Beyond the corners of the universes only rule 1 (or 25) fires, fully: the centroid of NB (PB)."""
    cfg = cfg_of()
    z = np.linspace(0, 1, 101)
    sp = Fuzzy().pack(cfg)
    for (e, de), name in [((-5.0, -40.0), "NB"), ((5.0, 40.0), "PB")]:
        for k, (out, gain) in enumerate(zip(OUTPUTS, GAINS.values(), strict=True)):
            mu = membership(cfg, out, z)[name]
            k1 = np.sum(z * mu) / np.sum(mu)
            expected = gain["min"] + k1 * (gain["max"] - gain["min"])
            assert compiled(sp, e, de)[k] == pytest.approx(expected, abs=1e-13)


# ------------------------------------------------------------------ membership functions


@pytest.mark.parametrize("variable", VARIABLES)
def test_membership_shapes(variable: str) -> None:
    cfg = cfg_of()
    umin, umax = UNIVERSES[variable]
    sets = TABLE_SETS[variable]

    def mu(name: str, x: float) -> float:
        return float(membership(cfg, variable, np.array([x]))[name][0])

    for name in ("NS", "ZE", "PS"):  # triangles: feet at lower, upper; peak at the midpoint
        lo, hi = sets[name]
        mid = 0.5 * (lo + hi)
        assert mu(name, lo) == 0.0 and mu(name, hi) == 0.0 and mu(name, mid) == 1.0
        assert mu(name, lo - 1e-9) == 0.0 and mu(name, hi + 1e-9) == 0.0
        assert mu(name, 0.5 * (lo + mid)) == pytest.approx(0.5, abs=1e-12)
        assert mu(name, 0.5 * (mid + hi)) == pytest.approx(0.5, abs=1e-12)
    lo, hi = sets["NB"]  # left shoulder: 1 up to the universe minimum (and below), 0 from upper
    assert lo < umin < hi
    for x in (umin - 10.0, lo, 0.5 * (lo + umin), umin):
        assert mu("NB", x) == 1.0
    assert mu("NB", 0.5 * (umin + hi)) == pytest.approx(0.5, abs=1e-12)
    assert mu("NB", hi) == 0.0 and mu("NB", umax) == 0.0
    lo, hi = sets["PB"]  # right shoulder: 0 up to lower, 1 from the universe maximum on
    assert lo < umax < hi
    for x in (umax, 0.5 * (umax + hi), hi, umax + 10.0):
        assert mu("PB", x) == 1.0
    assert mu("PB", 0.5 * (lo + umax)) == pytest.approx(0.5, abs=1e-12)
    assert mu("PB", lo) == 0.0 and mu("PB", umin) == 0.0


@pytest.mark.parametrize("variable", ["e", "kd1"])
def test_membership_figure(variable: str) -> None:
    fig = membership_figure(cfg_of(), variable)
    (ax,) = fig.axes
    assert len(ax.lines) == 5
    assert ax.get_title().startswith("Fuzzy Membership functions for ")
    assert [t.get_text() for t in ax.get_legend().get_texts()] == list(SET_NAMES)


# ---------------------------------------------------------------------------- inference


def skfuzzy_gains(e: float, de: float) -> tuple[np.ndarray, np.ndarray]:
    """k_p1, k_i1, k_d1 by scikit-fuzzy (membership, fmin/fmax, defuzz): (piecewise linear, discrete)."""

    def mfs(variable: str, x: np.ndarray) -> dict[str, np.ndarray]:
        s, (umin, umax) = TABLE_SETS[variable], UNIVERSES[variable]
        out = {
            "NB": fuzz.trapmf(x, [s["NB"][0], s["NB"][0], umin, s["NB"][1]]),
            "PB": fuzz.trapmf(x, [s["PB"][0], umax, s["PB"][1], s["PB"][1]]),
        }
        for name in ("NS", "ZE", "PS"):
            lo, hi = s[name]
            out[name] = fuzz.trimf(x, [lo, 0.5 * (lo + hi), hi])
        return out

    z = np.linspace(0.0, 1.0, 101)
    me = mfs("e", np.array([np.clip(e, *E_UNIVERSE)]))
    md = mfs("de_dt", np.array([np.clip(de, *DE_DT_UNIVERSE)]))
    area, discrete = [], []
    for out in OUTPUTS:
        mo = mfs(out, z)
        agg = np.zeros_like(z)
        for e_set, de_set, then in PRINTED_RULES:
            strength = np.fmin(me[e_set], md[de_set])[0]
            agg = np.fmax(agg, np.fmin(strength, mo[then]))
        area.append(fuzz.defuzz(z, agg, "centroid"))
        discrete.append(np.sum(z * agg) / np.sum(agg))  # MATLAB's sum(x .* mf) / sum(mf)
    return np.array(area), np.array(discrete)


def test_control_surface_agrees_with_scikit_fuzzy() -> None:
    """Same sets, rules, min/min/max and 101-point universe; inputs beyond the universes are clipped."""
    E, D = np.meshgrid(np.linspace(-1.7, 1.8, 25), np.linspace(-17.0, 5.5, 25), indexing="ij")
    ref = np.array([skfuzzy_gains(e, d) for e, d in zip(E.ravel(), D.ravel(), strict=True)])  # (N, 2, 3)
    lo = np.array([g["min"] for g in GAINS.values()])
    span = np.array([g["max"] - g["min"] for g in GAINS.values()])
    for mode, col in (("piecewise_linear", 0), ("discrete", 1)):
        ours = np.column_stack([k.ravel() for k in fuzzy_surface(cfg_of(centroid=mode), E, D)])
        assert np.max(np.abs((ours - lo) / span - ref[:, col])) < 1e-12, mode
    # the two centroids differ by the end weighting of the sampled aggregate only
    assert 1e-4 < np.max(np.abs(ref[:, 0] - ref[:, 1])) < 1e-2


@pytest.mark.parametrize("centroid", ["discrete", "piecewise_linear"])
def test_compiled_schedule_equals_the_surface(centroid: str) -> None:
    cfg = cfg_of(centroid=centroid)
    sp = Fuzzy().pack(cfg)
    es, ds = np.linspace(-2.0, 2.0, 41), np.linspace(-20.0, 8.0, 43)
    surface = np.stack(fuzzy_surface(cfg, es[:, None], ds[None, :]), axis=-1)
    for i, e in enumerate(es):
        for j, d in enumerate(ds):
            assert np.max(np.abs(compiled(sp, e, d) - surface[i, j])) < 1e-12


def test_gains_stay_within_their_ranges_and_vary() -> None:
    cfg = cfg_of()
    E, D = np.meshgrid(np.linspace(-3, 3, 121), np.linspace(-30, 15, 121))
    for k, g in zip(fuzzy_surface(cfg, E, D), GAINS.values(), strict=True):
        assert g["min"] <= k.min() and k.max() <= g["max"]
        assert k.max() - k.min() > 0.6 * (g["max"] - g["min"])
    # clipping: beyond the universes the gains are those at the edges
    a = np.stack(fuzzy_surface(cfg, [E_UNIVERSE[1], E_UNIVERSE[0]], [DE_DT_UNIVERSE[0], DE_DT_UNIVERSE[1]]))
    b = np.stack(fuzzy_surface(cfg, [9.0, -9.0], [-99.0, 99.0]))
    assert np.array_equal(a, b)


def test_inputs_are_clipped_to_their_universes() -> None:
    """With the thesis's sets clipping changes nothing (NB, PB are 1 beyond the edges, the triangles 0);
    a triangle reaching past the edge shows it: e = -1.8 is evaluated as e = -1.44 (de/dt = 5.5 as 4.3)."""
    cfg = cfg_of(sets={"e": {"NS": [-2.0, -0.214]}, "de_dt": {"PS": [-3.88, 6.0]}})
    sp = Fuzzy().pack(cfg)
    for (e, d), (e_edge, d_edge) in [((-1.8, 1.06), (-1.44, 1.06)), ((0.68, 5.5), (0.68, 4.3))]:
        edge = np.stack(fuzzy_surface(cfg, e_edge, d_edge))
        assert np.array_equal(np.stack(fuzzy_surface(cfg, e, d)), edge)
        assert np.max(np.abs(compiled(sp, e, d) - edge)) < 1e-12
    assert float(membership(cfg, "e", -1.8)["NS"]) != float(membership(cfg, "e", -1.44)["NS"])


def test_resolution_and_config_round_trip() -> None:
    coarse = cfg_of(resolution=11)
    assert Fuzzy().pack(coarse).size < Fuzzy().pack(cfg_of()).size
    again = FuzzyConfig.model_validate(coarse.model_dump())
    assert np.array_equal(Fuzzy().pack(again), Fuzzy().pack(coarse))
    # a partial override of one set keeps the other sets of the tables
    cfg = cfg_of(sets={"e": {"ZE": [-0.4, 0.5]}})
    assert cfg.sets.e.ZE == (-0.4, 0.5) and TABLE_SETS["e"]["NS"] == cfg.sets.e.NS
    assert TABLE_SETS["de_dt"]["ZE"] == cfg.sets.de_dt.ZE


# ------------------------------------------------------------------------- validation

BAD = [
    ({"sets": {"e": {"NS": [-0.2, -1.0]}}}, "sets.e.NS", "lower -0.2 must be below upper -1"),
    ({"sets": {"kp1": {"ZE": [0.4, 0.4]}}}, "sets.kp1.ZE", "must be below"),
    ({"sets": {"e": {"NB": [-1.2, -0.92]}}}, "sets", "e.NB = (-1.2, -0.92) must straddle the universe minimum -1.44"),
    ({"sets": {"ki1": {"PB": [0.753, 0.99]}}}, "sets", "ki1.PB = (0.753, 0.99) must straddle the universe maximum 1"),
    ({"universes": {"e": [-1.44, 3.0]}}, "sets", "e.PB = (0.9449, 2.64) must straddle the universe maximum 3"),
    ({"sets": {"de_dt": {"ZE": [-6.0, -3.0]}}}, "sets", "de_dt = -6.89 lies in no fuzzy set"),
    ({"rules": [list(r) for r in RULES[:2]] + [["NS", "NS", "ZE", "PX", "PS"], *RULES[3:]]}, "rules.2.3", "'NB'"),
    ({"rules": [list(r) for r in RULES[:4]]}, "rules", "5"),
    ({"resolution": 2}, "resolution", "3"),
    ({"centroid": "bisector"}, "centroid", "discrete"),
]


@pytest.mark.parametrize(("extra", "key", "message"), BAD)
def test_bad_configs_are_one_line_errors(extra: dict, key: str, message: str) -> None:
    path = "controllers.fz.loops.y.schedule"
    with pytest.raises(ConfigError) as info:
        validate_model(FuzzyConfig, {"kind": "fuzzy", **GAINS, **copy.deepcopy(extra)}, path)
    assert info.value.path == f"{path}.{key}"
    assert message in info.value.allowed
    assert "\n" not in info.value.line()


# ---------------------------------------------------------------------------- closed loop


def test_closed_loop_logs_the_scheduled_gains() -> None:
    """The schedule inside the compiled PID: logged gains = surface at the loop's (e, de/dt)."""
    cstr = {"num": [-1.117, 3.1472], "den": [1.0, 4.6429, 5.3821]}  # eq. 5.10
    dt = 1e-3
    raw = {
        "name": "fuzzy_test",
        "plant": {"name": "transfer_function", "params": cstr},
        "controllers": {"fz": {"kind": "pid", "loops": {"y": {"schedule": {"kind": "fuzzy", **GAINS}}}}},
        "reference": {"y": {"kind": "step", "time": 0.5}},
        "simulation": {"t_end": 6.0, "dt": dt},
    }
    (run,) = engine.run_experiment(config.build(raw)).runs
    assert run.status == "ok"
    e = run.r[:, 0] - run.x @ np.array(cstr["num"][::-1])
    edot = np.concatenate([[0.0], np.diff(e) / dt])  # the PID's backward difference
    expected = np.column_stack(fuzzy_surface(cfg_of(), e, edot))
    assert np.max(np.abs(run.log[:, :3] - expected)) < 1e-12
    assert np.ptp(run.log[:, 0]) > 0.1  # the gains are scheduled

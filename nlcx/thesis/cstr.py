"""Chapter 5 (the CSTR): Table 5.8, the parameter tables 5.1-5.7, the ZN variants and claims.

Table 5.8 compares five PID tunings on the transfer function 5.10: t_r, t_s (2 % band),
M_p (%), e_ss and the inverse-response magnitude (our undershoot, %) of sections 5.3-5.4.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import yaml

from nlcx.thesis import catalog

#: Table 5.8 column -> (nlcx metric, unit).
CSTR_METRICS = {
    "tr_s": ("rise_time", "s"),
    "ts_s": ("settling_time", "s"),
    "Mp_percent": ("overshoot", "%"),
    "ess": ("steady_state_error", ""),
    "inverse_response_percent": ("undershoot", "%"),
}


#: Our Table 5.8: method -> column -> value.
MethodValues = dict[str, dict[str, float]]


def _value(metrics: pd.DataFrame, controller: str, metric: str, signal: str = "C_B") -> float:
    """One metric of one controller's run on one signal (default the output C_B); NaN if absent."""
    rows = metrics[(metrics.controller == controller) & (metrics.metric == metric) & (metrics.signal == signal)]
    return float(rows.value.iloc[0]) if not rows.empty else math.nan


def method_values(records: dict[Path, Any], root: Path) -> MethodValues:
    """Our Table 5.8 numbers: method -> thesis column -> value."""
    out = {}
    for method, (file, label) in catalog.CSTR_METHODS.items():
        record = records[root / "ch5" / file]
        out[method] = {col: _value(record.metrics, label, metric) for col, (metric, _) in CSTR_METRICS.items()}
    return out


def table_5_8(records: dict[Path, Any], root: Path) -> pd.DataFrame:
    """method, metric, thesis, nlcx, delta, unit."""
    printed = catalog.cstr_table().set_index("method")
    ours = method_values(records, root)
    rows = []
    for method in catalog.CSTR_METHODS:
        for col, (_, unit) in CSTR_METRICS.items():
            thesis = float(printed.loc[method, col])
            value = ours[method][col]
            rows.append(
                {
                    "method": method,
                    "metric": col,
                    "thesis": thesis,
                    "nlcx": value,
                    "delta": value - thesis,
                    "unit": unit,
                }
            )
    return pd.DataFrame(rows)


def _tuning(record: Any, tuner: str) -> dict[str, float]:
    return {r["parameter"]: r["value"] for r in record.tuning if r["tuner"] == tuner}


def table_5_1(record: Any) -> pd.DataFrame:
    """The Ziegler-Nichols rules of Table 5.1 applied to the K_u, T_u found in the run."""
    from nlcx.tuning.ziegler_nichols import RULES, zn_gains

    zn = _tuning(record, "ziegler_nichols")
    ku, tu = float(zn["Ku"]), float(zn["Tu"])
    rows = []
    for rule, (a, ti, td) in RULES.items():
        kp, ki, kd = zn_gains(ku, tu, rule)
        rows.append({
            "controller": rule.upper(), "kp_rule": f"{a:g} Ku", "Ti_rule": f"Tu/{1 / ti:g}" if ti else "",
            "Td_rule": f"Tu/{1 / td:g}" if td else "", "Ku": ku, "Tu": tu, "kp": kp,
            "Ti": ti * tu if ti else math.nan, "Td": td * tu if td else math.nan, "ki": ki, "kd": kd,
        })  # fmt: skip
    return pd.DataFrame(rows)


def fuzzy_schedule(record: Any) -> dict[str, Any]:
    """The fuzzy schedule as run (after the ZN tuner filled in its gain ranges)."""
    loops = record.built["fuzzy"]["loops"]
    return next(iter(loops.values()))["schedule"]


def table_5_2(record: Any) -> pd.DataFrame:
    """Universes of discourse actually used, beside Table 5.2."""
    sched = fuzzy_schedule(record)
    printed = catalog.fuzzy_universes().set_index("name")
    rows = []
    for name in ("e", "de_dt"):
        lo, hi = sched["universes"][name]
        rows.append(
            {
                "variable": name,
                "role": "input",
                "nlcx_min": lo,
                "nlcx_max": hi,
                "thesis_min": float(printed.loc[name, "min"]),
                "thesis_max": float(printed.loc[name, "max"]),
            }
        )
    rows.append(
        {
            "variable": "kp1, ki1, kd1",
            "role": "output",
            "nlcx_min": 0.0,
            "nlcx_max": 1.0,
            "thesis_min": 0.0,
            "thesis_max": 1.0,
        }
    )
    return pd.DataFrame(rows)


def table_sets(record: Any, variable: str) -> pd.DataFrame:
    """The fuzzy sets of one variable actually used, beside Tables 5.3-5.7."""
    sched = fuzzy_schedule(record)
    printed = catalog.fuzzy_sets()
    printed = printed[printed.variable == variable].set_index("set")
    rows = []
    for name, (lo, hi) in sched["sets"][variable].items():
        rows.append(
            {
                "set": name,
                "shape": printed.loc[name, "shape"],
                "nlcx_lower": lo,
                "nlcx_upper": hi,
                "thesis_lower": float(printed.loc[name, "lower"]),
                "thesis_upper": float(printed.loc[name, "upper"]),
            }
        )
    return pd.DataFrame(rows)


def zn_variants(root: Path, out_dir: Path) -> pd.DataFrame:
    """Run the ZN loop variants of ``configs/thesis/ch5/zn_variants.yaml`` against Table 5.8's ZN row."""
    from nlcx import config as cfg
    from nlcx import engine, report

    spec = yaml.safe_load((root / "ch5" / "zn_variants.yaml").read_text(encoding="utf-8"))
    printed = catalog.cstr_table().set_index("method").loc["ZN"]
    rows = []
    for name, variant in spec["variants"].items():
        exp = cfg.load(
            root / "ch5" / spec["base"],
            [f"{k}={v!r}" if isinstance(v, str) else f"{k}={v}" for k, v in (variant.get("set") or {}).items()],
        )
        result = engine.run_experiment(exp)
        label = exp.controllers[0].label
        values = {col: _value(result.metrics, label, metric) for col, (metric, _) in CSTR_METRICS.items()}
        distance = math.sqrt(sum(
            ((values[c] - float(printed[c])) / max(abs(float(printed[c])), 1.0)) ** 2
            for c in ("tr_s", "ts_s", "Mp_percent", "inverse_response_percent")
        ))  # fmt: skip
        rows.append({"variant": name, "description": variant.get("description", ""), **values, "distance": distance})
    table = pd.DataFrame(rows).sort_values("distance", kind="stable")
    thesis_row = {
        "variant": "thesis (Table 5.8)",
        "description": "",
        **{c: float(printed[c]) for c in CSTR_METRICS},
        "distance": 0.0,
    }
    table = pd.concat([pd.DataFrame([thesis_row]), table], ignore_index=True)
    report.write_csv(out_dir / "tables" / "zn_variants.csv", table)
    return table


def _best(v: MethodValues, col: str) -> str:
    """The method with the smallest value in a Table 5.8 column (NaN counts as worst)."""
    return min(v, key=lambda m: v[m][col] if not math.isnan(v[m][col]) else math.inf)


def _listing(v: MethodValues, col: str) -> str:
    """Every method's value in a Table 5.8 column, e.g. ``ZN 1.2; Fuzzy 1.5; ...``."""
    return "; ".join(f"{m} {v[m][col]:.3g}" for m in v)


@dataclass(frozen=True)
class CstrClaim:
    """A claim of section 5.4 or the conclusion 5.6 about Table 5.8: ``holds`` decides it and
    ``evidence`` quotes the numbers, both from our Table 5.8 values (method -> column -> value)."""

    key: str
    source: str
    text: str
    holds: Callable[[MethodValues], bool]
    evidence: Callable[[MethodValues], str]


TABLE_5_8_CLAIMS = (
    CstrClaim(
        "zn-fastest-rise",
        "Table 5.8, 5.6",
        "ZN gives the shortest rise time",
        lambda v: _best(v, "tr_s") == "ZN",
        lambda v: "t_r: " + _listing(v, "tr_s"),
    ),
    CstrClaim(
        "anfis-best-ts",
        "Table 5.8, 5.6",
        "ANFIS gives the best settling time",
        lambda v: _best(v, "ts_s") == "ANFIS",
        lambda v: "t_s: " + _listing(v, "ts_s"),
    ),
    CstrClaim(
        "anfis-best-mp",
        "Table 5.8, 5.6",
        "ANFIS gives the smallest overshoot of the methods with overshoot (GA has none)",
        lambda v: min([m for m in v if m != "GA"], key=lambda m: v[m]["Mp_percent"]) == "ANFIS",
        lambda v: "M_p %: " + _listing(v, "Mp_percent"),
    ),
    CstrClaim(
        "hybrids-lower-mp",
        "Table 5.8",
        "Every hybrid method lowers M_p below ZN's",
        lambda v: all(v[m]["Mp_percent"] < v["ZN"]["Mp_percent"] for m in v if m != "ZN"),
        lambda v: "M_p %: " + _listing(v, "Mp_percent"),
    ),
    CstrClaim(
        "anfis-less-inverse",
        "5.4.3, 5.6",
        "ANFIS's inverse response is smaller than ZN's and fuzzy's",
        lambda v: (
            v["ANFIS"]["inverse_response_percent"]
            < min(v["ZN"]["inverse_response_percent"], v["Fuzzy"]["inverse_response_percent"])
        ),
        lambda v: "inverse response %: " + _listing(v, "inverse_response_percent"),
    ),
    CstrClaim(
        "ann-smallest-inverse",
        "5.4.2, 5.6",
        "The ANN PID reduces the inverse response the most and lowers M_p",
        lambda v: _best(v, "inverse_response_percent") == "ANN" and v["ANN"]["Mp_percent"] < v["ZN"]["Mp_percent"],
        lambda v: "inverse response %: " + _listing(v, "inverse_response_percent"),
    ),
    CstrClaim(
        "ga-sluggish-no-overshoot",
        "5.4.4",
        "GA tuning is sluggish (longest t_r) with zero overshoot",
        lambda v: max(v, key=lambda m: v[m]["tr_s"]) == "GA" and v["GA"]["Mp_percent"] <= 0.5,
        lambda v: f"t_r: {_listing(v, 'tr_s')} | M_p GA {v['GA']['Mp_percent']:.3g} %",
    ),
    CstrClaim(
        "zero-ess",
        "Table 5.8",
        "Every method reaches zero steady-state error",
        lambda v: all(abs(v[m]["ess"]) <= 0.01 for m in v),
        lambda v: "e_ss: " + _listing(v, "ess"),
    ),
    CstrClaim(
        "rhp-zero-inverse",
        "5.2, 5.3.1",
        "The RHP zero gives the ZN loop an inverse response (44.46 %)",
        lambda v: v["ZN"]["inverse_response_percent"] > 10,
        lambda v: f"ZN inverse response {v['ZN']['inverse_response_percent']:.3g} %",
    ),
)


def _preview_claims(preview: Any) -> list[tuple[str, str, str, bool, str]]:
    """Section 5.5 and 5.6 on Fig. 5.19: H∞ preview control tracks better, with less effort, than H2."""
    ise_h2, ise_inf = (_value(preview.metrics, label, "ise") for label in ("h2", "hinf"))
    eff_h2, eff_inf = (_value(preview.metrics, label, "control_effort", signal="u") for label in ("h2", "hinf"))
    return [
        (
            "hinf-better-tracking",
            "5.5, 5.6",
            "H∞ preview control tracks better (lower ISE) than H2",
            ise_inf < ise_h2,
            f"ISE: H2 {ise_h2:.4g}, H∞ {ise_inf:.4g}",
        ),
        (
            "hinf-less-effort",
            "5.5, 5.6",
            "H∞ preview control needs less control effort than H2",
            eff_inf < eff_h2,
            f"∫u² dt: H2 {eff_h2:.4g}, H∞ {eff_inf:.4g}",
        ),
    ]


def claims(records: dict[Path, Any], root: Path) -> list[dict[str, Any]]:
    """The claims of chapter 5 (section 5.4 and the conclusion 5.6), checked on our runs."""
    v = method_values(records, root)
    rows = [(c.key, c.source, c.text, c.holds(v), c.evidence(v)) for c in TABLE_5_8_CLAIMS]
    preview = records.get(root / "ch5" / "fig_5_19.yaml")
    if preview is not None:
        rows += _preview_claims(preview)
    return [
        {
            "chapter": 5,
            "pendulum": "cstr",
            "id": f"cstr-{key}",
            "source": source,
            "claim": text,
            "reproduced": "yes" if ok else "no",
            "evidence": evidence,
        }
        for key, source, text, ok, evidence in rows
    ]

"""Chapter 5 (the CSTR): Table 5.8, the parameter tables 5.1-5.7 and the ZN variants.

Table 5.8 compares five PID tunings on the transfer function 5.10: t_r, t_s (2 % band),
M_p (%), e_ss and the inverse-response magnitude (our undershoot, %) of sections 5.3-5.4.
The chapter's claims about it and about Fig. 5.19 are rows of the claims table
(:mod:`nlcx.thesis.claims`), which reads our Table 5.8 through :func:`method_values`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict, cast

import pandas as pd

from nlcx import safe_yaml
from nlcx.thesis import catalog

if TYPE_CHECKING:
    from nlcx.thesis.records import Record

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


def cstr_value(metrics: pd.DataFrame, controller: str, metric: str, signal: str = "C_B") -> float:
    """One metric of one controller's run on one signal (default the output C_B); NaN if absent."""
    rows = metrics[(metrics.controller == controller) & (metrics.metric == metric) & (metrics.signal == signal)]
    return float(rows.value.iloc[0]) if not rows.empty else math.nan


def method_values(records: Mapping[Path, Record], root: Path) -> MethodValues:
    """Our Table 5.8 numbers: method -> thesis column -> value."""
    out = {}
    for method, (file, label) in catalog.CSTR_METHODS.items():
        record = records[root / "ch5" / file]
        out[method] = {col: cstr_value(record.metrics, label, metric) for col, (metric, _) in CSTR_METRICS.items()}
    return out


def table_5_8(records: dict[Path, Record], root: Path) -> pd.DataFrame:
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


def _tuning(record: Record, tuner: str) -> dict[str, float]:
    return {r["parameter"]: r["value"] for r in record.tuning if r["tuner"] == tuner}


def table_5_1(record: Record) -> pd.DataFrame:
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


def fuzzy_schedule(record: Record) -> dict[str, Any]:
    """The fuzzy schedule as run (after the ZN tuner filled in its gain ranges)."""
    loops = record.built["fuzzy"]["loops"]
    return next(iter(loops.values()))["schedule"]


def table_5_2(record: Record) -> pd.DataFrame:
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


def table_sets(record: Record, variable: str) -> pd.DataFrame:
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


class _ZnVariant(TypedDict, total=False):
    #: Overrides of the base config: key -> value.
    set: dict[str, object]
    description: str


class _ZnVariants(TypedDict):
    """``configs/thesis/ch5/zn_variants.yaml``."""

    #: The base config, relative to the file.
    base: str
    variants: dict[str, _ZnVariant]


def zn_variants(root: Path, out_dir: Path) -> pd.DataFrame:
    """Run the ZN loop variants of ``configs/thesis/ch5/zn_variants.yaml`` against Table 5.8's ZN row."""
    from nlcx import config as cfg
    from nlcx import engine, report

    spec = cast(_ZnVariants, safe_yaml.load_file(root / "ch5" / "zn_variants.yaml"))
    printed = catalog.cstr_table().set_index("method").loc["ZN"]
    rows = []
    for name, variant in spec["variants"].items():
        exp = cfg.load(
            root / "ch5" / spec["base"],
            [f"{k}={v!r}" if isinstance(v, str) else f"{k}={v}" for k, v in (variant.get("set") or {}).items()],
        )
        result = engine.run_experiment(exp)
        label = exp.controllers[0].label
        values = {col: cstr_value(result.metrics, label, metric) for col, (metric, _) in CSTR_METRICS.items()}
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

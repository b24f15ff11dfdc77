"""docs/fidelity.md from the identification study's outputs, and the selected profile.

    python scripts/fidelity_report.py doc results/identify > docs/fidelity.md
    python scripts/fidelity_report.py profile results/identify > configs/thesis/profiles/selected.yaml
    python scripts/fidelity_report.py replication results/identify > docs/replication.md

`make identify` runs the studies, the two reproductions (literal and selected profiles) and
the consistency study, then this. Every number on the page comes from those outputs (the
ranking CSVs, the pendulum study's screening.csv, the fits' JSON files, study.json, claims.csv
and the tables of each reproduction, the consistency study); the narrative is the template
scripts/templates/fidelity.md.j2.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
import pandas as pd
import yaml

from nlcx.thesis import hypotheses, profiles, split
from nlcx.thesis.fitting import DEFINITIONS, scores

ROOT = Path(__file__).resolve().parents[1]
SPLIT = ROOT / "configs" / "identify" / "split.yaml"
PENDULUM_SPEC = ROOT / "configs" / "identify" / "pendulum_all.yaml"
CSTR_SPEC = ROOT / "configs" / "identify" / "cstr.yaml"
CONSISTENCY_SPEC = ROOT / "configs" / "identify" / "consistency.yaml"
TARGETED_SPEC = ROOT / "configs" / "identify" / "targeted.yaml"
#: A set of printed cells counts as robustly inconsistent when the loop nearest to it misses
#: by at least this much (relative) under every definition of t_r and t_s.
ROBUST_MISS = 0.2
#: The study's targets (test set, selected profile): measure -> (goal, bound, sense).
TARGETS = {
    "proposed, median relative error": ("≤ 0.25", 0.25, -1),
    "conventional, median relative error": ("≤ 0.20", 0.20, -1),
    "direction agreement": ("≥ 0.85", 0.85, 1),
    "Table 5.8 test rows, median relative error": ("≤ 0.25", 0.25, -1),
    "claims: yes": ("≥ 90", 90, 1),
}
CSTR_METRICS = ("tr_s", "ts_s", "Mp_percent")


def fmt(value: Any, digits: int = 3) -> str:
    """A number as the page shows it: — for missing, inf, or ``digits`` decimals."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    if isinstance(value, float) and abs(value) >= 1000:
        return f"{value:.3g}"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def table_5_8_errors(directory: Path) -> tuple[pd.DataFrame, pd.Series]:
    """Table 5.8's rows of the CSTR metrics with a printed value other than 0, and each one's
    relative error |nlcx - thesis| / |thesis| (inf where nlcx has no value)."""
    table_5_8 = pd.read_csv(directory / "tables" / "table_5_8.csv")
    rows = table_5_8[table_5_8.metric.isin(CSTR_METRICS) & (table_5_8.thesis != 0)]
    return rows, ((rows.nlcx - rows.thesis).abs() / rows.thesis.abs()).fillna(np.inf)


def reproduction(directory: Path, spec_split: split.Split) -> dict[str, Any]:
    """A reproduction's claims counts, its pendulum test scores and its Table 5.8 test error."""
    claims = pd.read_csv(directory / "claims.csv").reproduced.value_counts()
    rows = []
    for part in split.PARTS:
        for table in getattr(spec_split.pendulum, part):
            frame = pd.read_csv(directory / "tables" / f"table_{table.replace('.', '_')}.csv")
            frame = frame[frame.metric.isin(spec_split.metrics)]
            rows.append(frame.assign(part=part, table=table)[["part", "table", "signal", "controller", "metric",
                                                              "thesis", "nlcx"]])  # fmt: skip
    cstr, rel = table_5_8_errors(directory)
    return {
        "claims": {v: int(claims.get(v, 0)) for v in ("yes", "partly", "no")},
        "scores": scores(pd.concat(rows, ignore_index=True)),
        "table_5_8_test": float(np.median(rel[cstr.method.isin(spec_split.cstr.test)])),
    }


def ranking_rows(ranking: pd.DataFrame, top: int) -> list[dict[str, Any]]:
    shown = pd.concat([ranking.head(top), ranking[ranking.hypothesis == "literal"]]).drop_duplicates("hypothesis")
    return shown.to_dict("records")


def families_rows(families: dict[str, dict[str, hypotheses.OptionValue]]) -> list[dict[str, str]]:
    """One row per family: its values (the first is the default) and what each does."""
    return [
        {
            "family": name,
            "choices": ", ".join(values),
            "docs": "; ".join(f"*{v}*: {o.doc}" for v, o in values.items()).replace("|", "\\|"),
            "free": ", ".join(
                dict.fromkeys(f"{k} ∈ [{lo:g}, {hi:g}]" for o in values.values() for k, (lo, hi) in o.free.items())
            ),
        }
        for name, values in families.items()
    ]


def screening_rows(study: Path) -> list[dict[str, Any]]:
    """The screening table of a study (its screening.csv: family, best value, train loss, gain,
    forwarded), best gain first; none for a study without a screen."""
    path = study / "screening.csv"
    if not path.is_file():
        return []
    table = pd.read_csv(path, dtype={"family": str, "best_value": str, "forwarded": str})
    return table.to_dict("records")


def targets(literal: dict[str, Any], selected: dict[str, Any]) -> list[dict[str, Any]]:
    """The study's targets with the literal and selected profiles' values (reproductions)."""

    def values(rep: dict[str, Any]) -> list[float]:
        s = rep["scores"]
        return [s["test_proposed_median_rel_error"], s["test_conventional_median_rel_error"],
                s["test_direction_agreement"], rep["table_5_8_test"], rep["claims"]["yes"]]  # fmt: skip

    rows = []
    for (name, (goal, bound, sense)), lit, sel in zip(TARGETS.items(), values(literal), values(selected),
                                                              strict=True):  # fmt: skip
        rows.append({"measure": name, "goal": goal, "literal": lit, "selected": sel,
                     "reached": sense * (sel - bound) >= 0})  # fmt: skip
    return rows


def context(results: Path) -> dict[str, Any]:
    spec_split = split.load(SPLIT)
    pend = pd.read_csv(results / "pendulum_all" / "ranking.csv")
    cstr = pd.read_csv(results / "cstr" / "ranking.csv")
    best = pend.iloc[0]
    pendulum_spec = yaml.safe_load(PENDULUM_SPEC.read_text())
    examined = pendulum_spec.get("families", list(hypotheses.FAMILIES))
    screened = screening_rows(results / "pendulum_all")
    literal_rep = reproduction(results / "reproduce_literal", spec_split)
    selected_rep = reproduction(results / "reproduce_selected", spec_split)
    return {
        "split": spec_split,
        "pendulum_spec": pendulum_spec,
        "cstr_spec": yaml.safe_load(CSTR_SPEC.read_text()),
        "families": families_rows({f: hypotheses.FAMILIES[f] for f in examined}),
        "screening": screened,
        "screening_singles": len(hypotheses.family(examined, 1)) - 1,
        "forwarded": [r["family"] for r in screened if r["forwarded"] == "yes"],
        "cstr_families": families_rows(hypotheses.CSTR_FAMILIES),
        "pend": pend,
        "pend_study": json.loads((results / "pendulum_all" / "study.json").read_text()),
        "pend_top": ranking_rows(pend, 10),
        "pend_best": best,
        "pend_literal": pend[pend.hypothesis == "literal"].iloc[0],
        "default_profile": "selected" if rule_chose_selected(pend) else "literal",
        "min_validation_gain": profiles.MIN_VALIDATION_GAIN,
        "pend_values": json.loads(best["values"]),
        "singles": [r for r in pend.to_dict("records") if len(json.loads(r["options"])) <= 1],
        "definitions": pd.read_csv(results / "pendulum_all" / "definitions.csv").to_dict("records"),
        "cstr": cstr,
        "cstr_study": json.loads((results / "cstr" / "study.json").read_text()),
        "cstr_top": ranking_rows(cstr, 10),
        "cstr_best": cstr.iloc[0],
        "cstr_literal": cstr[cstr.hypothesis == "literal"].iloc[0],
        "literal": literal_rep,
        "selected": selected_rep,
        "targets": targets(literal_rep, selected_rep),
        **consistency(results / "consistency"),
        "final_round": final_round(results),
        "targeted": targeted(results / "targeted"),
        "frozen": frozen_rows(results),
    }


#: The frozen-gain analyses `make identify` writes (`nlcx linearize`): directory -> (what, axis).
FROZEN = {
    "frozen_conventional": ("conventional PID, x_error_ags.yaml", None),
    "frozen_error_ags": ("error-AGS PID, x_error_ags.yaml, frozen at e", "e"),
    "frozen_time_ags": ("time-AGS PID, x_time_ags.yaml, frozen at t", "t"),
}


def frozen_rows(results: Path) -> list[dict[str, Any]]:
    """Per frozen point: the least damped pole pair (zeta, omega_n), the slowest pole, and the
    margins of the loop broken at F_x (with the loop transfer's unstable poles)."""
    rows = []
    for name, (what, axis) in FROZEN.items():
        directory = results / name
        if not directory.is_dir():
            continue
        poles = pd.read_csv(directory / ("poles_along.csv" if axis else "poles.csv"))
        margins = pd.read_csv(directory / ("margins_along.csv" if axis else "margins.csv"))
        points = sorted(poles[axis].unique()) if axis else [None]
        picks = sorted({points[round(q * (len(points) - 1))] for q in (0, 0.1, 0.25, 0.5, 1)}) if axis else [None]
        for point in picks:
            here = poles if point is None else poles[poles[axis] == point]
            slow = here[here.real > -100]  # the derivative's realisation poles are near -2/dt
            pair = slow[slow.imag.abs() > 1e-9].sort_values("zeta")
            cut = margins if point is None else margins[margins[axis] == point]
            at_input = cut[cut.opening == "input"].iloc[0]
            rows.append({
                "what": what,
                "point": "—" if point is None else f"{axis} = {point:g}",
                "zeta": float(pair.zeta.iloc[0]) if len(pair) else math.nan,
                "omega_n": float(pair.omega_n.iloc[0]) if len(pair) else math.nan,
                "slowest": float(slow.real[slow.real < -1e-9].max()),
                "gm": float(at_input.gain_margin),
                "pm": float(at_input.phase_margin),
                "rhp": int(at_input.rhp_poles),
            })  # fmt: skip
    return rows


def consistency(study: Path) -> dict[str, Any]:
    """What the page shows of the consistency study (nlcx/thesis/consistency/): one row per
    printed column (table, controller), the families each was examined under (summary.json)."""
    spec = yaml.safe_load(CONSISTENCY_SPEC.read_text())
    definitions = spec.get("definitions") or list(DEFINITIONS)
    summary = json.loads((study / "summary.json").read_text())
    columns = pd.read_csv(study / "columns.csv", dtype={"table": str, "also_printed_in": str}).fillna(
        {"also_printed_in": ""}
    )
    rows = []
    for _, group in columns.groupby(["table", "controller"], sort=False):
        first = group.iloc[0].to_dict()
        others = group.iloc[1:]
        rows.append({**first, "others": " / ".join(str(v) for v in others.most_cells_hit) or "—",
                     "reproduced_any": bool(group.reproduced.any())})  # fmt: skip
    cells = pd.read_csv(study / "cells.csv", dtype={"table": str, "text": str})
    train = split.load(SPLIT).pendulum.train
    train_cells = cells[cells.table.isin(train) & (cells.definition == definitions[0])]
    subsets = pd.read_csv(study / "subsets.csv", dtype={"table": str})
    keys = list(dict.fromkeys(zip(columns.table, columns.controller, strict=True)))

    def of(table: str, controller: str) -> pd.DataFrame:
        return subsets[(subsets.table == table) & (subsets.controller == controller)]

    return {
        "consistency_spec": {**spec, "definitions": definitions, "cloud": spec.get("cloud", {"n": 1500})},
        "consistency_summary": summary,
        "consistency_study": json.loads((study / "study.json").read_text()),
        "consistency_hypotheses": sum(c["hypotheses"] for c in summary["columns"]),
        "consistency_columns": rows,
        "consistency_reproduced": [f"{r['table']} {r['controller']}" for r in rows if r["reproduced_any"]],
        "consistency_train_cells": train_cells.to_dict("records"),
        "consistency_sets_total": len(subsets),
        "consistency_robust": subsets[subsets.least_miss >= ROBUST_MISS].to_dict("records"),
        "consistency_weak": [
            {"table": f"{t} {c}", "least": float(of(t, c).least_miss.max())}
            for t, c in keys
            if len(of(t, c)) and not (of(t, c).least_miss >= ROBUST_MISS).any()
        ],
        "consistency_train_sets": subsets[subsets.table.isin(train)].to_dict("records"),
    }


def final_round(results: Path) -> dict[str, Any] | None:
    """The final round (configs/identify/final_round.yaml), if it ran: its ranking, its rank 1
    against the study's rank 1 (R1, refitted in the round) and the pre-registered rule's
    decision (:func:`nlcx.thesis.profiles.final_round_selects`)."""
    study = results / "final_round"
    if not (study / "ranking.csv").is_file():
        return None
    ranking = pd.read_csv(study / "ranking.csv")
    first = str(pd.read_csv(results / "pendulum_all" / "ranking.csv").hypothesis.iloc[0])
    best, current = ranking.iloc[0], ranking[ranking.hypothesis == first].iloc[0]
    gain = 1.0 - float(best.validation_median_rel_error) / float(current.validation_median_rel_error)
    return {
        "study": json.loads((study / "study.json").read_text()),
        "rows": ranking.to_dict("records"),
        "best": best,
        "current": current,
        "gain": gain,
        "selects": best.hypothesis != current.hypothesis and profiles.final_round_selects(best, current),
    }


def targeted(study: Path) -> dict[str, Any] | None:
    """The targeted search (configs/identify/targeted.yaml), if it ran: one row per set searched,
    its verdict counts and the spec's budget."""
    if not (study / "targeted.csv").is_file():
        return None
    table = pd.read_csv(study / "targeted.csv", dtype={"table": str})
    spec = yaml.safe_load(TARGETED_SPEC.read_text())
    counts = table.verdict.value_counts()
    return {
        "spec": spec,
        "study": json.loads((study / "study.json").read_text()),
        "rows": table.to_dict("records"),
        "counts": {v: int(counts.get(v, 0)) for v in ("reachable", "undecided", "unreachable")},
        "loops": int(table.loops.sum()),
        "candidates": int((pd.read_csv(study.parent / "consistency" / "subsets.csv").least_miss >= ROBUST_MISS).sum()),
        "unreachable_columns": sorted(set(table[table.verdict == "unreachable"].table)),
    }


def claims_cell(row: Any) -> str:
    """'yes / partly / no' of a ranking row with claims, — otherwise."""
    values = [row.get(f"claims_{v}") for v in ("yes", "partly", "no")]
    if any(v is None or (isinstance(v, float) and math.isnan(v)) for v in values):
        return "—"
    return " / ".join(str(int(v)) for v in values)


def chapter_tables(results: Path, searched: dict[str, Any] | None) -> dict[int, dict[str, Any]]:
    """Per chapter of the thesis, from the two reproductions (``literal`` and ``selected``
    profiles): each table's cells within tolerance and verdict (report_summary.csv), the claims'
    verdicts (claims.csv), for chapter 5 each method's median relative error in Table 5.8, and
    the verdicts of the targeted search's sets (``searched``, :func:`targeted`)."""
    chapters: dict[int, dict[str, Any]] = {c: {"tables": {}, "claims": {}} for c in (2, 3, 4, 5)}
    for profile in ("literal", "selected"):
        directory = results / f"reproduce_{profile}"
        summary = pd.read_csv(directory / "report_summary.csv")
        for row in summary[summary.cells > 0].itertuples():
            chapter = int(str(row.table).split()[-1].split(".")[0])
            entry = chapters[chapter]["tables"].setdefault(
                str(row.table), {"table": str(row.table), "cells": row.cells}
            )
            entry[profile] = {"within": int(row.within_tolerance), "verdict": str(row.verdict)}
        for table in sorted((directory / "tables").glob("table_[234]_*.csv")):
            statuses = pd.read_csv(table).get("nlcx_status", pd.Series(dtype=str))
            chapter = int(table.stem.split("_")[1])
            runs = chapters[chapter].setdefault("not_ok", {}).setdefault(profile, 0)
            chapters[chapter]["not_ok"][profile] = runs + int((statuses.dropna() != "ok").sum())
        claims = pd.read_csv(directory / "claims.csv")
        for chapter, group in claims.groupby("chapter"):
            counts = group.reproduced.value_counts()
            chapters[int(chapter)]["claims"][profile] = {v: int(counts.get(v, 0)) for v in ("yes", "partly", "no")}
        rows, rel = table_5_8_errors(directory)
        per_method = rel.groupby(rows.method, sort=False).median()
        chapters[5].setdefault("methods", {})[profile] = {str(k): float(v) for k, v in per_method.items()}
    for chapter, entry in chapters.items():
        entry["tables"] = list(entry["tables"].values())
        mine = [r for r in searched["rows"] if str(r["table"]).split(".")[0] == str(chapter)] if searched else []
        entry["targeted"] = {v: sum(r["verdict"] == v for r in mine) for v in ("reachable", "undecided", "unreachable")}
        entry["targeted"]["sets"] = len(mine)
    return chapters


def environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["f"] = fmt
    env.filters["from_json"] = json.loads
    env.globals["claims_cell"] = claims_cell
    return env


def render_replication(results: Path) -> str:
    """docs/replication.md: the replication report, chapter by chapter."""
    found = context(results)
    chapters = chapter_tables(results, found["targeted"])
    return environment().get_template("replication.md.j2").render(**found, chapters=chapters)


def render(results: Path) -> str:
    return environment().get_template("fidelity.md.j2").render(**context(results))


def rule_chose_selected(ranking: pd.DataFrame) -> bool:
    """The pre-fixed rule (:func:`nlcx.thesis.profiles.rule_selects`) on the pendulum ranking."""
    return profiles.rule_selects(ranking.iloc[0], ranking[ranking.hypothesis == "literal"].iloc[0])


def selected_profile(results: Path) -> str:
    """The pendulum study's rank 1 (by validation), or the final round's where the
    pre-registered rule lets it replace that one, with chapter 5's rank 1 (by train loss)."""
    final = final_round(results)
    study = "final_round" if final is not None and final["selects"] else "pendulum_all"
    pend = yaml.safe_load((results / study / "profile.yaml").read_text())
    cstr = yaml.safe_load((results / "cstr" / "profile.yaml").read_text())
    profile = {**pend, "chapter5": cstr["chapter5"]}
    chapter5 = "+".join(f"{k}={v}" for k, v in cstr["chapter5"]["hypothesis"].items()) or "literal"
    profile["source"] = f"{pend['source']}; chapter 5: {chapter5}, rank 1 by train loss in cstr"
    profile["default"] = rule_chose_selected(pd.read_csv(results / study / "ranking.csv"))
    header = "# Generated by make identify (scripts/fidelity_report.py profile); do not edit.\n"
    return header + yaml.safe_dump(profile, sort_keys=False)


if __name__ == "__main__":
    command, results = sys.argv[1], Path(sys.argv[2])
    pages = {"doc": render, "replication": render_replication, "profile": selected_profile}
    sys.stdout.write(pages[command](results))

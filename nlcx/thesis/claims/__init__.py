"""The qualitative claims of chapters 2-5, checked against our runs.

The claims are data: ``nlcx/thesis/data/claims.yaml`` holds each one (its id, the thesis's
sentence and section, our paraphrase, and the checks that decide it: which cells of which
runs, compared how, against which named threshold), read and checked by
:mod:`nlcx.thesis.claims.table`. It is YAML, not CSV, because a claim is a conjunction of a
varying number of checks, each reading its own cells: nested, a check per line; as CSV rows
the claim's words would repeat on every check. Each kind of check is one evaluator of
:mod:`nlcx.thesis.claims.checks`. The pendulums' claims (chapters 2-4) read their
stabilisation and tracking runs; the CSTR's (chapter 5) read our Table 5.8 (one run per
tuning method) and the preview run of Fig. 5.19.

A claim is ``yes`` when every check holds, ``partly`` when some do, ``no`` when none does
(an ``all_or_nothing`` claim: ``yes`` or ``no``); the evidence column gives the numbers of
each check, joined by " | ". Definitions the checks use (the thresholds' values are named in
the table):

- M_p, t_r, t_s, e_ss as in the tables (docs/metrics.md; M_p of a position = overshoot
  fraction, of an angle = peak deviation in rad);
- chattering = total variation sum |F_k - F_{k-1}| of every input force, compared only
  between runs with the same noise realisation (common seeds);
- unbounded = the run diverged (``unstable``: |angle| > pi/2 or non-finite) or a position
  left +-10 m (``position_limit``); bounded = neither;
- oscillatory = a position still moves more than 0.02 m, 2 % of its unit step, peak to peak
  over the last 5 s (``oscillation_ptp``); zero e_ss = |e_ss| <= 0.01 (``ess_tolerance``;
  positions, per unit step) and the run completed;
- tracks well = RMS tracking error over the last 5 s <= 10 % of the sine's amplitude
  (``tracking_rms_fraction``);
- the CSTR (Table 5.8's columns, docs/metrics.md): no overshoot = M_p <= 0.5 %
  (``zero_overshoot``); zero e_ss = |e_ss| <= 0.01 (``ess_tolerance``; the step is a unit
  step); an inverse response = an undershoot above 10 % of the step
  (``marked_inverse_response``); ISE and control effort (the integral of u²) of Fig. 5.19's
  run.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd
from matplotlib.figure import Figure

from nlcx.drawing import new_figure
from nlcx.thesis import cstr
from nlcx.thesis.catalog import FigureSpec, TableSpec
from nlcx.thesis.claims.checks import KINDS, Check, ClaimRun
from nlcx.thesis.claims.table import CHAPTER_PLANTS, Claim, ClaimTable, Threshold, claim_table, parse, thesis_runs

if TYPE_CHECKING:
    from nlcx.thesis.records import Record

__all__ = [
    "CHAPTER_PLANTS",
    "KINDS",
    "Check",
    "Claim",
    "ClaimRun",
    "ClaimTable",
    "Threshold",
    "claim_table",
    "claims_for",
    "configs_for",
    "evaluate",
    "judge",
    "lyapunov_figure",
    "parse",
]


def claims_for(pendulum: str) -> list[Claim]:
    """Every claim about one plant (x, xy, xz, xyz, cstr), in the order of ``claims.csv``."""
    return [c for c in claim_table().claims if c.pendulum == pendulum]


def configs_for(root: Path, chapters: set[int]) -> list[Path]:
    """Every experiment the claims of these chapters look at."""
    checks = [check for claim in claim_table().claims if claim.chapter in chapters for check in claim.checks]
    refs = dict.fromkeys(ref for check in checks for ref in check.runs)
    return list(dict.fromkeys(root / config for ref in refs for config in thesis_runs()[ref].configs))


def judge(claim: Claim, runs: Mapping[str, ClaimRun], table: ClaimTable) -> tuple[str, str]:
    """(reproduced, evidence) of one claim on the runs of the thesis tables and figures it reads
    (``runs``: reference -> run): yes when every check holds, partly when some do (no for an
    ``all_or_nothing`` claim), no when none; the evidence of the checks it shows."""
    results = [
        KINDS[check.kind].evaluate(check, [runs[ref] for ref in check.runs], table.limits(check))
        for check in claim.checks
    ]
    n_ok = sum(ok for ok, _ in results)
    verdict = "yes" if n_ok == len(results) else ("no" if n_ok == 0 or claim.all_or_nothing else "partly")
    return verdict, " | ".join(text for check, (_, text) in zip(claim.checks, results, strict=True) if check.shown)


def _runs(root: Path, records: Mapping[Path, Record]) -> dict[str, ClaimRun]:
    """Every thesis table and figure the claims read whose runs are all among ``records``."""
    runs = {}
    for ref, spec in thesis_runs().items():
        configs = [root / config for config in spec.configs]
        if not all(config in records for config in configs):
            continue
        if isinstance(spec, TableSpec):  # Table 5.8: our values, one run per tuning method
            runs[ref] = ClaimRun(ref, "none", cstr.method_values(records, root))
        else:
            runs[ref] = ClaimRun(ref, spec.uncertainty, records[configs[0]])
    return runs


def evaluate(root: Path, records: dict[Path, Record], chapters: set[int]) -> pd.DataFrame:
    """claims.csv: chapter, pendulum, id, source, claim, reproduced, evidence."""
    table = claim_table()
    runs = _runs(root, records)
    rows = []
    for chapter in sorted(chapters):
        for claim in (c for c in table.claims if c.chapter == chapter):
            verdict, evidence = judge(claim, runs, table)
            rows.append(
                {
                    "chapter": chapter,
                    "pendulum": claim.pendulum,
                    "id": claim.id,
                    "source": claim.source,
                    "claim": claim.text,
                    "reproduced": verdict,
                    "evidence": evidence,
                }
            )
    return pd.DataFrame(rows)


def lyapunov_figure(spec: FigureSpec, records: list[Record]) -> Figure:
    """V̇ from the stored trajectory beside sum F v, for time-AGS (a) and error-AGS (b)."""
    fig, axes = new_figure(len(records), 1, (7.5, 2.9 * len(records)))
    for k, (ax, rec, name) in enumerate(zip(axes[:, 0], records, ("Time", "Error"), strict=False)):
        for label, color in (("proposed", "C3"), ("conventional", "C0")):
            if label not in rec.lyapunov:
                continue
            t, dV, power = rec.lyapunov[label]
            ax.plot(t, dV, color=color, lw=1.3, label=f"V̇ from trajectory, {label}")
            ax.plot(t, power, color="k", ls=":", lw=1.0, label=f"ΣF·v, {label}" if label == "proposed" else None)
        ax.set_title(f"({chr(ord('a') + k)}) V̇ vs time with {name} AGS PID")
        ax.set_xlabel("Time (s)")
        ax.set_ylabel("V̇ (W)")
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        else:  # both runs diverged (possible under a loop profile): nothing to draw
            ax.text(0.5, 0.5, "no run completed", transform=ax.transAxes, ha="center", va="center")
    fig.suptitle(spec.title, fontsize=9)
    fig.tight_layout()
    return fig

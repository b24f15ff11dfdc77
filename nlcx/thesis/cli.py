"""The thesis's commands: reproduce, baselines, calibrate and identify.

``nlcx`` lists them by name and help without importing the thesis (:mod:`nlcx.cli.lazy`); a
command's module is imported when it runs or shows its own help. Each is an ordinary Typer
command function: its options are read from its signature.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from nlcx import runtime, safe_yaml
from nlcx.cli._app import NoReport, OverridesArg, checked_jobs, one_line_errors
from nlcx.cli.experiments import DeviceOpt, checked_device
from nlcx.errors import ConfigError, NlcxError
from nlcx.terminal import echo

if TYPE_CHECKING:
    from nlcx.thesis import profiles
    from nlcx.thesis.records import Record


@one_line_errors
def reproduce(
    chapter: Annotated[
        list[int] | None, typer.Option("--chapter", "-c", help="Chapter(s) to reproduce (2, 3, 4).")
    ] = None,
    only: Annotated[str | None, typer.Option("--only", help="Comma-separated keys, e.g. fig-2.4,table-2.3.")] = None,
    jobs: Annotated[int | None, typer.Option("--jobs", "-j", help="Worker processes (default: all cores).")] = None,
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("results/thesis"),
    configs: Annotated[Path, typer.Option("--configs", help="Thesis experiment configs.")] = Path("configs/thesis"),
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="Override for every experiment, e.g. plant.params.equations=printed."),
    ] = None,
    profile: Annotated[
        str | None,
        typer.Option(
            "--profile",
            help="Loop profile (configs/thesis/profiles/NAME.yaml); literal: as printed. "
            "Default: selected where the identification study's rule chose it, else literal.",
        ),
    ] = None,
    no_report: NoReport = False,
) -> None:
    """Regenerate the thesis's figures and tables (ours beside theirs) and check its claims."""
    from nlcx import rundir
    from nlcx.thesis import profiles
    from nlcx.thesis.reproduce import reproduce as run_reproduce

    checked_jobs(jobs)
    runtime.imports_done()
    chosen = profiles.load(profile or profiles.default_name(configs), configs)

    start = time.perf_counter()
    keys = [k for k in (only or "").split(",") if k.strip()]
    done = [0]

    def progress(record: Record) -> None:
        done[0] += 1
        bad = [c for c, s in record.status.items() if s != "ok"]
        note = f" ({', '.join(bad)} unstable)" if bad else ""
        echo(f"  [{done[0]:>3}] {record.name:<12} {record.wall:5.2f} s{note}")

    with rundir.staged(out) as stage:  # renamed to OUT when complete, report included
        summary = run_reproduce(
            configs, stage, chapters=chapter, only=keys, jobs=jobs, progress=progress,
            overrides=tuple(set_ or ()), profile=chosen,
        )  # fmt: skip
        echo(f"profile {chosen.name}: {len(summary['figures'])} figures, {len(summary['tables'])} tables -> {out}/")
        if "claims" in summary:
            counts = summary["claims"].reproduced.value_counts().to_dict()
            echo("claims: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
        wall = time.perf_counter() - start
        write_reproduction_manifest(
            stage, chosen, wall, jobs, overrides=set_ or (), started=start, only=keys, chapters=chapter or ()
        )
        echo(f"done in {wall:.1f} s")
        t0 = time.perf_counter()
        failure = None if no_report else rundir.write_pages(stage, configs)
    if failure is not None:
        raise rundir.ReportError(out, failure)
    if not no_report:
        echo(f"report {out / 'report.html'} ({time.perf_counter() - t0:.1f} s)")


@one_line_errors
def baselines(
    configs: Annotated[Path, typer.Option("--configs", help="The baseline configs.")] = Path("configs/baselines"),
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("results/baselines"),
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes of the sweeps.")] = 2,
    only: Annotated[
        str | None, typer.Option("--only", help="Comma-separated pendulums (x, xy, xz, xyz); default: all.")
    ] = None,
    variants: Annotated[int, typer.Option("--variants", help="Variants of each pendulum's robustness sweep.")] = 200,
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="Override for every config, e.g. simulation.t_end=5."),
    ] = None,
    no_report: NoReport = False,
) -> None:
    """AGS PID against the baselines (LQR, sliding mode) on the four pendulums, in the thesis's
    scenarios and a robustness sweep (docs/baselines.md): one directory, one report."""
    from nlcx import rundir
    from nlcx.limits import check_count
    from nlcx.thesis import baselines as study

    checked_jobs(jobs)
    check_count("--variants", variants, 1, 100_000, "variants of each robustness sweep")
    pendulums = [p.strip() for p in (only or ",".join(study.PENDULUMS)).split(",") if p.strip()]
    study.check_pendulums(pendulums)
    study.configs_of(configs, pendulums)  # every config there, before any work
    runtime.imports_done()
    start = time.perf_counter()

    def progress(what: str, seconds: float) -> None:
        echo(f"  {what:<40} {seconds:6.2f} s")

    with rundir.staged(out) as stage:
        study.run(configs, stage, pendulums=pendulums, variants=variants, jobs=jobs, overrides=tuple(set_ or ()),
                  progress=progress)  # fmt: skip
        wall = time.perf_counter() - start
        from nlcx import manifest, report

        record = {"nlcx_output": "baselines", "command": "nlcx " + " ".join(sys.argv[1:]),
                  **report.provenance(set_ or (), start), "pendulums": pendulums, "variants": variants,
                  **report.environment(), "wall_s": round(wall, 2), "jobs": jobs}  # fmt: skip
        manifest.write(stage, record)
        echo(f"done in {wall:.1f} s")
        failure = None if no_report else rundir.write_pages(stage)
    if failure is not None:
        raise rundir.ReportError(out, failure)
    echo(f"wrote {out}/" + ("" if no_report else f"; report {out / 'report.html'}"))


def write_reproduction_manifest(
    out: Path,
    profile: profiles.Profile,
    wall: float,
    jobs: int | None,
    overrides: Sequence[str] = (),
    started: float | None = None,
    only: Sequence[str] = (),
    chapters: Sequence[int] = (),
) -> None:
    """manifest.json of a reproduction: its kind (``nlcx_output``: reproduction), the command,
    what it was asked for where it was not everything (``only``: ``--only``'s keys,
    ``chapters``: ``--chapter``'s; the report shows only those figures),
    its ``overrides`` (``--set``), start and duration from the ``time.perf_counter()`` instant
    ``started`` (:func:`nlcx.report.provenance`), the profile, where it ran and the versions and
    commit (:func:`nlcx.report.environment`), the wall time ``wall`` and the workers."""
    import os
    import sys

    from nlcx import manifest, report

    record = {
        "nlcx_output": "reproduction",
        "command": "nlcx " + " ".join(sys.argv[1:]),
        **report.provenance(overrides, started),
        "profile": profile.name,
        "profile_source": profile.source,
        **report.environment(),
        "wall_s": round(wall, 2),
        "jobs": jobs or os.cpu_count(),
        **({"only": [k.strip() for k in only]} if only else {}),
        **({"chapters": list(chapters)} if chapters else {}),
    }
    manifest.write(out, record)


@one_line_errors
def calibrate(
    spec: Annotated[Path, typer.Argument(help="Calibration spec YAML.", show_default=False)],
    overrides: OverridesArg = None,
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes evaluating the population.")] = 1,
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory (default results/calibration/<name>).")
    ] = None,
    write: Annotated[bool, typer.Option("--write", help="Write the fitted values into the spec's write.file.")] = False,
) -> None:
    """Fit unprinted numbers (e.g. the conventional gains) to a thesis table with the seeded GA."""
    from nlcx import rundir
    from nlcx.thesis.calibrate import calibrate as run_calibration
    from nlcx.thesis.calibrate import load_spec, write_back
    from nlcx.tuning.optimise import require_pymoo

    checked_jobs(jobs)
    require_pymoo("nlcx calibrate")
    runtime.imports_done()

    name = load_spec(spec, overrides or []).name
    out_dir = out or Path("results/calibration") / name

    def progress(generation: int, best: float) -> None:
        echo(f"  generation {generation:>3}: best loss {best:.5g}")

    with rundir.claim_in_place(out_dir, "calibration"):
        outcome = run_calibration(spec, out_dir, jobs=jobs, overrides=overrides or [], progress=progress)
    echo(outcome["tuning"].to_string(index=False))
    echo(outcome["fit"].to_string(index=False))
    if write:
        echo(f"wrote {write_back(spec, outcome)}")
    echo(f"loss {outcome['result'].f:.5g}; results in {out_dir}/")


@one_line_errors
def identify(
    spec: Annotated[Path, typer.Argument(help="Identification spec YAML.", show_default=False)],
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes (fits on the GPU run in this one).")] = 1,
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory (default results/identify/<name>).")
    ] = None,
    device: DeviceOpt = None,
) -> None:
    """Fit loop hypotheses to the train tables, rank them on validation (resumable).
    A spec with "chapter: 5" is chapter 5's study (Table 5.8), ranked by train loss; one with
    "kind: consistency" asks of each printed column whether any loop gives it; one with
    "kind: targeted" searches the sets of printed cells that study found unreachable."""

    from nlcx import rundir
    from nlcx.thesis.consistency import consistency
    from nlcx.thesis.consistency.targeted import targeted
    from nlcx.thesis.identify import identify as run_identify
    from nlcx.thesis.identify_cstr import identify_cstr
    from nlcx.tuning.optimise import require_pymoo

    checked_jobs(jobs)
    require_pymoo("nlcx identify")  # every study fits with the GA
    runtime.imports_done()
    raw = safe_yaml.load_file(spec)
    if not isinstance(raw, dict) or not isinstance(raw.get("name"), str):
        raise ConfigError("spec", str(spec), "an identification spec: a YAML mapping with a name")
    out_dir = out or Path("results/identify") / raw["name"]
    pendulum_study = raw.get("kind") not in ("consistency", "targeted") and raw.get("chapter") != 5
    if device not in (None, "cpu") and not pendulum_study:
        raise NlcxError(f"--device = {device!r}: a consistency, targeted or chapter 5 study runs on the cpu only")

    def progress(done: int, total: int, name: str) -> None:
        echo(f"  [{done}/{total}] {name}")

    with rundir.claim_in_place(out_dir, "identification"):  # resumed in place: locked, not staged
        if raw.get("kind") == "consistency":
            table = consistency(spec, out_dir, jobs=jobs, progress=progress)
        elif raw.get("kind") == "targeted":
            table = targeted(spec, out_dir, jobs=jobs, progress=progress)
        elif raw.get("chapter") == 5:
            table = identify_cstr(spec, out_dir, jobs=jobs, progress=progress)
        else:
            table = run_identify(spec, out_dir, jobs=jobs, progress=progress, device=checked_device(device))
    if raw.get("kind") == "targeted":
        echo(table[["table", "controller", "cells", "smallest_miss", "loops", "verdict"]].to_string(index=False))
        echo(f"results in {out_dir}/")
        return
    if raw.get("kind") == "consistency":
        shown = table[["table", "definition", "loops", "most_cells_hit", "cells", "reproduced"]]
        echo(shown.to_string(index=False))
        echo(f"results in {out_dir}/")
        return
    if raw.get("chapter") == 5:
        columns = ["rank", "hypothesis", "train_loss", "test_median_rel_error"]
    else:
        columns = ["rank", "hypothesis", "train_loss", "validation_median_rel_error", "validation_direction_agreement"]
    echo(table[columns].head(10).to_string(index=False))
    echo(f"{len(table)} hypotheses; results in {out_dir}/")

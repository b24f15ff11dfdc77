"""Without the optional extra ``tuning`` (pymoo), nlcx runs and sweeps; what needs the GA says so in one line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MESSAGE = "needs the optional extra: pip install 'nlcx[tuning]'"

#: Prepended to each script: an import of pymoo (or of any of its modules) fails, as where it is not installed.
BLOCKER = textwrap.dedent(
    """
    import sys

    class NoPymoo:
        def find_spec(self, name, path=None, target=None):
            if name == "pymoo" or name.startswith("pymoo."):
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
            return None

    sys.meta_path.insert(0, NoPymoo())
    """
)


def _without_pymoo(script: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    """``script`` run in a fresh Python in which pymoo cannot be imported, from the repository's root."""
    return subprocess.run(
        [sys.executable, "-c", BLOCKER + textwrap.dedent(script)],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
        env={**os.environ, "NLCX_TEST_OUT": str(tmp_path)},
    )  # fmt: skip


@pytest.mark.slow
def test_a_run_and_a_sweep_need_no_pymoo_and_ga_tuning_names_the_extra(tmp_path: Path) -> None:
    done = _without_pymoo(
        """
        import json, os
        import nlcx
        from nlcx.errors import NlcxError

        out = os.environ["NLCX_TEST_OUT"]
        run = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=1"])
        sweep = nlcx.sweep(
            "configs/sweeps/robustness.yaml",
            ["simulation.t_end=0.5", "sweep.random.n=2", "outputs.timeseries=false"],
            jobs=1, out=os.path.join(out, "sweep"),
        )
        try:
            nlcx.run("configs/thesis/ch5/fig_5_17.yaml", ["simulation.t_end=1"])
            ga = "no error"
        except NlcxError as exc:
            ga = str(exc)
        print(json.dumps({
            "runs": sorted(run.controllers), "variants": int((sweep.variants["status"] == "ok").sum()), "ga": ga,
            "pymoo": "pymoo" in sys.modules,
        }))
        """,
        tmp_path,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["runs"] == ["conventional", "proposed"]
    assert seen["variants"] == 6  # 3 friction models x 2 draws
    assert seen["ga"] == f"controllers.ga.tune.kind = ga: {MESSAGE}"
    assert seen["pymoo"] is False


@pytest.mark.slow
@pytest.mark.parametrize(
    ("arguments", "what"),
    [
        (["identify", "configs/identify/cstr.yaml"], "nlcx identify"),
        (["reproduce", "--only", "fig-5.17", "--no-report"], "configs/thesis/ch5/fig_5_17.yaml: controllers.ga"),
    ],
)
def test_the_commands_that_need_the_ga_name_the_extra_in_one_line(
    tmp_path: Path, arguments: list[str], what: str
) -> None:
    done = _without_pymoo(
        f"""
        import os
        from nlcx.cli import main

        sys.argv = ["nlcx", *{arguments!r}, "--out", os.path.join(os.environ["NLCX_TEST_OUT"], "out")]
        main()
        """,
        tmp_path,
    )
    assert done.returncode != 0
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert what in lines[0] and lines[0].endswith(MESSAGE), lines[0]
    assert not (tmp_path / "out").exists()

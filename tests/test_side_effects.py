"""Importing nlcx and calling its API leaves the process as it was: the garbage collector (on or
off, and what is frozen), the warning filters and matplotlib's backend. The ``nlcx`` command
sets them for itself and restores them when the command ends.

Each check runs in a fresh Python process, so that what the test session set does not count.
"""

from __future__ import annotations

import ast
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "nlcx"
CONFIG = ROOT / "configs" / "x_error_ags.yaml"
SWEEP = ROOT / "configs" / "sweeps" / "robustness.yaml"

#: Runs ``{workload}`` between two readings of the process-wide state and prints both as JSON.
#: matplotlib starts on the SVG backend, one nlcx has no reason to choose. numpy, scipy and
#: others add warning filters when imported; the filters that count are those code of nlcx
#: added (a module named nlcx.*) and left in place.
PROBE = """
import gc, json, os, sys, warnings
import matplotlib
matplotlib.use("svg")
added = []
def spied(set_filter):
    def spy(*args, **kwargs):
        set_filter(*args, **kwargs)
        if sys._getframe(1).f_globals.get("__name__", "").split(".")[0] == "nlcx":
            added.append(warnings.filters[-1 if kwargs.get("append") else 0])
    return spy
warnings.filterwarnings = spied(warnings.filterwarnings)
warnings.simplefilter = spied(warnings.simplefilter)
def state():
    return {{
        "collector on": gc.isenabled(),
        "frozen": gc.get_freeze_count(),
        "warning filters of nlcx": [repr(f) for f in added if f in warnings.filters],
        "showwarning": repr(warnings.showwarning),
        "backend": matplotlib.get_backend(),
        "MPLBACKEND": os.environ.get("MPLBACKEND"),
    }}
before = state()
{workload}
print(json.dumps([before, state()]))
"""


def _modules() -> list[str]:
    """Every module of the package but the ``__main__`` ones (they run a command when imported)."""
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] != "__main__":
            names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


def _changed(workload: str, tmp_path: Path) -> dict[str, Any]:
    """What of the process's state ``workload`` changed: {key: (before, after)}."""
    code = PROBE.format(workload=workload)
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    before, after = json.loads(done.stdout.splitlines()[-1])
    return {key: (before[key], after[key]) for key in before if before[key] != after[key]}


API_WORKLOAD = f"""
import importlib
import nlcx
for name in {_modules()!r}:
    importlib.import_module(name)
result = nlcx.run({str(CONFIG)!r}, ["simulation.t_end=2"])
result.plot()
saved = result.save("run", report=True)
again = nlcx.load_run(saved)
again.plot()
assert (saved / "report.html").is_file() and again.metrics.equals(result.metrics)
swept = nlcx.sweep({str(SWEEP)!r}, ["sweep.random.n=1", "simulation.t_end=1"], executor="serial")
assert len(swept.variants) == 3
"""


def test_importing_nlcx_and_calling_its_api_leaves_the_process_as_it_was(tmp_path: Path) -> None:
    assert _changed(API_WORKLOAD, tmp_path) == {}


def test_the_probe_sees_each_process_wide_setting(tmp_path: Path) -> None:
    planted = (
        "import gc, os, warnings, matplotlib\n"
        "gc.disable()\n"
        "gc.freeze()\n"
        "warnings.filterwarnings('ignore', category=DeprecationWarning)\n"
        "warnings.showwarning = print\n"
        "matplotlib.use('Agg')\n"
        "os.environ['MPLBACKEND'] = 'Agg'\n"
    )
    changed = _changed(_as_nlcx(planted), tmp_path)
    assert set(changed) == {"collector on", "frozen", "warning filters of nlcx", "showwarning", "backend", "MPLBACKEND"}
    scoped = "import warnings\nwith warnings.catch_warnings():\n    warnings.filterwarnings('ignore')\n"
    assert _changed(_as_nlcx(scoped), tmp_path) == {}  # a filter set for a block is gone after it


def _as_nlcx(code: str) -> str:
    """``code`` run as a module of nlcx would run it."""
    return f"exec({code!r}, {{'__name__': 'nlcx.planted'}})"


#: ``nlcx <args>`` through the console entry point, in this process.
COMMAND = """
from nlcx.cli import main
sys.argv = ["nlcx", *{args!r}]
try:
    main()
except SystemExit as exit:
    assert not exit.code, exit.code
"""


@pytest.mark.parametrize(
    "args",
    [
        ["validate", str(CONFIG)],
        ["list", "plant"],
        ["metrics", "step.csv"],
        ["diff", "step.csv", "step.csv"],
        ["run", str(CONFIG), "simulation.t_end=1", "--out", "run", "-q"],
    ],
    ids=lambda args: args[0],
)
def test_a_command_restores_what_it_set_when_it_ends(tmp_path: Path, args: list[str]) -> None:
    """validate, list, metrics and diff never switch the collector back on themselves; run
    freezes the heap after its imports."""
    t = [k / 100 for k in range(501)]
    rows = "".join(f"{ti!r},{1.0 - math.exp(-2.0 * ti)!r}\n" for ti in t)
    (tmp_path / "step.csv").write_text("t,y\n" + rows)
    assert _changed(COMMAND.format(args=args), tmp_path) == {}


def test_a_command_runs_with_its_settings(tmp_path: Path) -> None:
    """While a command runs: the collector is on as the caller left it, matplotlib's backend
    is Agg for it and the processes it starts, and numba's note on experimental first-class
    function types is not shown."""
    during = (
        "import warnings\n"
        "from nlcx.cli import _app\n"
        "@_app.app.command('probe')\n"
        "def probe() -> None:\n"
        "    warnings.warn('First-class function type feature is experimental', UserWarning)\n"
        "    print(json.dumps([gc.isenabled(), os.environ['MPLBACKEND']]))\n" + COMMAND.format(args=["probe"])
    )
    code = PROBE.format(workload=during)
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.splitlines()[0]) == [True, "Agg"]
    assert "experimental" not in done.stderr


def test_an_untested_numba_is_named_once_in_one_line(tmp_path: Path) -> None:
    code = "import numba\nnumba.__version__ = '0.99.0'\nimport sys\n" + COMMAND.format(args=["validate", str(CONFIG)])
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if "0.99.0" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: numba 0.99.0 is untested"), done.stderr
    assert len(done.stderr.splitlines()) == 1, done.stderr


def _import_time_settings(source: str) -> list[str]:
    """Calls in ``source`` that set the process's warning filters or garbage collector when the
    module is imported (outside any function), and every ``matplotlib.use`` call."""
    in_functions: set[int] = set()
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            in_functions.update(id(n) for n in ast.walk(node) if n is not node)
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Attribute):
            continue
        owner = node.func.value.id if isinstance(node.func.value, ast.Name) else ""
        name = f"{owner}.{node.func.attr}"
        if name in ("matplotlib.use", "mpl.use"):
            found.append((node.lineno, name))
        elif id(node) not in in_functions and name in (
            "warnings.filterwarnings", "warnings.simplefilter", "warnings.resetwarnings",
            "gc.disable", "gc.freeze", "gc.set_threshold",
        ):  # fmt: skip
            found.append((node.lineno, f"{name} on import"))
    return [f"line {line}: {call}" for line, call in sorted(found)]


def test_no_module_sets_warnings_or_the_collector_on_import_nor_chooses_a_backend() -> None:
    offenders = {
        str(path.relative_to(ROOT)): calls
        for path in sorted(PACKAGE.rglob("*.py"))
        if (calls := _import_time_settings(path.read_text(encoding="utf-8")))
    }
    assert offenders == {}


def test_the_source_rule_finds_each_setting() -> None:
    planted = (
        "import gc, warnings, matplotlib\n"
        "warnings.filterwarnings('ignore')\n"
        "gc.disable()\n"
        "def draw():\n"
        "    matplotlib.use('Agg')\n"
        "    gc.disable()\n"  # inside a function: scoped by its caller, not an import-time setting
        "if True:\n"
        "    gc.freeze()\n"
    )
    assert [call.split(":")[0] for call in _import_time_settings(planted)] == ["line 2", "line 3", "line 5", "line 8"]

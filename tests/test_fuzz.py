"""Property-based fuzzing of the command line with hostile configs and overrides.

Configs are drawn from the JSON schemas of nlcx's own models (the simulation, metrics, outputs
and plant sections, the x pendulum's parameters, the PID controller's config), placed into a
valid base (``configs/x_error_ags.yaml``, 1 s long, no figure) and then mutated anywhere: wrong
types, numbers at and past every edge (written to YAML as ``.nan`` and ``.inf`` where they are
not finite), unknown keys, nesting past the YAML reader's limit, hostile strings (terminal
escapes, ``${...}`` resolvers, lone surrogates and NUL written as YAML escapes, strings past
the 5 MB limit, path separators and ``..``), and edits of the YAML text itself (tags, aliases,
bytes that are not UTF-8, a file cut in half). They reach the command line in-process as YAML
files and as override strings.

Every example must end as the guarantees state (docs/guide/guarantees.md): exit 0, or exit 1
or 2 with exactly one line on stderr that names no Python exception, shows no traceback, is
not an internal error and holds no character a terminal would obey. A run's directory is then
complete (its manifest lists and verifies every file in it) or absent, and nothing but nlcx's
lock file is left beside it. The value of an environment variable set for the suite never
reaches the output of a command or any file it writes.

One fixed test checks that a command does not show the warning numba gives when it compiles
the kernel, which numba words with terminal escapes.

The examples are derandomized (the same ones on every run) and bounded; the number each
property tried, by exit status, is printed at the end of the module.
"""

from __future__ import annotations

import copy
import os
import shutil
import tempfile
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from _hostile import (
    CONFIG,
    EXCEPTION_NAME,
    SECRET,
    SECRET_VARIABLE,
    TERMINAL_UNSAFE,
    TEXT_EDITS,
    files_under,
    from_model_schema,
    mutated,
    one_line,
    overrides,
    yaml_text,
)
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from nlcx import manifest, registry, rundir
from nlcx.cli import app
from nlcx.config import sections

runner = CliRunner()
#: The base every config is drawn into: the x pendulum with two PID controllers, 1 s, no figure.
BASE: dict[str, Any] = yaml.safe_load(CONFIG.read_text())
BASE["simulation"]["t_end"] = 1.0
BASE["outputs"] = {"figure": False}
#: A run's horizon, set after every other override: ten steps.
SHORT = ["simulation.t_end=0.05", "simulation.dt=0.005"]
#: Names of a run directory, and of a config file, that a terminal or a path could trip on.
OUT_NAMES = ["out", "o\x1b[31mut", "o ut", "ü\u202e", "o\nut", "..out", "-out", "out.yaml", "o\\ut", "o'ut"]
CONFIG_NAMES = ["c.yaml", "c\x1b[2J.yaml", "c\u202e.yaml", "c d.yaml", "c.yml", "c.txt", "c", "c\nd.yaml"]

#: Fixed examples, bounded: no shrinking (a failing example is reported as drawn, and the file's
#: time stays bounded). The explicit examples, tried first, are small cases at edges that the
#: drawn examples reach only now and then.
SETTINGS: dict[str, Any] = {
    "derandomize": True,
    "phases": (Phase.explicit, Phase.generate),
    "deadline": None,
    "database": None,
    "suppress_health_check": [
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.large_base_example,
        HealthCheck.filter_too_much,
    ],
}
#: Examples tried, by property and exit status.
TRIED: Counter[tuple[str, int]] = Counter()
EXAMPLES = {
    "validate-config-file": 250,
    "validate-overrides": 250,
    "validate-any-bytes": 150,
    "run": 70,
}


@pytest.fixture(scope="module", autouse=True)
def secret_and_summary(request: pytest.FixtureRequest) -> Iterator[None]:
    """Set :data:`SECRET_VARIABLE` for the module; at its end, print how many examples each
    property tried, by exit status."""
    before = os.environ.get(SECRET_VARIABLE)
    os.environ[SECRET_VARIABLE] = SECRET
    yield
    if before is None:
        os.environ.pop(SECRET_VARIABLE, None)
    else:
        os.environ[SECRET_VARIABLE] = before
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    if reporter is None or capture is None:
        return
    with capture.global_and_fixture_disabled():
        reporter.write("\n")
        for name in EXAMPLES:
            codes = {code: n for (prop, code), n in sorted(TRIED.items()) if prop == name}
            detail = ", ".join(f"exit {code}: {n}" for code, n in codes.items())
            reporter.write_line(f"test_fuzz: {name}: {sum(codes.values())} examples ({detail or 'not run'})")


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A directory for the examples' files (each example works in a new directory under it)."""
    return tmp_path_factory.mktemp("fuzz")


@pytest.fixture(scope="module")
def base_file(workdir: Path) -> Path:
    """:data:`BASE` as a YAML file."""
    path = workdir / "base.yaml"
    path.write_text(yaml_text(BASE))
    return path


# ------------------------------------------------------------------ what every example must end as


def check_outcome(prop: str, result: Any) -> int:
    """Exit 0, or exit 1 or 2 with one line (:func:`_hostile.one_line`) that is not an internal
    error; either way no Python exception name, no traceback, nothing a terminal would obey,
    and not :data:`SECRET`, in what the command printed. Counted under ``prop``."""
    TRIED[prop, result.exit_code] += 1
    if result.exit_code == 0:
        assert result.exception is None, repr(result.exception)
        assert not EXCEPTION_NAME.search(result.output), result.output
    else:
        line = one_line(result, (1, 2))
        assert not line.startswith("internal error"), line
    assert not TERMINAL_UNSAFE.search(result.output), result.output
    assert SECRET not in result.output
    return int(result.exit_code)


def check_complete(directory: Path) -> None:
    """``directory`` is a complete output directory: marked, and every file in it listed in
    its manifest and as the manifest records it."""
    assert (directory / manifest.MANIFEST).is_file()
    assert manifest.is_marked(directory)
    assert manifest.unlisted(directory) == []
    manifest.verify(directory)


def check_no_secret(directory: Path) -> None:
    """No file under ``directory`` holds :data:`SECRET`."""
    for path in files_under(directory):
        assert SECRET.encode() not in path.read_bytes(), path


@pytest.fixture(scope="module")
def example_dir(workdir: Path) -> Callable[[], Any]:
    """A context manager: a new, empty directory for one example, removed after it."""
    from contextlib import contextmanager

    @contextmanager
    def make() -> Iterator[Path]:
        path = Path(tempfile.mkdtemp(dir=workdir))
        try:
            yield path
        finally:
            shutil.rmtree(path, ignore_errors=True)

    return make


# ------------------------------------------------------------------ configs drawn from the models' schemas

PARAMS = registry.plants.get("x_pendulum").Params
PID = registry.controllers.get("pid").Config
SECTION_MODELS = {
    "simulation": sections.SimulationSection,
    "metrics": sections.MetricsSection,
    "outputs": sections.OutputsSection,
}
#: Experiment names with path separators, ``..``, NUL, escapes, or past any file name's length.
HOSTILE_NAMES = ["../../x", "../..", "..", ".", "a/b", "/abs", "a\\b", "a\x00b", "\x1b[31mx", "", " ", "-x", ".hidden",
                 "x" * 300, "CON", "\ud800", f"${{oc.env:{SECRET_VARIABLE}}}", "~", "*", "a\nb"]  # fmt: skip
#: Names of loops and of a plant's states: the x pendulum's, mostly.
SIGNALS = st.sampled_from(["x", "theta", "F_x", "dx", "dtheta"]) | st.text(max_size=6)


def _subset(draw: Callable[..., Any], drawn: dict[str, Any]) -> dict[str, Any]:
    """Some of the keys of ``drawn``, with their values."""
    keep = draw(st.sets(st.sampled_from(sorted(drawn, key=str)))) if drawn else set()
    return {key: drawn[key] for key in keep}


@st.composite
def schema_configs(draw: Callable[..., Any]) -> dict[str, Any]:
    """:data:`BASE` with some keys of its sections replaced by values drawn from the sections'
    models, the x pendulum's parameters and x0, and one controller's keys drawn from the PID's
    model; its name, now and then, one of :data:`HOSTILE_NAMES`."""
    raw = copy.deepcopy(BASE)
    raw["name"] = draw(st.sampled_from([raw["name"]] * 4 * len(HOSTILE_NAMES) + HOSTILE_NAMES))
    for section, model in SECTION_MODELS.items():
        if draw(st.booleans()):
            drawn = draw(from_model_schema(model.model_json_schema(), keys=SIGNALS))
            raw[section] = {**raw.get(section, {}), **_subset(draw, drawn)}
    if draw(st.booleans()):
        raw["plant"]["params"] = {
            **raw["plant"]["params"],
            **_subset(draw, draw(from_model_schema(PARAMS.model_json_schema()))),
        }
        plant = draw(from_model_schema(sections.PlantSection.model_json_schema(), keys=SIGNALS))
        raw["plant"].update(_subset(draw, {k: v for k, v in plant.items() if k != "params"}))
    if draw(st.booleans()):
        label = draw(st.sampled_from(sorted(raw["controllers"])))
        drawn = draw(from_model_schema(PID.model_json_schema(), keys=SIGNALS))
        raw["controllers"][label] = {**raw["controllers"][label], **_subset(draw, drawn)}
    return raw


def configs(most: int = 3, plain: float = 1 / 3) -> st.SearchStrategy[Any]:
    """Schema-drawn configs (:func:`schema_configs`): a share ``plain`` as they are, the others
    mutated (:func:`_hostile.mutated`, at most ``most`` mutations)."""
    chance = st.floats(0, 1, exclude_max=True)
    return st.tuples(schema_configs(), chance).flatmap(
        lambda pair: st.just(pair[0]) if pair[1] < plain else mutated(pair[0], most)
    )


def write_config(path: Path, config: Any, allow_unicode: bool, edit: str) -> Path:
    """``config`` as YAML text, edited (:data:`_hostile.TEXT_EDITS`), in the file ``path``."""
    text = TEXT_EDITS[edit](yaml_text(config, allow_unicode))
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
    return path


# ------------------------------------------------------------------ the properties


#: The base with the smallest positive float as its step: t_end / dt overflows.
TINY_STEP = {**BASE, "simulation": {**BASE["simulation"], "dt": 5e-324}}


@pytest.mark.slow
@settings(max_examples=EXAMPLES["validate-config-file"], **SETTINGS)
@example(config=TINY_STEP, allow_unicode=True, edit="none", name="c.yaml")
@example(config=BASE, allow_unicode=True, edit="recursive-alias", name="c.yaml")
@given(
    config=configs(),
    allow_unicode=st.booleans(),
    edit=st.sampled_from(list(TEXT_EDITS)) | st.just("none"),
    name=st.sampled_from(CONFIG_NAMES),
)
def test_validate_a_drawn_and_mutated_config_file(
    example_dir: Callable[[], Any], config: Any, allow_unicode: bool, edit: str, name: str
) -> None:
    """``nlcx validate FILE`` on a schema-drawn, mutated config written as YAML (its text edited
    too): valid (exit 0) or refused in one line; the secret is printed nowhere."""
    with example_dir() as here:
        path = write_config(here / name, config, allow_unicode, edit)
        result = runner.invoke(app, ["validate", str(path)])
        check_outcome("validate-config-file", result)
        if result.exit_code == 0:
            assert ": valid (" in result.stdout


@pytest.mark.slow
@settings(max_examples=EXAMPLES["validate-overrides"], **SETTINGS)
@example(texts=["title=caf\udce9"])  # the byte 0xe9 of a Latin-1 argument, as Python decodes argv
@given(texts=overrides(BASE))
def test_validate_with_hostile_overrides(base_file: Path, texts: list[str]) -> None:
    """``nlcx validate BASE OVERRIDE...`` with overrides in and around Hydra's grammar, whose
    values are hostile (as YAML and as raw text): valid or refused in one line."""
    check_outcome("validate-overrides", runner.invoke(app, ["validate", str(base_file), *texts]))


@pytest.mark.slow
@settings(max_examples=EXAMPLES["validate-any-bytes"], **SETTINGS)
@given(
    data=st.binary(max_size=300)
    | st.text(
        st.characters(codec=None) | st.sampled_from(["\x00", "\x1b", ":", "\n", "&", "*", "!", "{"]), max_size=200
    ).map(lambda text: text.encode("utf-8", "surrogatepass"))
)
def test_validate_any_bytes_as_a_config(example_dir: Callable[[], Any], data: bytes) -> None:
    """``nlcx validate FILE`` on any bytes at all (not UTF-8, not YAML, lone surrogates encoded,
    control characters): refused in one line, never an internal error."""
    with example_dir() as here:
        path = here / "c.yaml"
        path.write_bytes(data)
        check_outcome("validate-any-bytes", runner.invoke(app, ["validate", str(path)]))


@pytest.mark.slow
@settings(max_examples=EXAMPLES["run"], **SETTINGS)
@example(config=BASE, extra=[], out_name="out")
@example(config=BASE, extra=["name=\ud800"], out_name="out")
@given(
    config=configs(most=2, plain=1 / 2),
    extra=st.lists(overrides(BASE, most=1), max_size=1).map(lambda lists: [t for texts in lists for t in texts]),
    out_name=st.sampled_from(OUT_NAMES),
)
def test_run_writes_a_complete_directory_or_nothing(
    example_dir: Callable[[], Any], config: Any, extra: list[str], out_name: str
) -> None:
    """``nlcx run FILE [OVERRIDE] SHORT --no-report --out OUT`` on a schema-drawn, mutated config
    (figures off, ten steps): exit 0 with OUT complete (marked, every file listed and verified),
    or refused in one line with OUT complete or absent; beside OUT nothing but its lock file,
    and not even that for a refused target; the secret in no file written."""
    config = copy.deepcopy(config)
    if isinstance(config, dict):
        outputs = config.setdefault("outputs", {})
        if isinstance(outputs, dict):
            for key in ("figure", "gains_figure"):  # a figure painter process per example is too slow
                if outputs.get(key, key == "figure") is True:
                    outputs[key] = False
    with example_dir() as here:
        path = write_config(here / "c.yaml", config, True, "none")
        parent = here / "work"
        parent.mkdir()
        out = parent / out_name
        result = runner.invoke(app, ["run", str(path), *extra, *SHORT, "--no-report", "--out", str(out)])
        code = check_outcome("run", result)
        assert {p.name for p in parent.iterdir()} <= {out.name, rundir.lock_path(out).name}
        if code != 0 and result.stderr.startswith("output error"):  # a refused target takes no lock
            assert not rundir.lock_path(out).exists()
        if code == 0:
            assert out.is_dir(), result.output
        if out.exists():
            check_complete(out)
        check_no_secret(here)


def test_numbas_experimental_feature_warning_is_not_shown_by_a_command() -> None:
    """The warning numba gives when it compiles the kernel (first-class function types), worded
    as numba words it (its message in bold: terminal escapes), is not shown while a command runs:
    a run that compiles (a new numba cache) prints it on stderr otherwise, escapes included."""
    import warnings

    from numba.core.errors import NumbaExperimentalFeatureWarning

    from nlcx import runtime

    given_by_numba = NumbaExperimentalFeatureWarning("First-class function type feature is experimental")
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        with runtime.command():
            warnings.warn(given_by_numba, stacklevel=1)
    assert [str(w.message) for w in shown] == []

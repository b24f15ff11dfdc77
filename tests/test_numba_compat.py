"""numba's private API is used in nlcx._numba_compat alone, with the numba versions it is tested
with pinned in pyproject.toml and an untested version named in one line.

The source rules read the package with :mod:`ast`; they do not import it.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from numba import njit, types
from packaging.requirements import Requirement

from nlcx import _numba_compat

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - pytest brings tomli to Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "nlcx"
#: The one module that may use numba's private API.
COMPAT = PACKAGE / "_numba_compat.py"
#: Modules of numba.core whose names are public: exception classes and types.
PUBLIC_CORE = ("numba.core.errors", "numba.core.types")
#: Options of numba.njit that numba does not document.
PRIVATE_OPTIONS = ("_nrt", "no_cpython_wrapper", "no_cfunc_wrapper")


def _private_module(module: str) -> bool:
    """Whether importing ``module`` reaches into numba's private ``numba.core``."""
    inside = module == "numba.core" or module.startswith("numba.core.")
    public = module in PUBLIC_CORE or module.startswith(tuple(f"{m}." for m in PUBLIC_CORE))
    return inside and not public


def _dotted(node: ast.expr) -> str:
    """``a.b.c`` of an attribute chain on a name; "" for anything else."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return f"{base}.{node.attr}" if base else ""
    return ""


def private_numba_uses(source: str) -> list[str]:
    """Every use of numba's private API in ``source``: the ``_nrt``, ``no_cpython_wrapper`` and
    ``no_cfunc_wrapper`` options, an import from ``numba.core`` other than its errors and types,
    and an attribute ``numba.core.<private>``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.keyword) and node.arg in PRIVATE_OPTIONS:
            found.append(f"line {node.value.lineno}: {node.arg}=")
        elif isinstance(node, ast.Import):
            found += [f"line {node.lineno}: import {a.name}" for a in node.names if _private_module(a.name)]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names = [f"{node.module}.{a.name}" for a in node.names]
            if node.module in ("numba", "numba.core"):  # judged by what is imported from it
                private = any(_private_module(n) for n in names)
            else:
                private = _private_module(node.module)
            if private:
                found.append(f"line {node.lineno}: from {node.module} import {', '.join(a.name for a in node.names)}")
        elif isinstance(node, ast.Attribute):
            name = _dotted(node)
            if name.count(".") == 2 and _private_module(name):
                found.append(f"line {node.lineno}: {name}")
    return found


def test_no_module_but_the_compat_module_uses_numbas_private_api() -> None:
    offenders = {
        str(path.relative_to(ROOT)): uses
        for path in sorted(PACKAGE.rglob("*.py"))
        if path != COMPAT and (uses := private_numba_uses(path.read_text(encoding="utf-8")))
    }
    assert offenders == {}, f"numba's private API outside {COMPAT.relative_to(ROOT)}: {offenders}"


def test_the_rule_finds_each_kind_of_private_use_and_passes_the_public_ones() -> None:
    planted = (
        "from numba import njit\n"
        "from numba.core.caching import IndexDataCacheFile\n"
        "import numba.core.typing.typeof\n"
        "from numba.core import typing\n"
        "from numba import core\n"
        "f = njit(cache=True, _nrt=False)\n"
        "g = numba.core.typing.typeof.typeof_impl\n"
        "h = njit(no_cpython_wrapper=True)\n"
        "i = njit(no_cfunc_wrapper=True)\n"
    )
    lines = sorted(int(use.split(":")[0].removeprefix("line ")) for use in private_numba_uses(planted))
    assert lines == list(range(2, 10))
    public = (
        "import numba\n"
        "from numba import njit, types\n"
        "from numba.core import errors, types as core_types\n"
        "from numba.core.errors import NumbaError\n"
        "from numba.core.types import float64\n"
        "import numba.core.types.npytypes\n"
        "f = njit(cache=True, error_model='numpy')\n"
        "e = numba.core.errors.NumbaWarning\n"
    )
    assert private_numba_uses(public) == []


@pytest.mark.parametrize("version", ["0.58.1", "0.69.0", "0.69.0rc1", "1.0.0", "unknown"])
def test_an_untested_numba_is_named_in_one_line(monkeypatch: pytest.MonkeyPatch, version: str) -> None:
    monkeypatch.setattr(numba, "__version__", version)
    with pytest.warns(_numba_compat.UntestedNumbaWarning) as caught:
        assert _numba_compat.check_version() is False
    (warning,) = caught
    message = str(warning.message)
    assert f"numba {version} is untested" in message and "0.59 to 0.68" in message and "\n" not in message


@pytest.mark.parametrize("version", ["0.59.0", "0.63.2", "0.68.1", "0.68.0rc1"])
def test_a_tested_numba_passes_quietly(
    monkeypatch: pytest.MonkeyPatch, version: str, recwarn: pytest.WarningsRecorder
) -> None:
    monkeypatch.setattr(numba, "__version__", version)
    assert _numba_compat.check_version() is True
    assert not [w for w in recwarn if issubclass(w.category, _numba_compat.UntestedNumbaWarning)]


def test_the_installed_numba_is_a_tested_one() -> None:
    assert _numba_compat.is_tested(numba.__version__), numba.__version__


def test_pyproject_pins_the_tested_versions() -> None:
    """Every tested minor version satisfies the pin, the minor versions either side do not, and
    the tested versions have no gap (a pin is one range)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    (pin,) = [Requirement(d) for d in project["dependencies"] if Requirement(d).name == "numba"]
    tested = sorted(_numba_compat.TESTED)
    assert [minor for _, minor in tested] == list(range(tested[0][1], tested[-1][1] + 1))
    for major, minor in tested:
        assert pin.specifier.contains(f"{major}.{minor}.0") and pin.specifier.contains(f"{major}.{minor}.9")
    (first_major, first_minor), (last_major, last_minor) = tested[0], tested[-1]
    assert not pin.specifier.contains(f"{first_major}.{first_minor - 1}.9")
    assert not pin.specifier.contains(f"{last_major}.{last_minor + 1}.0")


def test_hot_njit_compiles_without_reference_counting() -> None:
    def twice(a):  # pragma: no cover - compiled
        for i in range(a.size):
            a[i] *= 2.0

    lazy = _numba_compat.hot_njit(cache=False)(twice)
    eager = _numba_compat.hot_njit(types.void(types.float64[::1]), cache=False)(twice)
    for compiled in (lazy, eager):
        a = np.arange(3.0)
        compiled(a)
        assert a.tolist() == [0.0, 2.0, 4.0]
        assert compiled.targetoptions["_nrt"] is False


def test_inner_njit_compiles_a_function_that_compiled_code_calls_without_its_wrappers() -> None:
    def twice(a):  # pragma: no cover - compiled
        for i in range(a.size):
            a[i] *= 2.0

    inner = _numba_compat.inner_njit(cache=False)(twice)

    @njit(cache=False)
    def caller(a):  # pragma: no cover - compiled
        inner(a)

    a = np.arange(3.0)
    caller(a)
    assert a.tolist() == [0.0, 2.0, 4.0]
    assert inner.targetoptions["no_cpython_wrapper"] is True
    assert inner.targetoptions["no_cfunc_wrapper"] is True
    with pytest.raises(TypeError, match="compiled code only"):
        inner(a)  # from Python: refused, not a call through the missing wrapper


def test_register_typeof_types_a_class_when_a_compiled_function_is_called() -> None:
    class Tagged:
        pass

    _numba_compat.register_typeof(Tagged, lambda value, context: types.float32)
    assert numba.typeof(Tagged()) == types.float32

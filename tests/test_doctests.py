"""The examples in the public API's docstrings run and give what they show."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: The modules of the public API (``nlcx.__all__``) whose docstrings carry examples.
MODULES = (
    "nlcx",
    "nlcx.api",
    "nlcx.results",
    "nlcx.comparison",
    "nlcx.comparison_frame",
    "nlcx.metrics.step",
    "nlcx.plants.scalar",
    "nlcx.plants.lti",
    "nlcx.controllers.law",
    "nlcx.terminal",
    "nlcx.analysis.linearization",
)


@pytest.mark.parametrize("name", MODULES)
def test_the_docstring_examples_run(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)  # the examples name configs/ relative to the repository
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [t for t in finder.find(module, name) if t.examples]
    assert tests, f"{name} has no docstring examples"
    report: list[str] = []
    for test in tests:
        runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)


def test_every_public_name_has_an_example() -> None:
    """Each callable of ``nlcx.__all__`` (classes through their methods) shows an example."""
    import nlcx

    missing = []
    for name in nlcx.__all__:
        obj = getattr(nlcx, name)
        if name.startswith("__") or (isinstance(obj, type) and issubclass(obj, Exception)):
            continue
        docs = [obj.__doc__ or ""]
        if isinstance(obj, type):
            docs += [getattr(obj, m).__doc__ or "" for m in vars(obj) if not m.startswith("_")]
        if not any(">>>" in doc for doc in docs):
            missing.append(name)
    assert not missing, f"no example in the docstrings of: {', '.join(missing)}"

"""nlcx: reproducible experiments on the control of nonlinear systems.

The Python API in one namespace. Importing ``nlcx`` is light: each name loads its module (and
numpy, pandas, numba) on first use, and nothing of the process (the garbage collector, the
warning filters, matplotlib's backend) or of numba's cache is changed
(:func:`nlcx.compiled_cache.ready` runs when the API first builds an experiment).

>>> import nlcx
>>> result = nlcx.run("configs/x_error_ags.yaml", ["simulation.t_end=10"])
>>> result.compare(["overshoot"]).columns.tolist()
['unit', 'conventional', 'proposed', 'change_proposed_pct', 'better']
"""

from __future__ import annotations

import importlib
from typing import Any

from nlcx._version import __version__ as __version__

#: Where each public name lives (imported on first access, PEP 562; ``__init__.pyi`` gives type
#: checkers and editors the same names, so this module imports none of them, even for typing).
_HOMES = {
    "Result": "nlcx.results",
    "SweepResult": "nlcx.sweep_results",
    "experiment": "nlcx.api",
    "load_run": "nlcx.results",
    "run": "nlcx.api",
    "sweep": "nlcx.api",
    "compare": "nlcx.comparison_frame",
    "thesis_improvement": "nlcx.comparison",
    "Comparison": "nlcx.comparison_frame",
    "ConfigError": "nlcx.errors",
    "NlcxError": "nlcx.errors",
    "step_info": "nlcx.metrics",
    "plant": "nlcx.plants.scalar",
    "controller": "nlcx.controllers.law",
    "linearize": "nlcx.analysis",
}


__all__ = sorted(["__version__", *_HOMES])


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'nlcx' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})

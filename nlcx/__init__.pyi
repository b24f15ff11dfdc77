"""The names of :mod:`nlcx`, for type checkers, editors and the API reference: the module imports
them lazily (its ``__all__`` is built from where each lives); each ``import X as X`` marks a
re-export."""

from nlcx._version import __version__ as __version__
from nlcx.analysis import linearize as linearize
from nlcx.api import experiment as experiment
from nlcx.api import run as run
from nlcx.api import sweep as sweep
from nlcx.comparison import thesis_improvement as thesis_improvement
from nlcx.comparison_frame import Comparison as Comparison
from nlcx.comparison_frame import compare as compare
from nlcx.controllers.law import controller as controller
from nlcx.errors import ConfigError as ConfigError
from nlcx.errors import NlcxError as NlcxError
from nlcx.metrics import step_info as step_info
from nlcx.plants.scalar import plant as plant
from nlcx.results import Result as Result
from nlcx.results import load_run as load_run
from nlcx.sweep_results import SweepResult as SweepResult

__all__ = [
    "Comparison",
    "ConfigError",
    "NlcxError",
    "Result",
    "SweepResult",
    "__version__",
    "compare",
    "controller",
    "experiment",
    "linearize",
    "load_run",
    "plant",
    "run",
    "step_info",
    "sweep",
    "thesis_improvement",
]

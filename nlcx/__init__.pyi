"""The names of :mod:`nlcx` (its ``__all__``), for type checkers and editors: the module imports
them lazily; each ``import X as X`` marks a re-export."""

from nlcx._version import __version__ as __version__
from nlcx.analysis import linearize as linearize
from nlcx.api import experiment as experiment
from nlcx.api import run as run
from nlcx.api import sweep as sweep
from nlcx.comparison import compare as compare
from nlcx.comparison import improvement as improvement
from nlcx.errors import ConfigError as ConfigError
from nlcx.errors import NlcxError as NlcxError
from nlcx.metrics import step_info as step_info
from nlcx.plants.scalar import plant as plant
from nlcx.results import Result as Result
from nlcx.results import SweepResult as SweepResult
from nlcx.results import load_run as load_run

__all__: list[str]

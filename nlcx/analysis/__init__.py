"""Linear analysis of configured loops: the plant linearised about its operating point, the
PID's gain schedules frozen at one point, the loop closed (:func:`linearize`), the same
along the schedules' argument (:func:`linearize_along`), and the directory ``nlcx linearize``
writes (:func:`save_analysis`).

python-control is imported with this package, never by ``import nlcx``.
"""

from __future__ import annotations

from nlcx.analysis.frozen import FrozenLoop, FrozenPoint
from nlcx.analysis.frozen_results import FrozenSweep, Linearization
from nlcx.analysis.linearization import linearize, linearize_along
from nlcx.analysis.output import save_analysis

__all__ = ["FrozenLoop", "FrozenPoint", "FrozenSweep", "Linearization", "linearize", "linearize_along", "save_analysis"]

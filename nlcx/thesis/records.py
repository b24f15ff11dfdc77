"""What the reproduction keeps of each experiment it runs (:func:`nlcx.thesis.reproduce.run_config`),
which the tables, figures and claims are made from."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd


@dataclass
class Record:
    """What one experiment run hands back to the parent process."""

    config: Path
    name: str
    #: The config as run, every default filled in (:meth:`nlcx.config.Experiment.resolved`).
    resolved: dict[str, Any]
    metrics: pd.DataFrame
    status: dict[str, str]
    extras: pd.DataFrame
    lyapunov: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)
    tuning: list[dict[str, Any]] = field(default_factory=list)
    #: Each controller's configuration as built (after its tuners).
    built: dict[str, dict[str, Any]] = field(default_factory=dict)
    wall: float = 0.0

"""The proposed AGS PID schedules of chapters 2-4: the numbers the thesis prints and the ones run.

Tables 2.2, 3.1, 3.6 and 4.1 print the gain range (k_min, k_max of eqs. 2.17-2.22) of every
AGS loop; section 2.3 prints the rates k of AGS PID 1 (the θ loop) and AGS PID 2 (the x
loop) of the x pendulum. These numbers have one source in nlcx, the transcription in
``data/ags_gain_ranges.csv`` and ``data/ags_rates.csv``:

- ``scripts/make_thesis_configs.py`` writes the building blocks ``configs/thesis/ags/*.yaml``
  from :func:`schedules` (what the experiments run);
- ``nlcx reproduce`` sets the configs actually run beside :func:`printed_ranges` and
  :func:`printed_rate` in its parameter tables (``tables.ags_table``).
"""

from __future__ import annotations

import math
from typing import Any

import pandas as pd

from nlcx.thesis import catalog

GAINS = ("kp", "ki", "kd")
#: The x-pendulum loop whose printed rates k (section 2.3) each loop uses: the x-y and x-y-z
#: pendulums reuse controllers 1 and 2 as controllers 3 and 4 (section 3.3).
PRINTED_RATES_OF = {"theta": "PID1", "phi": "PID1", "x": "PID2", "y": "PID2"}
#: The z loop's rates are not printed; it is a position loop, so it runs with AGS PID 2's
#: (docs/assumptions.md A11).
ASSUMED_RATES_OF = {"z": "PID2"}


def section_2_3_rates() -> dict[str, dict[str, float]]:
    """Section 2.3: rates k of k_p, k_i, k_d by x-pendulum loop, ``{"PID1": {"kp": ...}, "PID2": ...}``."""
    rates = catalog.ags_rates().dropna(subset=["k_p", "k_i", "k_d"])
    return {row.loop.split()[0]: {"kp": row.k_p, "ki": row.k_i, "kd": row.k_d} for row in rates.itertuples()}


def printed_rate(signal: str, gain: str) -> float:
    """The rate k the thesis prints for one loop's gain (section 2.3); NaN where it prints none."""
    loop = PRINTED_RATES_OF.get(signal)
    return math.nan if loop is None else section_2_3_rates()[loop][gain]


def run_rates(signal: str) -> dict[str, float]:
    """The rates k one loop runs with: the printed ones, else the documented assumption (A11)."""
    return section_2_3_rates()[PRINTED_RATES_OF.get(signal) or ASSUMED_RATES_OF[signal]]


def printed_ranges(table: str) -> pd.DataFrame:
    """The gain ranges of one of Tables 2.2, 3.1, 3.6, 4.1, indexed by the loop's signal."""
    ranges = catalog.gain_ranges()
    return ranges[ranges.table == table].set_index("signal")


def schedules(plant: str) -> tuple[str, dict[str, dict[str, Any]]]:
    """The AGS table of a pendulum and, per loop signal in the table's order, the loop's name
    (PID1, ...), its gain ranges ``{"kp": {"min": .., "max": ..}, ..}`` and its ``rate``."""
    ranges = catalog.gain_ranges()
    ranges = ranges[ranges.plant == plant]
    loops = {
        row.signal: {
            "loop": row.loop,
            **{gain: {"min": getattr(row, f"{gain}_min"), "max": getattr(row, f"{gain}_max")} for gain in GAINS},
            "rate": run_rates(row.signal),
        }
        for row in ranges.itertuples(index=False)
    }
    return str(ranges.table.iloc[0]), loops

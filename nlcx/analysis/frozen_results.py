"""The results of a frozen-gain linear analysis (:mod:`nlcx.analysis.linearization`): one
frozen point (:class:`Linearization`, its structural poles at 0 as :class:`MarginalPole`) and a
sweep of them along one argument of the schedules (:class:`FrozenSweep`), each with named
python-control systems and tables."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import control as ct
import numpy as np

from nlcx.analysis.frozen import FrozenLoop, FrozenPoint
from nlcx.analysis.linear import pole_counts, structural_poles

if TYPE_CHECKING:
    import pandas as pd

    from nlcx.config import Experiment

__all__ = ["FrozenSweep", "Linearization", "MarginalPole"]


@dataclass(frozen=True)
class MarginalPole:
    """A structural closed-loop pole at 0 (:attr:`Linearization.marginal`)."""

    #: The controller state it belongs to (e.g. ``pid_x_integral``: loop x's integrator).
    name: str
    #: The pole, 0 within rounding.
    value: complex


@dataclass(frozen=True)
class Linearization:
    """A PID loop frozen at one point of its schedules and linearised: named python-control
    state-space systems and their tables.

    Attributes
    ----------
    experiment : nlcx.config.Experiment
        The validated experiment.
    label : str
        The controller analysed.
    at : FrozenPoint
        Where its schedules are frozen (t in s, e in the outputs' units).
    loops : tuple of FrozenLoop
        Each loop with its frozen gains.
    period : float
        The period T the PID updates over (its ``sample_time``, or the simulation step), s.
    plant : control.StateSpace
        The plant linearised about its operating point: inputs and outputs by the plant's
        names, states likewise, in deviations from that point.
    controller : control.StateSpace
        The frozen PID, from the references (``<output>_ref``) and the outputs to the inputs.
    closed_loop : control.StateSpace
        From the references to the outputs and the inputs.
    poles : pandas.DataFrame
        The closed-loop poles: real, imag, zeta, omega_n, the rightmost first.
    margins : pandas.DataFrame
        Gain and phase margins with the loop broken at the plant input, per loop (the others
        closed) and per input that several loops drive (:data:`nlcx.analysis.linear.MARGIN_COLUMNS`).
    loop_transfers : dict of str to control.StateSpace
        The loop transfer of each opening of ``margins``, by its name.
    notes : tuple of str
        What the linear model leaves out of this configuration.
    """

    experiment: Experiment
    label: str
    at: FrozenPoint
    loops: tuple[FrozenLoop, ...]
    period: float
    plant: ct.StateSpace
    controller: ct.StateSpace
    closed_loop: ct.StateSpace
    poles: pd.DataFrame
    margins: pd.DataFrame
    loop_transfers: dict[str, ct.StateSpace] = field(repr=False)
    notes: tuple[str, ...] = ()
    #: A control law's linear gains (:func:`nlcx.analysis.law.law_gains`); None for a PID.
    law_gains: pd.DataFrame | None = field(default=None, repr=False)

    @property
    def gains(self) -> pd.DataFrame:
        """Each loop's frozen gains: its output, input, sign, scale, schedule, the parallel gains
        k_p, k_i, k_d it acts with, its derivative (filtered or backward) and filter N; for a
        control law, d u / d (each measure, reference and state of the law): input, of, gain."""
        import pandas as pd

        if self.law_gains is not None:
            return self.law_gains.copy()
        fields = ("name", "output", "input", "sign", "scale", "schedule", "kp", "ki", "kd", "derivative", "N")
        rows = [{("loop" if f == "name" else f): getattr(loop, f) for f in fields} for loop in self.loops]
        return pd.DataFrame(rows)

    def __repr__(self) -> str:
        unstable, on_axis = pole_counts(self.poles)
        return (
            f"<Linearization of {self.experiment.name}, controller {self.label!r} at t = {self.at.t:g} s, "
            f"e = {self.at.e:g}: {len(self.poles)} poles, {unstable} in the right half-plane, {on_axis} on the "
            f"imaginary axis>"
        )

    @property
    def marginal(self) -> tuple[MarginalPole, ...]:
        """The structural poles at 0 (:func:`nlcx.analysis.linear.structural_poles`): modes of
        the controller's states alone that nothing moves and that move nothing, such as a
        PID's integrator redundant with another one on the same input (the x pendulum's two
        loops on F_x). Each is named by the controller state it mostly lies along."""
        return tuple(MarginalPole(name, value) for name, value in structural_poles(self.closed_loop))

    @property
    def stable(self) -> bool:
        """Whether every closed-loop pole but the structural ones at 0 (:attr:`marginal`) lies in
        the open left half-plane: none in the closed right half-plane (a pole within rounding
        of the imaginary axis counts as on it, :func:`nlcx.analysis.linear.pole_counts`)."""
        unstable, on_axis = pole_counts(self.poles)
        return unstable == 0 and on_axis == len(self.marginal)


@dataclass(frozen=True)
class FrozenSweep:
    """:func:`linearize` repeated along one argument of the schedules.

    Attributes
    ----------
    axis : {"t", "e"}
        The argument swept.
    values : numpy.ndarray
        Its values, from 0 to the end of the simulation (t) or to the largest error a loop
        starts from or is commanded to (e).
    points : tuple of Linearization
        The analysis at each value.
    """

    axis: str
    values: np.ndarray
    points: tuple[Linearization, ...] = field(repr=False)

    def __repr__(self) -> str:
        return (
            f"<FrozenSweep along {self.axis} from {self.values[0]:g} to {self.values[-1]:g}, {self.values.size} points>"
        )

    def _stacked(self, tables: list[pd.DataFrame]) -> pd.DataFrame:
        import pandas as pd

        parts = [table.assign(**{self.axis: value}) for table, value in zip(tables, self.values, strict=True)]
        stacked = pd.concat(parts, ignore_index=True)
        return stacked[[self.axis, *(c for c in stacked.columns if c != self.axis)]]

    @property
    def poles(self) -> pd.DataFrame:
        """The closed-loop poles at each value: the swept argument, then :attr:`Linearization.poles`'s columns."""
        return self._stacked([p.poles for p in self.points])

    @property
    def margins(self) -> pd.DataFrame:
        """The margins at each value: the swept argument, then :attr:`Linearization.margins`'s columns."""
        return self._stacked([p.margins for p in self.points])

    @property
    def gains(self) -> pd.DataFrame:
        """The frozen gains at each value: the swept argument, then :attr:`Linearization.gains`'s columns."""
        return self._stacked([p.gains for p in self.points])

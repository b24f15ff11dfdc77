"""The Lyapunov function V = kinetic + potential energy along a stored trajectory.

Theorems 2.1, 3.1, 3.2 and 4.1 state dV/dt = sum_i F_i v_i (the power of the base forces).
Both sides are computed here from the stored run: V-dot by differentiating V(x(t)) in
time, the power from the stored forces and base velocities.
"""

from __future__ import annotations

import numpy as np

from nlcx.engine import Run
from nlcx.plants.base import Plant


def lyapunov_rate(plant: Plant, run: Run) -> tuple[np.ndarray, np.ndarray]:
    """(dV/dt, sum F_i v_i) at the sampling instants of ``run``.

    dV/dt is the central difference of V (one-sided at the ends). The forces are held over
    each step, so the power uses the mean base velocity of the step at the step's midpoint
    and is averaged onto the samples the same way as the difference, which makes the two
    agree to the integration error.
    """
    if plant.features.energy is None or plant.features.power is None:
        raise ValueError(f"{plant.name} defines no energy function")
    V = plant.features.energy(run.x)
    t = run.t
    dV = np.gradient(V, t)
    # power of the held force over each step [t_k, t_k+1]: F_k * (q_k+1 - q_k) / dt
    step_power = np.zeros(t.size - 1)
    names = plant.state_names
    for j, name in enumerate(plant.input_names):
        axis = plant.features.input_axes.get(name)
        if axis is None:
            continue
        q = run.x[:, names.index(axis.removesuffix("_dot"))]
        step_power += run.u[:-1, j] * np.diff(q) / np.diff(t)
    power = np.empty(t.size)
    power[1:-1] = 0.5 * (step_power[1:] + step_power[:-1])
    power[0] = step_power[0]
    power[-1] = step_power[-1]
    return dV, power

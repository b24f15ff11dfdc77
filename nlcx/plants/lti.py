"""A python-control LTI system as an nlcx plant: :func:`from_control`.

A ``StateSpace`` (or a ``TransferFunction``, realised by python-control's ``ss``) is simulated
as dx/dt = A x + B u, y = C x: A and B are the plant's parameter vector (row by row), read by
one compiled right-hand side for every such plant (:func:`lti_rhs`), and C its output matrix.
The system must be continuous-time and strictly proper (D = 0): a controller sampled with a
zero-order hold and a direct feedthrough would form an algebraic loop. Its states, inputs and
outputs are named by the system's labels (``x[0]`` becomes ``x0``) or by the names given.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from nlcx import registry
from nlcx._numba_compat import hot_njit
from nlcx.errors import ConfigError
from nlcx.kernel.signatures import FloatArray
from nlcx.plants.base import Plant, PlantModel, PlantParams, Signal, divergence_bounds, initial_state

if TYPE_CHECKING:
    from control import StateSpace, TransferFunction

__all__ = ["LTIPlant", "from_control", "lti_rhs"]


@hot_njit(cache=True, error_model="numpy")
def lti_rhs(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, nb: int
) -> None:  # pragma: no cover - compiled
    """dx/dt = A x + B u for each of the first nb columns (variants) b: p[:, b] holds A row by
    row (n x n), then B row by row (n x m)."""
    n, m = x.shape[0], u.shape[0]
    for i in range(n):
        for b in range(nb):
            dx[i, b] = 0.0
        for j in range(n):  # each loop runs along a row, over the variants
            for b in range(nb):
                dx[i, b] += p[i * n + j, b] * x[j, b]
        for k in range(m):
            for b in range(nb):
                dx[i, b] += p[n * n + i * m + k, b] * u[k, b]


class LTIPlant(PlantModel):
    """A linear time-invariant plant from python-control (:func:`from_control`)."""

    rhs = staticmethod(lti_rhs)
    #: A, B and C of the system.
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    #: The output signals (y = C x need not select states).
    output_signals: tuple[Signal, ...] = ()

    def parameter_vector(self, params: PlantParams) -> np.ndarray:
        """A then B, row by row (the order :func:`lti_rhs` reads them)."""
        return np.concatenate([self.A.ravel(), self.B.ravel()])

    def build(
        self, name: str, params: PlantParams, x0: Mapping[str, float], bounds: Mapping[str, float], path: str = "plant"
    ) -> Plant:
        names = [s.name for s in self.states]
        return Plant(
            name=name,
            states=self.states,
            inputs=self.inputs,
            outputs=self.output_signals,
            rhs=self.rhs,
            p=self.parameter_vector(params),
            C=self.C.copy(),
            x0=initial_state(names, x0, path),
            params=params.model_dump(),
            param_units={},
            bounds=divergence_bounds(names, {**self.default_bounds, **bounds}),
        )


def _identifier(label: str) -> str:
    """A python-control label as a signal name: ``x[0]`` -> ``x0``."""
    name = re.sub(r"\W", "", label)
    return name if name and not name[0].isdigit() else f"s{name}"


def _signals(key: str, given: Sequence[str] | Mapping[str, str] | None, labels: Sequence[str]) -> tuple[Signal, ...]:
    """Signals named as ``given`` (names, or {name: unit}) or as the system's ``labels``."""
    if given is None:
        pairs = [(_identifier(label), "") for label in labels]
    elif isinstance(given, Mapping):
        pairs = [(str(k), str(v)) for k, v in given.items()]
    else:
        pairs = [(str(k), "") for k in given]
    if len(pairs) != len(labels):
        raise ConfigError(key, [p for p, _ in pairs], f"{len(labels)} names, one per {key[:-1]} of the system")
    for name, _ in pairs:
        if not name.isidentifier():
            raise ConfigError(key, name, "a signal name: a Python identifier, e.g. x_dot")
    if len({name for name, _ in pairs}) != len(pairs):
        raise ConfigError(key, [p for p, _ in pairs], "each name once")
    return tuple(Signal(name, unit) for name, unit in pairs)


def _state_space(system: object, name: str) -> StateSpace:
    """``system`` as a python-control state space, refused in one line unless it is a
    continuous-time, strictly proper (D = 0) StateSpace or TransferFunction."""
    import control as ct

    if not isinstance(system, ct.StateSpace | ct.TransferFunction):
        raise ConfigError("system", type(system).__name__, "a control.StateSpace or control.TransferFunction")
    ss = ct.ss(system)
    if not ss.isctime():
        raise ConfigError("system", name, "a continuous-time system (dt = 0 or None); discretisation is nlcx's")
    if np.any(ss.D != 0):
        raise ConfigError("system", name, "strictly proper (D = 0): a direct feedthrough and the controller's "
                          "zero-order hold would form an algebraic loop")  # fmt: skip
    return ss


def from_control(
    system: StateSpace | TransferFunction,
    name: str,
    *,
    states: Sequence[str] | Mapping[str, str] | None = None,
    inputs: Sequence[str] | Mapping[str, str] | None = None,
    outputs: Sequence[str] | Mapping[str, str] | None = None,
    bounds: Mapping[str, float] | None = None,
    replace: bool = True,
) -> LTIPlant:
    """Register a python-control LTI system as the nlcx plant ``name``.

    Parameters
    ----------
    system : control.StateSpace or control.TransferFunction
        Continuous-time and strictly proper (D = 0); a transfer function is realised by
        ``control.ss``.
    name : str
        The name a config's ``plant.name`` uses.
    states, inputs, outputs : sequence of str or mapping of str to unit, optional
        The signals' names (and units), in the system's order; default: its labels as names.
    bounds : mapping, optional
        Divergence bounds |x_i| <= bound by state name.
    replace : bool
        Replace an LTI plant registered under ``name`` before; a plant of another kind never.

    Returns
    -------
    LTIPlant
        The registered plant model.

    Examples
    --------
    >>> import control, nlcx
    >>> from nlcx.plants import from_control
    >>> _ = from_control(control.tf([1.0], [1.0, 2.0, 1.0]), "double_lag", inputs=["u"], outputs=["y"])
    >>> result = nlcx.run({"name": "lag", "plant": {"name": "double_lag"},
    ...                    "controllers": {"pi": {"kind": "pid", "loops": {
    ...                        "y": {"schedule": {"kind": "constant", "kp": 2.0, "ki": 1.0, "kd": 0.0}}}}},
    ...                    "reference": {"y": {"kind": "step", "final": 1.0}}, "simulation": {"t_end": 20.0}})
    >>> round(float(result.response("pi").y[0, -1]), 3)
    1.0
    """
    ss = _state_space(system, name)
    existing = registry.plants.get(name) if name in registry.plants else None
    if existing is not None and not (replace and isinstance(existing, LTIPlant)):
        raise ConfigError("plant", name, f"already registered ({type(existing).__name__}); allowed: a new name")
    state_signals = _signals("states", states, ss.state_labels)
    attributes = {
        "__doc__": f"{name}: a linear time-invariant plant from python-control ({ss.nstates} states)",
        "Params": PlantParams,
        "states": state_signals,
        "inputs": _signals("inputs", inputs, ss.input_labels),
        "output_signals": _signals("outputs", outputs, ss.output_labels),
        "outputs": (),
        "default_bounds": dict(bounds or {}),
        "A": np.array(ss.A, dtype=float),
        "B": np.array(ss.B, dtype=float),
        "C": np.array(ss.C, dtype=float),
    }
    model: LTIPlant = type(f"{name}_plant", (LTIPlant,), attributes)()
    registry.plants.register(name, model, replace=True)
    return model

"""What a plant is: its right-hand side f(t, x, u, p) plus metadata.

A registered plant is a :class:`PlantModel` subclass. It names its states, inputs and
outputs with units, declares its parameters as a pydantic model (the one place their
defaults live) and supplies a numba-compiled right-hand side with
:data:`nlcx.kernel.abi.RHS_SIG`: it evaluates the first nb columns of its arrays, one variant
a column (:func:`evaluate_rhs` calls it on one state or on rows of states).
:meth:`PlantModel.build` turns a validated configuration into a :class:`Plant`, the numeric
instance the engine integrates.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np
import numpy.typing as npt
from numba.core.errors import NumbaError
from pydantic import BaseModel, ConfigDict

from nlcx.errors import ConfigError, did_you_mean
from nlcx.kernel.signatures import RightHandSide


class PlantParams(BaseModel):
    """Base of every plant's parameter model: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


@dataclass(frozen=True)
class Signal:
    """A named signal with its SI unit and the words a figure labels it with."""

    name: str
    unit: str
    label: str = ""

    @property
    def axis_label(self) -> str:
        """E.g. 'Angle θ (rad)'."""
        text = self.label or self.name
        return f"{text} ({self.unit})" if self.unit else text


@dataclass(frozen=True)
class PlantFeatures:
    """What some plants offer beyond their equations; a new feature adds a field here.

    Every field has a neutral default, so a plant declares only what it has.
    """

    #: States whose derivative is an acceleration (default targets of a disturbance).
    velocity_states: tuple[str, ...] = ()
    #: Default input of a PID loop on each output.
    loop_inputs: Mapping[str, str] = field(default_factory=dict)
    #: Velocity state of the coordinate each input force drives (where friction acts).
    input_axes: Mapping[str, str] = field(default_factory=dict)
    #: Weight of the moving assembly, (M + m) g: the normal force of Appendix A's friction.
    weight: float | None = None
    #: Operating point (an equilibrium state) for feed-forward (gravity compensation) and
    #: linearisation; None: every state 0.
    x_op: np.ndarray | None = None
    #: Total mechanical energy E(x) and the inputs' power P(x, u) (the Lyapunov figures).
    energy: Callable[[np.ndarray], np.ndarray] | None = None
    power: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None


@dataclass(frozen=True)
class Plant:
    """A plant ready to simulate: equations, numeric parameters and metadata; optional
    capabilities (friction axes, operating point, energy, ...) in :attr:`features`."""

    name: str
    states: tuple[Signal, ...]
    inputs: tuple[Signal, ...]
    outputs: tuple[Signal, ...]
    rhs: RightHandSide
    p: np.ndarray
    C: np.ndarray
    x0: np.ndarray
    #: The validated parameters (the parameter model's fields).
    params: dict[str, object]
    param_units: dict[str, str]
    bounds: np.ndarray
    features: PlantFeatures = field(default_factory=PlantFeatures)

    @property
    def state_names(self) -> list[str]:
        return [s.name for s in self.states]

    @property
    def input_names(self) -> list[str]:
        return [s.name for s in self.inputs]

    @property
    def output_names(self) -> list[str]:
        return [s.name for s in self.outputs]

    def state_index(self, name: str) -> int:
        return self.state_names.index(name)

    def f(self, x: npt.ArrayLike, u: npt.ArrayLike, t: float = 0.0) -> np.ndarray:
        """dx/dt = f(t, x, u; p) for one state (1-D x, u) or for each row of 2-D x, u."""
        return evaluate_rhs(self.rhs, x, u, self.p, t)

    def unit_of(self, name: str) -> str:
        for sig in (*self.states, *self.inputs, *self.outputs):
            if sig.name == name:
                return sig.unit
        raise KeyError(name)


#: A plant's parameter model: the type of the ``params`` its :class:`PlantModel` methods receive.
ParamsT = TypeVar("ParamsT", bound=PlantParams)


class PlantModel(Generic[ParamsT]):
    """A registered plant. Subclasses set the class attributes and :meth:`parameter_vector`.

    A subclass names its parameter model twice: as :attr:`Params` (validated at run time) and as
    the type argument (``class PendulumModel(PlantModel[PendulumParams])``) its methods' ``params`` has."""

    Params: ClassVar[type[PlantParams]] = PlantParams
    states: ClassVar[tuple[Signal, ...]] = ()
    inputs: ClassVar[tuple[Signal, ...]] = ()
    #: Outputs are states measured directly (y = C x selects them).
    outputs: ClassVar[tuple[str, ...]] = ()
    #: States whose derivative is an acceleration (default targets of a disturbance).
    velocity_states: ClassVar[tuple[str, ...]] = ()
    #: Default divergence bounds |x_i| <= bound, by state name.
    default_bounds: ClassVar[Mapping[str, float]] = {}
    #: Input a PID loop on each output drives unless its config says otherwise.
    loop_inputs: ClassVar[Mapping[str, str]] = {}
    #: Velocity state of the coordinate each input force acts on (friction acts there too).
    input_axes: ClassVar[Mapping[str, str]] = {}
    #: The compiled right-hand side (:data:`~nlcx.kernel.signatures.RightHandSide`); every registered plant
    #: sets it. Any: the checker would bind a callable class attribute to the instance, as a method.
    rhs: ClassVar[Any] = None

    def __init_subclass__(cls, **kwargs: object) -> None:
        """Keep a right-hand side given as ``rhs = my_rhs`` a plain function of the class.

        A numba dispatcher (or a Python function) assigned as a class attribute would bind to
        the instance like a method, and the kernel would call it with ``self`` as a seventh
        argument; it is stored as a ``staticmethod`` instead, as if written so. A Python
        function that numba has not compiled is refused in one line that names the fix."""
        super().__init_subclass__(**kwargs)
        rhs = cls.__dict__.get("rhs")
        if rhs is None or isinstance(rhs, staticmethod):
            return
        if not hasattr(rhs, "py_func"):
            raise ConfigError(
                f"{cls.__name__}.rhs",
                getattr(rhs, "__name__", rhs),
                "a numba-compiled function: decorate it with @numba.njit(nlcx.kernel.abi.RHS_SIG), "
                "or write f(t, x, u, p) for one state and register it with @nlcx.plant",
            )
        cls.rhs = staticmethod(rhs)

    def parameter_vector(self, params: ParamsT) -> np.ndarray:
        """The parameter vector p the right-hand side reads."""
        raise NotImplementedError

    def select_rhs(self, params: ParamsT) -> RightHandSide:
        """The compiled right-hand side for these parameters (e.g. a model variant)."""
        return self.rhs

    def weight(self, params: ParamsT) -> float | None:
        """Weight of the moving assembly (the normal force of friction), if defined."""
        return None

    def operating_point(self, params: ParamsT) -> dict[str, float]:
        """The equilibrium state the plant is operated about (default: every state 0).

        It is also the default initial state."""
        return {}

    def energy(self, params: ParamsT) -> Callable[[np.ndarray], np.ndarray] | None:
        """Total mechanical energy E(x) (vectorised over leading axes), if defined."""
        return None

    def power(self, params: ParamsT) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
        """Power delivered by the inputs, P(x, u) = sum F_i v_i, if defined."""
        return None

    def build(
        self,
        name: str,
        params: ParamsT,
        x0: Mapping[str, float],
        bounds: Mapping[str, float],
        path: str = "plant",
    ) -> Plant:
        """The :class:`Plant` registered as ``name`` with these parameters, x0 and bounds."""
        states = self.states
        names = [s.name for s in states]
        x_op = initial_state(names, self.operating_point(params), path)
        x_init = initial_state(names, {**self.operating_point(params), **x0}, path)
        bound_vec = divergence_bounds(names, {**self.default_bounds, **bounds})
        outputs = tuple(states[names.index(o)] for o in self.outputs)
        C = np.zeros((len(outputs), len(states)))
        for i, o in enumerate(self.outputs):
            C[i, names.index(o)] = 1.0
        return Plant(
            name=name,
            states=states,
            inputs=self.inputs,
            outputs=outputs,
            rhs=self.select_rhs(params),
            p=np.ascontiguousarray(self.parameter_vector(params), dtype=float),
            C=C,
            x0=x_init,
            params=params.model_dump(),
            param_units=param_units(type(params)),
            bounds=bound_vec,
            features=PlantFeatures(
                velocity_states=self.velocity_states,
                loop_inputs=dict(self.loop_inputs),
                input_axes=dict(self.input_axes),
                weight=self.weight(params),
                x_op=x_op,
                energy=self.energy(params),
                power=self.power(params),
            ),
        )


def param_units(model: type[BaseModel]) -> dict[str, str]:
    """Units declared on a parameter model's fields (``json_schema_extra={'unit': ...}``)."""
    units = {}
    for name, info in model.model_fields.items():
        extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
        units[name] = str(extra.get("unit", ""))
    return units


def initial_state(names: list[str], x0: Mapping[str, float], path: str = "plant") -> np.ndarray:
    """x(0): zero except the states named in ``x0``."""
    x_init = np.zeros(len(names))
    for key, value in x0.items():
        if key not in names:
            problem = f"unknown state{did_you_mean(key, names)}; allowed: {', '.join(names)}"
            raise ConfigError(f"{path}.x0.{key}", value, problem)
        x_init[names.index(key)] = float(value)
    return x_init


def divergence_bounds(names: list[str], bounds: Mapping[str, float]) -> np.ndarray:
    """Per-state bound on |x_i| (inf where none is set)."""
    bound_vec = np.full(len(names), np.inf)
    for key, value in bounds.items():
        if key not in names:
            problem = f"unknown state{did_you_mean(key, names)}; allowed: {', '.join(names)}"
            raise ConfigError(f"simulation.bounds.{key}", value, problem)
        bound_vec[names.index(key)] = float(value)
    return bound_vec


def equilibrium_input(plant: Plant, x_eq: np.ndarray | None = None, tol: float = 1e-9) -> np.ndarray:
    """The input u* that holds ``x_eq`` (default: the plant's operating point; for the
    pendulums every state zero, upright at rest).

    The accelerations of a mechanical plant are affine in its generalised forces,
    f(x, u) = f(x, 0) + B(x) u, so u* solves B u* = -f(x_eq, 0) (least squares). For the
    x-z and x-y-z pendulums this is the gravity compensation F_z = (M + m) g.
    """
    n, m = len(plant.states), len(plant.inputs)
    if x_eq is None:
        x_eq = plant.features.x_op if plant.features.x_op is not None else np.zeros(n)
    x = np.asarray(x_eq, dtype=float)
    f0 = plant.f(x, np.zeros(m))
    B = np.column_stack([plant.f(x, e) - f0 for e in np.eye(m)])
    u, *_ = np.linalg.lstsq(B, -f0, rcond=None)
    residual = f0 + B @ u
    if np.max(np.abs(residual)) > tol * max(1.0, np.max(np.abs(f0))):
        raise ConfigError("feedforward", "equilibrium", f"no input holds {plant.name} at this state")
    return u


def linearize(
    plant: Plant,
    x_op: np.ndarray | None = None,
    u_op: np.ndarray | None = None,
    h: float = 1e-6,
    relative: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C) of dx/dt = f(x, u) about (x_op, u_op) by central differences (y = C x): column
    j of A is (f(x + h_j e_j, u) - f(x - h_j e_j, u)) / (2 h_j), and B's likewise in u.

    Defaults: the operating point and the input that holds it (:func:`equilibrium_input`).
    The step h_j is ``h``, or with ``relative`` h max(1, |x_j|) (|u_j| for B): a step that
    grows with a large coordinate (e.g. a temperature in K) stays above its rounding.
    """
    op = plant.features.x_op
    x0 = (op if op is not None else np.zeros(len(plant.states))) if x_op is None else np.asarray(x_op, float)
    u0 = equilibrium_input(plant, x0) if u_op is None else np.asarray(u_op, float)
    A = _central_differences(lambda dx: plant.f(x0 + dx, u0), x0, h, relative)
    B = _central_differences(lambda du: plant.f(x0, u0 + du), u0, h, relative)
    return A, B, plant.C.copy()


def _central_differences(f: Callable[[np.ndarray], np.ndarray], at: np.ndarray, h: float, relative: bool) -> np.ndarray:
    """The Jacobian of ``f(d)``, a function of a deviation d from ``at``, by central differences
    (see :func:`linearize`): one column a coordinate of ``at``."""
    steps = h * np.maximum(1.0, np.abs(at)) if relative else np.full(at.size, h)
    columns = []
    for j, step in enumerate(steps):
        d = np.zeros(at.size)
        d[j] = step
        columns.append((f(d) - f(-d)) / (2 * step))
    return np.column_stack(columns)


def evaluate_rhs(
    rhs: RightHandSide, x: npt.ArrayLike, u: npt.ArrayLike, p: npt.ArrayLike, t: float = 0.0
) -> np.ndarray:
    """Call a compiled right-hand side on one state (1-D x, u; returns 1-D) or on rows of
    states (2-D, one state a row; returns rows; p one row or one per row).

    The right-hand side (:data:`nlcx.kernel.abi.RHS_SIG`) takes the variants as columns: the
    rows are handed to it transposed, as contiguous columns."""
    x = np.asarray(x, dtype=float)
    single = x.ndim == 1
    X = np.atleast_2d(x)
    nb = X.shape[0]

    def columns(a: npt.ArrayLike) -> np.ndarray:
        a = np.atleast_2d(np.asarray(a, dtype=float))
        return np.array(np.broadcast_to(a, (nb, a.shape[1])).T, order="C")

    U, P = columns(u), columns(p)
    out = np.zeros((X.shape[1], nb))
    rhs(float(t), columns(X), U, P, out, nb)
    return out[:, 0] if single else out.T.copy()


_ROWS_CHECKED: set[int] = set()


def check_rows(plant: Plant) -> None:
    """Guard against a right-hand side written for a single state: two different variants
    evaluated together must equal each evaluated alone (columns are variants, see
    :data:`nlcx.kernel.abi.RHS_SIG`). Checked once per compiled function."""
    key = id(plant.rhs)
    if key in _ROWS_CHECKED:
        return
    n, m = len(plant.states), len(plant.inputs)
    base = plant.features.x_op if plant.features.x_op is not None else np.zeros(n)
    X = np.stack([base, base + 0.01 * (1 + np.arange(n))])
    U = np.stack([np.zeros(m), 0.5 + np.arange(m)])
    P = np.stack([plant.p, plant.p * 1.01])
    try:
        together = evaluate_rhs(plant.rhs, X, U, P)
    except (TypeError, NumbaError) as exc:  # e.g. rhs(t, x, u, p, dx), the ABI before columns
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConfigError(
            "plant.name",
            plant.name,
            f"its right-hand side cannot be called as rhs(t, x, u, p, dx, nb) with (n, B) arrays "
            f"(nlcx.kernel.abi.RHS_SIG; a plant written for rows, rhs(t, x, u, p, dx), needs rewriting): {first}",
        ) from None
    alone = np.stack([evaluate_rhs(plant.rhs, X[i], U[i], P[i]) for i in range(2)])
    if not np.array_equal(together, alone, equal_nan=True):
        raise ConfigError(
            "plant.name",
            plant.name,
            "its right-hand side does not evaluate the variants of x independently; it must loop "
            "over the first nb columns (variants) as nlcx.kernel.abi.RHS_SIG documents",
        )
    _ROWS_CHECKED.add(key)

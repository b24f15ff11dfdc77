"""A plant written in plain Python: a scalar right-hand side ``f(t, x, u, p) -> dx`` for one state.

The kernel integrates a batch of variants in lock step and calls a plant's right-hand side
with :data:`nlcx.kernel.abi.RHS_SIG` (2-D arrays, one variant a column). :func:`plant` lets a
user write the equations for one state instead, with ``math`` or numpy, and read the
parameters by name; it compiles the function with numba, wraps it in a loop over the
variants, checks it once and registers it under a name, so a config's ``plant: {name: ...}``
runs it under every controller nlcx has.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, TypeVar, cast

import numpy as np
from pydantic import Field, create_model

from nlcx import registry
from nlcx.errors import ConfigError
from nlcx.kernel.signatures import RightHandSide
from nlcx.plants.base import PlantModel, PlantParams, Signal

__all__ = ["ScalarPlant", "plant"]

#: How a signal may be declared: its unit, or (unit, label).
SignalSpec = str | tuple[str, str]
#: How a parameter may be declared: its default, or (default, unit), or (default, unit, description).
ParamSpec = float | tuple[float, str] | tuple[float, str, str]
#: A right-hand side for one state, ``f(t, x, u, p) -> dx`` (``p``: the parameters by name).
ScalarFunction = TypeVar("ScalarFunction", bound=Callable[..., object])


@dataclass(frozen=True)
class _Declared:
    """What :func:`plant` was told: names, units and defaults."""

    name: str
    states: tuple[Signal, ...]
    inputs: tuple[Signal, ...]
    outputs: tuple[str, ...]
    params: tuple[tuple[str, float, str, str], ...]


def _signals(kind: str, spec: Mapping[str, SignalSpec] | Sequence[str]) -> tuple[Signal, ...]:
    """Signals from ``{name: unit}``, ``{name: (unit, label)}`` or a list of names."""
    items = spec.items() if isinstance(spec, Mapping) else ((name, "") for name in spec)
    out = []
    for name, value in items:
        if not isinstance(name, str) or not name.isidentifier():
            raise ConfigError(kind, name, "a signal name must be a Python identifier, e.g. x_dot")
        unit, label = (value, "") if isinstance(value, str) else tuple(value)
        out.append(Signal(name, str(unit), str(label)))
    if not out:
        raise ConfigError(kind, dict(spec) if isinstance(spec, Mapping) else list(spec), "declare at least one")
    return tuple(out)


def _parameters(spec: Mapping[str, ParamSpec]) -> tuple[tuple[str, float, str, str], ...]:
    """(name, default, unit, description) of each declared parameter."""
    out = []
    for name, value in spec.items():
        if not name.isidentifier() or name.startswith("_"):
            raise ConfigError("params", name, "a parameter name must be a Python identifier not starting with _")
        default, unit, text = (value, "", "") if not isinstance(value, tuple) else (*value, "", "")[:3]
        if not isinstance(default, (int, float)) or not math.isfinite(default):
            raise ConfigError(f"params.{name}", default, "a finite number as the default")
        out.append((name, float(default), str(unit), str(text)))
    return tuple(out)


def _params_model(declared: _Declared) -> type[PlantParams]:
    """The pydantic parameter model: one float field per parameter, its unit in the schema."""
    fields: dict[str, Any] = {  # pydantic.create_model takes its field definitions untyped
        name: (float, Field(default, description=text or None, json_schema_extra={"unit": unit}))
        for name, default, unit, text in declared.params
    }
    model: type[PlantParams] = create_model(f"{declared.name}_params", __base__=PlantParams, **fields)
    return model


def _batched_source(n_states: int, n_inputs: int, param_names: Sequence[str]) -> str:
    """Source of the right-hand side with :data:`~nlcx.kernel.abi.RHS_SIG`: for each of the
    first nb columns (variants) b, copy column b of x and u into one-variant vectors, build the
    named parameters from column b of p, call the user's ``f`` and write its result to dx[:, b]."""
    params = ", ".join(f"p[{k}, b]" for k in range(len(param_names)))
    writes = "\n".join(f"        dx[{i}, b] = d[{i}]" for i in range(n_states))
    return f"""
def rhs(t, x, u, p, dx, nb):
    xs = np.empty({n_states})
    us = np.empty({max(n_inputs, 1)})
    for b in range(nb):
        for i in range({n_states}):
            xs[i] = x[i, b]
        for j in range({n_inputs}):
            us[j] = u[j, b]
        d = f(t, xs, us, Params({params}))
{writes}
"""


def compile_scalar(f: Callable[..., object], declared: _Declared) -> tuple[Callable[..., object], type]:
    """(``f`` compiled by numba, the named tuple type its parameters ``p`` have)."""
    from numba import njit

    names = [name for name, *_ in declared.params]
    params_type = NamedTuple(f"{declared.name}_p", [(name, float) for name in names])  # type: ignore[misc]  # fields known at run time only
    scalar = f if hasattr(f, "py_func") else njit(error_model="numpy")(f)
    return scalar, params_type


def batched_rhs(scalar: Callable[..., object], params_type: type, declared: _Declared) -> RightHandSide:
    """The right-hand side with the kernel's batched signature that calls ``scalar`` on each
    variant (:func:`_batched_source`)."""
    from numba import njit

    from nlcx.kernel.abi import RHS_SIG

    names = [name for name, *_ in declared.params]
    namespace: dict[str, object] = {"np": np, "f": scalar, "Params": params_type}
    source = _batched_source(len(declared.states), len(declared.inputs), names)
    exec(compile(source, f"<nlcx plant {declared.name}>", "exec"), namespace)
    rhs = cast(RightHandSide, namespace["rhs"])  # the function the source defines
    return njit(RHS_SIG, error_model="numpy")(rhs)


class ScalarPlant(PlantModel[PlantParams]):
    """A plant declared with :func:`plant` from a scalar right-hand side (see there)."""

    #: The user's function, as written (for ``nlcx list``).
    function: ClassVar[Callable[..., object] | None] = None

    def parameter_vector(self, params: PlantParams) -> np.ndarray:
        """The parameters in their declared order (the order the named tuple reads them)."""
        return np.array([getattr(params, name) for name in type(params).model_fields], dtype=float)


#: numba's lines around the one that says what went wrong.
_CONTEXT_LINES = ("Failed in ", "During:", "File ", "<source missing", "^", "Cannot determine Numba type")


def _not_callable(name: str, exc: Exception) -> ConfigError:
    """The one-line error of a function numba cannot compile or that fails when called: the
    line of numba's message that says what went wrong, without its colours and context."""
    import re

    lines = [re.sub(r"\x1b\[[0-9;]*m", "", line).strip() for line in str(exc).splitlines()]
    useful = [line for line in lines if line and not line.startswith(_CONTEXT_LINES)]
    first = (useful or [line for line in lines if line] or [type(exc).__name__])[0]
    return ConfigError("plant", name, f"its function cannot be compiled or called as f(t, x, u, p): {first}")


def _check_scalar(scalar: Callable[..., object], params_type: type, declared: _Declared) -> np.ndarray:
    """A checker at registration: ``f(0, zeros, zeros, defaults)`` runs and returns one finite
    derivative per declared state (a wrong count or a failure is one line); its value."""
    n, m = len(declared.states), len(declared.inputs)
    defaults = params_type(*(default for _, default, *_ in declared.params))
    try:
        direct = np.asarray(scalar(0.0, np.zeros(n), np.zeros(max(m, 1)), defaults), dtype=float)
    except Exception as exc:  # numba's typing errors are long: keep the line that matters
        raise _not_callable(declared.name, exc) from None
    if direct.shape != (n,) or not np.all(np.isfinite(direct)):
        shown = direct.tolist() if direct.ndim else float(direct)
        raise ConfigError(
            "plant", declared.name, f"f(0, 0, 0, defaults) gave {shown}: one finite derivative per declared state ({n})"
        )
    return direct


def _check_batched(model: ScalarPlant, declared: _Declared, direct: np.ndarray) -> None:
    """The wrapped right-hand side gives ``f``'s value at the zero state (the copy in and out
    of the batch's columns)."""
    n, m = len(declared.states), len(declared.inputs)
    dx = model.build(declared.name, model.Params(), {}, {}).f(np.zeros(n), np.zeros(m))
    if not np.array_equal(dx, direct):  # pragma: no cover - a defect of the wrapper, not of f
        raise ConfigError("plant", declared.name, f"the batched right-hand side gave {dx.tolist()}, f gave {direct}")


#: The divergence bound |x_i| <= 1e6 of every state of a plant :func:`plant` registers, unless
#: its ``bounds`` say otherwise.
DEFAULT_BOUND = 1e6


def plant(
    name: str,
    *,
    states: Mapping[str, SignalSpec] | Sequence[str],
    inputs: Mapping[str, SignalSpec] | Sequence[str],
    outputs: Sequence[str] | None = None,
    params: Mapping[str, ParamSpec] | None = None,
    bounds: Mapping[str, float] | None = None,
    loop_inputs: Mapping[str, str] | None = None,
    velocity_states: Sequence[str] = (),
    replace: bool = True,
) -> Callable[[ScalarFunction], ScalarFunction]:
    """Register a plant written as a scalar right-hand side ``f(t, x, u, p) -> dx``.

    ``f`` computes dx/dt = f(t, x, u; p) for one state: ``x`` and ``u`` are 1-D float arrays in
    the declared order of states and inputs, ``p`` holds the parameters by name (``p.k``), and
    it returns one derivative per state (a tuple, list or array). It may use ``math`` and the
    numpy functions numba compiles. The decorator compiles ``f``, wraps it for the kernel (one
    variant a column, :data:`nlcx.kernel.abi.RHS_SIG`), calls it once on the default parameters
    at the zero state (a failure is one line), and registers the plant in
    :data:`nlcx.registry.plants`; the function itself is returned unchanged.

    Parameters
    ----------
    name : str
        The name a config's ``plant.name`` uses.
    states, inputs : mapping or sequence of str
        Names in order, with units: ``{"x": "m", "v": "m/s"}`` (or ``{"x": ("m", "Position")}``
        with a figure label, or just a list of names).
    outputs : sequence of str, optional
        The measured states (y = C x selects them); default: every state.
    params : mapping, optional
        ``{name: default}``, ``{name: (default, unit)}`` or ``{name: (default, unit, description)}``.
    bounds : mapping, optional
        Divergence bounds |x_i| <= bound by state name (``simulation.bounds`` adds to them);
        other states get :data:`DEFAULT_BOUND` (1e6), so a diverging run stops there (status
        ``unstable``) instead of overflowing. ``math.inf`` leaves a state unbounded.
    loop_inputs : mapping, optional
        The input a PID loop on each output drives by default; with one input, that input.
    velocity_states : sequence of str
        States whose derivative is an acceleration (where a disturbance enters by default).
    replace : bool
        Replace a plant registered under ``name`` before (a notebook cell run again), never a built-in.

    Returns
    -------
    callable
        A decorator that registers ``f`` and returns it.

    Examples
    --------
    A mass on a spring, driven by a force:

    >>> import nlcx
    >>> @nlcx.plant("mass_spring", states={"x": "m", "v": "m/s"}, inputs={"F": "N"},
    ...             outputs=["x"], params={"k": (4.0, "N/m"), "mass": (1.0, "kg")})
    ... def mass_spring(t, x, u, p):
    ...     return (x[1], (u[0] - p.k * x[0]) / p.mass)
    >>> result = nlcx.run({
    ...     "name": "spring", "plant": {"name": "mass_spring"},
    ...     "controllers": {"pid": {"kind": "pid", "loops": {
    ...         "x": {"schedule": {"kind": "constant", "kp": 20.0, "ki": 10.0, "kd": 5.0}}}}},
    ...     "reference": {"x": {"kind": "step", "final": 1.0}},
    ...     "simulation": {"t_end": 10.0, "dt": 0.01}})
    >>> result.status("pid")
    'ok'
    >>> bool(abs(result.trajectory("pid")["x"].iloc[-1] - 1.0) < 0.01)
    True
    """
    return _registrar(name, states, inputs, outputs, params, bounds, loop_inputs, velocity_states, replace)


def _registrar(
    name: str,
    states: Mapping[str, SignalSpec] | Sequence[str],
    inputs: Mapping[str, SignalSpec] | Sequence[str],
    outputs: Sequence[str] | None,
    params: Mapping[str, ParamSpec] | None,
    bounds: Mapping[str, float] | None,
    loop_inputs: Mapping[str, str] | None,
    velocity_states: Sequence[str],
    replace: bool,
) -> Callable[[ScalarFunction], ScalarFunction]:
    """The decorator of :func:`plant`: the declaration (names, outputs, loop inputs) checked
    before ``f`` is seen, then ``f`` registered with it."""
    declared = _declared(name, states, inputs, outputs, params)
    out_names = _outputs(declared, velocity_states, bounds)
    loops = _loop_inputs(declared, out_names, loop_inputs)

    def register(f: ScalarFunction) -> ScalarFunction:
        limits = {**dict.fromkeys((s.name for s in declared.states), DEFAULT_BOUND), **(bounds or {})}
        return _register(f, declared, out_names, loops, tuple(velocity_states), limits, replace)

    return register


def _declared(
    name: str,
    states: Mapping[str, SignalSpec] | Sequence[str],
    inputs: Mapping[str, SignalSpec] | Sequence[str],
    outputs: Sequence[str] | None,
    params: Mapping[str, ParamSpec] | None,
) -> _Declared:
    """The plant's signals and parameters as :func:`plant` was given them, validated."""
    return _Declared(
        name=name,
        states=_signals("states", states),
        inputs=_signals("inputs", inputs),
        outputs=tuple(outputs) if outputs is not None else (),
        params=_parameters(params or {}),
    )


def _outputs(
    declared: _Declared, velocity_states: Sequence[str], bounds: Mapping[str, float] | None
) -> tuple[str, ...]:
    """The measured states (default: every state); they, the velocity states and the bounded
    states must be declared states."""
    state_names = [s.name for s in declared.states]
    out_names = declared.outputs or tuple(state_names)
    for key in (*out_names, *velocity_states, *(bounds or {})):
        if key not in state_names:
            raise ConfigError("outputs", key, f"not a declared state; allowed: {', '.join(state_names)}")
    return tuple(out_names)


def _loop_inputs(
    declared: _Declared, out_names: tuple[str, ...], loop_inputs: Mapping[str, str] | None
) -> dict[str, str]:
    """The input a PID loop on each output drives by default (with one input: that input)."""
    input_names = [s.name for s in declared.inputs]
    loops = dict(loop_inputs) if loop_inputs is not None else {}
    if not loops and len(input_names) == 1:
        loops = dict.fromkeys(out_names, input_names[0])
    for output, input_name in loops.items():
        if output not in out_names or input_name not in input_names:
            raise ConfigError(f"loop_inputs.{output}", input_name, f"an output ({', '.join(out_names)}) "
                              f"mapped to an input ({', '.join(input_names)})")  # fmt: skip
    return loops


def _register(
    f: ScalarFunction,
    declared: _Declared,
    out_names: tuple[str, ...],
    loops: dict[str, str],
    velocity_states: tuple[str, ...],
    bounds: dict[str, float],
    replace: bool,
) -> ScalarFunction:
    """Compile ``f``, check it, wrap it for the kernel and register its plant (see :func:`plant`)."""
    name = declared.name
    scalar, params_type = compile_scalar(f, declared)
    direct = _check_scalar(scalar, params_type, declared)
    try:
        rhs = batched_rhs(scalar, params_type, declared)
    except Exception as exc:  # pragma: no cover - f compiled and ran above
        raise _not_callable(name, exc) from None
    existing = registry.plants.get(name) if name in registry.plants else None
    if existing is not None and not (replace and isinstance(existing, ScalarPlant)):
        allowed = "a new name" + ("" if replace else ", or replace=True")
        raise ConfigError("plant", name, f"already registered ({type(existing).__name__}); allowed: {allowed}")
    model_cls = type(
        f"{name}_plant",
        (ScalarPlant,),
        {
            "__doc__": (f.__doc__ or f"{name}: a plant written in plain Python").strip().splitlines()[0],
            "Params": _params_model(declared),
            "states": declared.states,
            "inputs": declared.inputs,
            "outputs": out_names,
            "velocity_states": velocity_states,
            "default_bounds": bounds,
            "loop_inputs": loops,
            "rhs": staticmethod(rhs),
            "function": staticmethod(f),
        },
    )
    model = model_cls()
    _check_batched(model, declared, direct)
    registry.plants.register(name, model, replace=True)
    return f

"""A control law in plain Python, ``law(t, dt, y, r, s, p) -> (u, s_next)``, for one variant.

The kernel steps a batch of variants in lock step and calls a controller's step with
:data:`nlcx.kernel.abi.CONTROLLER_SIG` (2-D arrays, one variant a row). :func:`controller`
lets a user write the law for one variant instead, read its parameters by name and keep
states of its own; it compiles the law with numba, generates the batched step that calls it
on each row (:func:`step_source`), checks it once and registers it, so that a config's
``controllers: {label: {kind: NAME}}`` runs it beside every controller nlcx has, under every
loop element, uncertainty, metric, sweep and report, and on the GPU, where the same generated
step is compiled for CUDA from its source (:class:`nlcx.kernel.device.Retarget`).

What the law sees at a control step t_k (every integration step, or every ``sample_time``):

- ``y``: the measured values, a tuple in the order of ``measures``. A name the plant has as
  an output is read after the sensor elements (measurement noise, quantiser); a name that is
  only a state is read from the true state x_k (full-state feedback).
- ``r``: the references, a tuple in the order of ``references``, at t_k.
- ``s``: the law's own states, a tuple in the order of ``states``; they are logged as updated
  at each control step.
- ``p``: the parameters, by name (``p.k1``; a tuple by position for nlcx's generated laws).
- ``dt``: the period of the law: the integration step, or ``sample_time``.

It returns the inputs it drives, in the order of ``inputs``, and the next value of its states
(and, with ``signals``, a third tuple: internal signals to log). The inputs are held until the
next control step (zero-order hold, as the PID's are); a plant input the law does not drive is
0. Its states and signals are logged every sample as ``<name>.<state>`` and ``<name>.<signal>``.

Per variant, the parameter row and the state row are laid out as:

- ``cp``: the measures' codes (a code c >= 0 reads state c of x, c < 0 output -c - 1 of y), the
  driven inputs' indices, the steps per control step (``hold``), the law's period (0: the
  integration step), then the parameters;
- ``cs``: the steps taken, the held inputs, the law's states, its signals.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Literal, NamedTuple, TypeVar

import numpy as np
from pydantic import Field, create_model

from nlcx import registry
from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel, check_sample_time
from nlcx.controllers.law_shape import LawShape, ParamSpec, shape_of
from nlcx.errors import ConfigError, did_you_mean
from nlcx.kernel.signatures import ControlLaw, ControllerStep, FloatArray, NumbaFunction
from nlcx.plants.base import Plant

__all__ = ["LawController", "LawShape", "controller", "law_model", "step_source"]

#: A law as its author wrote it (:func:`controller` returns it unchanged).
LawT = TypeVar("LawT", bound=ControlLaw)


def step_source(shape: LawShape) -> str:
    """Source of the batched step (:data:`~nlcx.kernel.abi.CONTROLLER_SIG`) that calls ``law``
    on every row b: at a control step (every ``hold``-th step) it gathers the row's measures,
    references, states and parameters into tuples, calls the law and keeps what it returns in
    ``cs``; every step it writes the held inputs to ``u`` (0 for an input the law does not
    drive) and the states and signals to ``log``. Offsets are literals of this shape's layout."""
    n_y, n_u, n_s, n_g, s0 = shape.n_y, shape.n_u, shape.n_s, shape.n_g, shape.s0
    g0 = s0 + n_s
    hold, period, p0 = shape.hold, shape.hold + 1, shape.p0

    def tup(items: list[str]) -> str:
        return "(" + "".join(f"{item}, " for item in items) + ")"

    ys = tup([f"measure(x, y, b, cp[b, {i}])" for i in range(n_y)])
    rs = tup([f"r[b, {j}]" for j in range(shape.n_r)])
    ss = tup([f"cs[b, {s0 + i}]" for i in range(n_s)])
    ps = ("Params" if shape.named_params else "") + tup([f"cp[b, {p0 + k}]" for k in range(shape.n_p)])
    keep = [f"            cs[b, {1 + j}] = out[0][{j}]" for j in range(n_u)]
    keep += [f"            cs[b, {s0 + i}] = out[1][{i}]" for i in range(n_s)]
    keep += [f"            cs[b, {g0 + k}] = out[2][{k}]" for k in range(n_g)]
    writes = [f"        u[b, int(cp[b, {n_y + j}])] = cs[b, {1 + j}]" for j in range(n_u)]
    logs = [f"        log[b, {i}] = cs[b, {s0 + i}]" for i in range(n_s + n_g)]
    return f"""
def step(t, dt, x, y, r, cp, cs, u, log, callbacks):
    for b in range(u.shape[0]):
        if cs[b, 0] % cp[b, {hold}] == 0.0:
            period = cp[b, {period}] if cp[b, {period}] > 0.0 else dt
            out = law(t, period, {ys}, {rs}, {ss}, {ps})
{chr(10).join(keep) or "            pass"}
        cs[b, 0] += 1.0
        for j in range(u.shape[1]):
            u[b, j] = 0.0
{chr(10).join(writes)}
{chr(10).join(logs)}
"""


def _measure_function() -> NumbaFunction:
    """The compiled helper the step reads a measure with: state ``code`` of x, or output
    ``-code - 1`` of y."""
    from numba import njit

    def measure(x: FloatArray, y: FloatArray, b: int, code: int) -> float:  # pragma: no cover - compiled
        c = int(code)
        return x[b, c] if c >= 0 else y[b, -c - 1]

    return njit(inline="always", error_model="numpy")(measure)


def compile_law(f: ControlLaw, shape: LawShape) -> tuple[ControlLaw, type | None]:
    """(``f`` compiled by numba, the named tuple type of its parameters, or None when ``p`` is a
    plain tuple)."""
    from numba import njit

    fields = [(name, float) for name, *_ in shape.params]
    named: Any = NamedTuple  # a named tuple whose fields are known at run time only
    params_type = named(f"{shape.name}_p", fields) if shape.named_params else None
    law = f if hasattr(f, "py_func") else njit(error_model="numpy")(f)
    return law, params_type


def batched_step(law: ControlLaw, params_type: type | None, shape: LawShape) -> ControllerStep:
    """The step with the kernel's batched signature that calls ``law`` on every row (:func:`step_source`)."""
    from nlcx._numba_compat import hot_njit
    from nlcx.kernel.abi import CONTROLLER_SIG

    namespace: dict[str, object] = {"law": law, "Params": params_type, "measure": _measure_function()}
    exec(compile(step_source(shape), f"<nlcx controller {shape.name}>", "exec"), namespace)
    return hot_njit(CONTROLLER_SIG, error_model="numpy")(namespace["step"])


def _defaults(shape: LawShape, params_type: type | None) -> tuple[float, ...]:
    """The parameters' defaults as the law receives them."""
    values = [default for _, default, *_ in shape.params]
    return params_type(*values) if params_type is not None else tuple(values)


#: numba's lines around the one that says what went wrong.
_CONTEXT_LINES = ("Failed in ", "During:", "File ", "<source missing", "^", "Cannot determine Numba type")


def _failure(name: str, exc: Exception) -> ConfigError:
    """The one-line error of a law numba cannot compile or that fails when called."""
    lines = [re.sub(r"\x1b\[[0-9;]*m", "", line).strip() for line in str(exc).splitlines()]
    useful = [line for line in lines if line and not line.startswith(_CONTEXT_LINES)]
    first = (useful or [line for line in lines if line] or ["it cannot be called"])[0]
    return ConfigError("controller", name, f"its law cannot be compiled or called as law(t, dt, y, r, s, p): {first}")


def _parts(out: object) -> list[tuple[Any, ...]] | None:
    """What a law returned as a list of 2 or 3 tuples, or None when it is not that."""
    if not isinstance(out, tuple) or len(out) not in (2, 3):
        return None
    parts = [part for part in out if isinstance(part, tuple)]
    return parts if len(parts) == len(out) else None


def check_law(law: ControlLaw, params_type: type | None, shape: LawShape) -> tuple[tuple[float, ...], ...]:
    """A checker at registration: ``law(0, T, zeros, zeros, initial states, defaults)`` runs
    and returns (inputs, next states[, signals]) of the declared sizes, every value finite;
    a wrong arity, return shape or value is one line naming the controller. What it returned."""
    period = shape.sample_time or 1e-3
    args = (0.0, period, (0.0,) * shape.n_y, (0.0,) * shape.n_r, tuple(v for _, v in shape.states))
    try:
        out = law(*args, _defaults(shape, params_type))
    except Exception as exc:  # numba's typing errors are long: keep the line that matters
        raise _failure(shape.name, exc) from None
    parts = _parts(out)
    expected = [shape.n_u, shape.n_s] + ([shape.n_g] if shape.n_g else [])
    wanted = f"a tuple of the inputs ({shape.n_u}), a tuple of the next states ({shape.n_s})" + (
        f" and a tuple of the signals ({shape.n_g})" if shape.n_g else ""
    )
    if parts is None or [len(part) for part in parts] != expected:
        shown = repr(out) if len(repr(out)) < 120 else repr(out)[:117] + "..."
        raise ConfigError("controller", shape.name, f"its law returned {shown} at the zero point; allowed: {wanted}")
    values = [float(v) for part in parts for v in part]
    if not all(math.isfinite(v) for v in values):
        raise ConfigError("controller", shape.name, f"its law returned {out} at the zero point: every value finite")
    return tuple(parts)


class LawController(ControllerModel):
    """A controller written as a law for one variant (:func:`controller`; see the module docstring)."""

    #: What the law reads and writes.
    shape: ClassVar[LawShape]
    #: The law as compiled, called by the step and by the linearisation.
    law: ClassVar[ControlLaw | None] = None
    #: The named tuple of its parameters (None: a plain tuple).
    params_type: ClassVar[type | None] = None
    #: The user's function, as written (for ``nlcx list``).
    function: ClassVar[ControlLaw | None] = None

    def parameters(self, cfg: Any, plant: Plant, path: str) -> np.ndarray:
        """The law's parameter values, in the order of :attr:`shape`'s ``params``."""
        return np.array([getattr(cfg, name) for name, *_ in self.shape.params], dtype=float)

    def measure_codes(self, plant: Plant, path: str) -> list[float]:
        """Each measure's code in ``cp``: an output of the plant read from y (after the sensor
        elements), else a state read from x; an unknown name is one line naming both lists."""
        codes = []
        for name in self.shape.measures:
            if name in plant.output_names:
                codes.append(-1.0 - plant.output_names.index(name))
            elif name in plant.state_names:
                codes.append(float(plant.state_names.index(name)))
            else:
                states = [s for s in plant.state_names if s not in plant.output_names]
                known = [*plant.output_names, *states]
                allowed = f"its outputs and states ({', '.join(known)})"
                raise ConfigError(
                    path,
                    self.shape.name,
                    f"measures {name!r}, which {plant.name} has not{did_you_mean(name, known)}; allowed: {allowed}",
                )
        return codes

    def _checked_names(self, plant: Plant, path: str) -> list[float]:
        """The driven inputs' indices; the inputs and references must be the plant's."""
        for name in self.shape.references:
            signals = [*plant.output_names, *plant.input_names]
            if name not in signals:
                hint = did_you_mean(name, signals)
                problem = f"reads the reference {name!r}, which is no signal of {plant.name}{hint}"
                raise ConfigError(path, self.shape.name, f"{problem}; allowed: {', '.join(signals)}")
        indices = []
        for name in self.shape.inputs:
            if name not in plant.input_names:
                hint = did_you_mean(name, plant.input_names)
                problem = f"drives the input {name!r}, which {plant.name} has not{hint}"
                raise ConfigError(path, self.shape.name, f"{problem}; allowed: {', '.join(plant.input_names)}")
            indices.append(float(plant.input_names.index(name)))
        return indices

    def build(self, label: str, cfg: Any, plant: Plant, path: str, dt: float | None = None) -> ControllerInstance:
        """The controller for ``plant``: the rows of the module docstring."""
        shape = self.shape
        codes, indices = self.measure_codes(plant, path), self._checked_names(plant, path)
        sample_time = cfg.sample_time
        hold = 1 if sample_time is None or dt is None else check_sample_time(sample_time, dt, path)
        period = 0.0 if sample_time is None else float(sample_time)
        cp = np.array([*codes, *indices, float(hold), period, *self.parameters(cfg, plant, path)], dtype=float)
        cs0 = np.array([0.0, *([0.0] * shape.n_u), *(v for _, v in shape.states), *([0.0] * shape.n_g)])
        return ControllerInstance(
            label=label,
            kind=shape.name,
            step=self.step,
            cp=cp,
            cs0=cs0,
            reference_signals=shape.references,
            log_names=shape.log_names,
            log_units=("",) * len(shape.log_names),
            config=cfg.model_dump(),
            records=self.records(cfg, plant, cp),
            law=self.compiled(),
        )

    def compiled(self) -> LawController:
        """The controller whose compiled law, shape and parameters' type the step runs (this one)."""
        return self

    def records(self, cfg: Any, plant: Plant, cp: np.ndarray) -> dict[str, object]:
        """Values the controller's design produced, for tuning.csv (none for a law as written)."""
        return {}


def law_config(
    shape: LawShape, base: type[ControllerConfig] = ControllerConfig, **extra: object
) -> type[ControllerConfig]:
    """The pydantic model of the law's config section: ``kind``, each parameter (its default,
    unit and description) and ``sample_time`` (its period; None: every integration step)."""
    fields: dict[str, Any] = {  # pydantic.create_model takes its field definitions untyped
        "kind": (Literal[shape.name], Field(shape.name, description="registered name of this controller")),
        **{
            name: (float, Field(default, description=text or None, json_schema_extra={"unit": unit}))
            for name, default, unit, text in shape.params
        },
        "sample_time": (
            float | None,
            Field(
                shape.sample_time,
                gt=0,
                description="period of the law, s; None: every integration step",
                json_schema_extra={"unit": "s"},
            ),
        ),
        **extra,
    }
    model: type[ControllerConfig] = create_model(f"{shape.name}_config", __base__=base, **fields)
    return model


def law_model(
    f: ControlLaw,
    shape: LawShape,
    base: type[LawController] = LawController,
    config: type[ControllerConfig] | None = None,
    doc: str | None = None,
) -> LawController:
    """A :class:`LawController` (subclass ``base``) running ``f`` of ``shape``: compiled,
    checked (:func:`check_law`) and wrapped for the kernel (:func:`batched_step`)."""
    law, params_type = compile_law(f, shape)
    check_law(law, params_type, shape)
    try:
        step = batched_step(law, params_type, shape)
    except Exception as exc:  # pragma: no cover - the law compiled and ran above
        raise _failure(shape.name, exc) from None
    text = doc or (f.__doc__ or f"{shape.name}: a control law written in plain Python").strip().splitlines()[0]
    cls = type(
        f"{shape.name}_controller",
        (base,),
        {
            "__doc__": text,
            "Config": config or law_config(shape),
            "shape": shape,
            "law": staticmethod(law),
            "params_type": params_type,
            "step": staticmethod(step),
            "function": staticmethod(f),
        },
    )
    return cls()


def controller(
    name: str,
    *,
    measures: Sequence[str],
    references: Sequence[str],
    inputs: Sequence[str],
    states: Mapping[str, float] | None = None,
    params: Mapping[str, ParamSpec] | None = None,
    signals: Sequence[str] = (),
    sample_time: float | None = None,
    replace: bool = True,
) -> Callable[[LawT], LawT]:
    """Register a control law written for one variant, ``law(t, dt, y, r, s, p) -> (u, s_next)``.

    ``y``, ``r`` and ``s`` are tuples of floats in the declared orders of ``measures``, ``references``
    and ``states`` (index them: ``y[0]``); ``p`` holds the parameters by name (``p.k1``); ``dt`` is the
    law's period. The law returns a tuple of the inputs it drives, in the order of ``inputs``, and a
    tuple of the next values of its states (with ``signals``, a third tuple of internal signals to
    log). It may use ``math`` and the numpy functions numba compiles. The decorator compiles the law,
    wraps it for the kernel (the rows of the module docstring), calls it once at the zero point with
    the default parameters (a wrong arity, return shape or value is one line naming the controller)
    and registers it in :data:`nlcx.registry.controllers`; the function itself is returned unchanged.

    Parameters
    ----------
    name : str
        The ``kind`` a config's controller section names.
    measures : sequence of str
        The plant signals the law reads, in the order of ``y``: outputs (read after the sensor
        elements) or states (read from the true state: full-state feedback).
    references : sequence of str
        The references the law reads, by signal name, in the order of ``r``.
    inputs : sequence of str
        The plant inputs the law drives, in the order of its first returned tuple.
    states : mapping, optional
        The law's own states and their initial values, in the order of ``s``.
    params : mapping, optional
        ``{name: default}``, ``{name: (default, unit)}`` or ``{name: (default, unit, description)}``;
        a config section sets any of them by name.
    signals : sequence of str
        Internal signals the law returns as a third tuple, logged beside its states.
    sample_time : float, optional
        The law's period, a whole number of integration steps (a config's ``sample_time`` sets
        it too); None: every integration step.
    replace : bool
        Replace a law registered under ``name`` before (a notebook cell run again). A built-in
        controller is never replaced.

    Returns
    -------
    callable
        A decorator that registers the law and returns it.

    Examples
    --------
    State feedback with integral action on the cart's position of the x pendulum (an LQR gain
    of its linear model); the outputs it follows, x and theta, are the ones measured:

    >>> import nlcx
    >>> @nlcx.controller("cart_lqi", measures=["x", "x_dot", "theta", "theta_dot"], references=["x", "theta"],
    ...                  inputs=["F_x"], states={"z": 0.0},
    ...                  params={"k1": -2.694, "k2": -3.129, "k3": -30.50, "k4": -5.160, "ki": -1.0})
    ... def cart_lqi(t, dt, y, r, s, p):
    ...     u = -(p.k1 * (y[0] - r[0]) + p.k2 * y[1] + p.k3 * y[2] + p.k4 * y[3] + p.ki * s[0])
    ...     return (u,), (s[0] + dt * (y[0] - r[0]),)
    >>> result = nlcx.run("configs/x_error_ags.yaml", {"controllers": {"lqi": {"kind": "cart_lqi"}}})
    >>> result.status("lqi"), round(float(result.trajectory("lqi")["x"].iloc[-1]), 3)
    ('ok', 1.0)
    """
    return _registrar(name, shape_of(name, measures, references, inputs, states, params, signals, sample_time), replace)


def _registrar(name: str, shape: LawShape, replace: bool) -> Callable[[LawT], LawT]:
    """The decorator of :func:`controller`: registers a law of ``shape`` under ``name`` (replacing
    a law registered before only if ``replace``) and returns the law."""

    def register(f: LawT) -> LawT:
        existing = registry.controllers.get(name) if name in registry.controllers else None
        if existing is not None and not (replace and isinstance(existing, LawController)):
            allowed = "a new name" + ("" if replace else ", or replace=True")
            raise ConfigError("controller", name, f"already registered ({type(existing).__name__}); allowed: {allowed}")
        registry.controllers.register(name, law_model(f, shape), replace=True)
        return f

    return register

"""The kernel's arguments and work spaces, one named structure per concept.

The engine hands :func:`nlcx.kernel.integrator.simulate` a batch of closed loops as eight
structures and their working storage, and the kernel hands its friction path
(:mod:`nlcx.kernel.friction_path`) its working slots and scratch the same way. Each is a
:class:`typing.NamedTuple`, which numba compiles as a named tuple: a field is read by its name
(``plant.x0``, ``records.U``, ``scratch.rhs_s``) in the compiled code as in Python.

Rows are variants; an axis of length 1 (written ``B|1``) is shared by every variant of the
batch. The structures the engine passes in are:

- :class:`Integration`: the Runge-Kutta method, its tableau and the step;
- :class:`PlantCall`: the plant's right-hand side and arrays;
- :class:`ControllerCall`: the controller's step, callbacks, parameters, state and references;
- :class:`LoopElements`: the loop elements' functions, table, parameters, state and time series;
- :class:`PlantForces`: what enters the plant besides the input (disturbances, friction axes);
- :class:`Records` and :class:`Outcome`: what the kernel writes;
- :class:`FrictionPath`: the two functions that step the variants with friction;
- :class:`Working`: the working storage of the call (slots, signals, stage columns, ...).

Each carries its numba type (``numba_type``), declared by :func:`declare`. numba types such a
value by that declaration when the kernel is called, with a check of each array's dtype,
dimensions and layout, so a call costs a lookup per structure whatever plugins it carries.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, TypeAlias

import numpy as np
from numba import types

from nlcx._numba_compat import register_typeof
from nlcx.kernel.abi import (
    ARR3,
    ARR4,
    F64,
    I64,
    IVEC,
    MAT,
    VEC,
    CallbackTuple,
    ControllerFn,
    ElementTuple,
    FunctionTable,
    RhsFn,
)
from nlcx.kernel.signatures import ControllerStep, FloatArray, RightHandSide

IMAT = types.int64[:, ::1]
BVEC = types.boolean[::1]

#: Integration methods the kernel steps: any explicit tableau, or the classic fourth-order
#: Runge-Kutta method written out (selected by the integrator's name, :func:`method_of`).
ANY_TABLEAU = 0
CLASSIC_RK4 = 1
#: Integrators (``simulation.integrator``) the kernel steps by a method of their own.
WRITTEN_OUT = {"rk4": CLASSIC_RK4}


def method_of(integrator: str) -> int:
    """The kernel's method for the integrator named ``integrator``."""
    return WRITTEN_OUT.get(integrator, ANY_TABLEAU)


def declare(cls: type, **fields: types.Type) -> types.Type:
    """Declare the numba type of the named tuple class ``cls`` from each field's numba type
    (every field, in the class's order), set it as ``cls.numba_type`` and type the class's
    values by it when a compiled function is called (:func:`_typer`). Returns the type."""
    names = tuple(cls._fields)  # type: ignore[attr-defined]  # cls is a NamedTuple class
    if tuple(fields) != names:
        raise TypeError(f"{cls.__name__}: declare the fields {names} in order, got {tuple(fields)}")
    numba_type = types.BaseTuple.from_types(tuple(fields.values()), cls)
    cls.numba_type = numba_type  # type: ignore[attr-defined]  # set here, on the class, once
    _TYPERS[cls] = _typer(cls.__name__, tuple(zip(names, fields.values(), strict=True)), numba_type)
    register_typeof(cls, _TYPERS[cls])
    return numba_type


#: numba's typing of a declared structure: (the structure's value, numba's typing context) -> its type.
Typer: TypeAlias = Callable[[tuple[object, ...], object], types.Type]

#: The typing of each declared structure, by class (a structure's structure fields are typed by theirs).
_TYPERS: dict[type, Typer] = {}


def _typer(name: str, fields: tuple[tuple[str, types.Type], ...], numba_type: types.Type) -> Typer:
    """numba's typing of a structure: its declared type, once every array field holds a
    writeable, aligned, C-contiguous array of the declared dtype and dimensions, every table
    field a :class:`~nlcx.kernel.abi.FunctionTable` of the declared type, every number field a
    number of the declared kind and every structure field a structure typed the same way (a
    function field is checked when numba hands it over: it must compile for its signature)."""
    arrays = tuple(
        (i, f, np.dtype(t.dtype.name), t.ndim) for i, (f, t) in enumerate(fields) if isinstance(t, types.Array)
    )
    tables = tuple((i, f, t) for i, (f, t) in enumerate(fields) if isinstance(t, types.UniTuple))
    numbers = tuple((i, f, float if t == F64 else int) for i, (f, t) in enumerate(fields) if t in (F64, I64))
    nested: tuple[tuple[int, str, type[tuple[object, ...]]], ...] = tuple(
        (i, f, t.instance_class)
        for i, (f, t) in enumerate(fields)
        if isinstance(t, (types.NamedTuple, types.NamedUniTuple))
    )

    def typer(value: tuple[object, ...], context: object) -> types.Type:
        for i, f, dtype, ndim in arrays:
            if not _is_array(value[i], dtype, ndim):
                wanted = f"a writeable C-contiguous {ndim}-d {dtype} array"
                raise TypeError(f"{name}.{f}: {wanted}, got {_described(value[i])}")
        for i, f, table in tables:
            functions = value[i]
            if not (isinstance(functions, FunctionTable) and functions.numba_type == table):
                raise TypeError(f"{name}.{f}: a FunctionTable of {table}, got {type(value[i]).__name__}")
        for i, f, kind in numbers:
            if not isinstance(value[i], kind) or isinstance(value[i], bool):
                raise TypeError(f"{name}.{f}: a {kind.__name__}, got {value[i]!r}")
        for i, f, cls in nested:
            structure = value[i]
            if not isinstance(structure, cls):
                raise TypeError(f"{name}.{f}: a {cls.__name__}, got {type(structure).__name__}")
            _TYPERS[cls](structure, context)
        return numba_type

    return typer


def _is_array(a: object, dtype: np.dtype, ndim: int) -> bool:
    """Whether ``a`` is an array numba may hand over as a writeable C-contiguous array of ``dtype``."""
    if not isinstance(a, np.ndarray) or a.dtype != dtype or a.ndim != ndim:
        return False
    flags = a.flags
    return bool(flags.c_contiguous and flags.writeable and flags.aligned)


def _described(a: object) -> str:
    if isinstance(a, np.ndarray):
        layout = "C-contiguous" if a.flags.c_contiguous else "non-contiguous"
        access = "" if a.flags.writeable else "read-only "
        return f"a {access}{layout} {a.ndim}-d {a.dtype} array"
    return type(a).__name__


# ----------------------------------------------------------------------------- what the engine passes


class Integration(NamedTuple):
    """How the kernel integrates over a sampling step: the method (:data:`CLASSIC_RK4` or
    :data:`ANY_TABLEAU`), the Butcher tableau (rk_a (s, s), rk_b (s,)) and the step dt."""

    method: int
    rk_a: np.ndarray
    rk_b: np.ndarray
    dt: float


class PlantCall(NamedTuple):
    """The plant: its right-hand side (:data:`~nlcx.kernel.abi.RHS_SIG`), initial states
    x0 (B, n), parameters p (B|1, n_p), output matrix C (n_y, n) and bounds (B|1, n):
    |x_i| > bounds[i] stops a run."""

    rhs: RightHandSide
    x0: np.ndarray
    p: np.ndarray
    C: np.ndarray
    bounds: np.ndarray


class ControllerCall(NamedTuple):
    """The controller: its step (:data:`~nlcx.kernel.abi.CONTROLLER_SIG`), its callbacks
    (:func:`~nlcx.kernel.abi.callback_slots`), parameters cp (B, n_cp), initial state
    cs0 (B, n_cs) and references ref (B|1, K+1|1, n_r) at the sampling instants."""

    step: ControllerStep
    callbacks: FunctionTable
    cp: np.ndarray
    cs0: np.ndarray
    ref: np.ndarray


class LoopElements(NamedTuple):
    """The loop elements: their functions (:func:`~nlcx.kernel.abi.element_slots`), the table
    of them in the order they act (n_el, :data:`~nlcx.kernel.abi.ELEMENT_ENTRY`), parameters
    ep (B, n_ep), initial state es0 (B, n_es) and time series data (B|1, K+1|1, n_data)."""

    functions: FunctionTable
    table: np.ndarray
    ep: np.ndarray
    es0: np.ndarray
    data: np.ndarray


class PlantForces(NamedTuple):
    """What drives the plant besides its input: disturbance terms at the stage times dist
    (B|1, K|1, s, n_d) with their map dist_map (n, n_d) (dx += dist_map @ d), and the friction
    of each input's axis, friction (B|1, n_u, FRICTION_AXIS)."""

    dist: np.ndarray
    dist_map: np.ndarray
    friction: np.ndarray


class Records(NamedTuple):
    """What the kernel records, every sample up to where a run stops: states X (B, K+1, n),
    inputs U (B, K+1, n_u), controller logs LOG (B, K+1|1, n_log) and friction forces FRICTION
    (B, K+1|1, n_u); a time axis of length 1: not recorded."""

    X: np.ndarray
    U: np.ndarray
    LOG: np.ndarray
    FRICTION: np.ndarray


class Outcome(NamedTuple):
    """How each run ended: status (B,) (:data:`~nlcx.kernel.abi.STATUS_OK`, ...), n_valid (B,)
    samples recorded and fail_index (B,): i < n state i, n + j input j, -1 none."""

    status: np.ndarray
    n_valid: np.ndarray
    fail_index: np.ndarray


# ----------------------------------------------------------------------------- the kernel's own


class Slots(NamedTuple):
    """The working slots of a batch: what moves with a variant when the batch compacts. Slot b
    holds variant vid[b]; stopped[b]: it left the batch. By columns (the plant's): its state x
    (n, B), parameters p (n_p, B) and bounds (n, B); by rows: the controller's parameters cp,
    state cs and log, the friction axes (B, n_u, FRICTION_AXIS) and each axis's friction mode,
    slip direction and the position a stuck axis holds (B, n_u)."""

    vid: np.ndarray
    stopped: np.ndarray
    x: np.ndarray
    p: np.ndarray
    bounds: np.ndarray
    cp: np.ndarray
    cs: np.ndarray
    log: np.ndarray
    axes: np.ndarray
    mode: np.ndarray
    direction: np.ndarray
    hold: np.ndarray


class OneColumn(NamedTuple):
    """One variant as a batch of one column, as the plant's right-hand side takes it: x, u, p
    and dx, each (., 1)."""

    x: np.ndarray
    u: np.ndarray
    p: np.ndarray
    dx: np.ndarray


class FrictionScratch(NamedTuple):
    """Work space of a step of one variant with friction
    (:func:`nlcx.kernel.friction_path.step_with_friction`), the variant as one column: the stage
    derivatives k_stage (s, n, 1) and a stage's state xs (n, 1) of its Runge-Kutta step, the
    friction forces f, a work input (n_u,), the stuck axes' system A (n_u, n_u) and right-hand
    side rhs_s (n_u,), a derivative dx (n,), a disturbance d_tmp (n_d,) and the variant as a
    batch of one column for its right-hand side."""

    k_stage: np.ndarray
    xs: np.ndarray
    f: np.ndarray
    work: np.ndarray
    A: np.ndarray
    rhs_s: np.ndarray
    dx: np.ndarray
    d_tmp: np.ndarray
    one: OneColumn


class FrictionWork(NamedTuple):
    """Work space of the friction path, allocated once per kernel call: the variant's state
    x, the end of its step x_new, the state where an axis stops x_mid (n, 1), its input u
    (n_u, 1) and the scratch of its step."""

    x: np.ndarray
    x_new: np.ndarray
    x_mid: np.ndarray
    u: np.ndarray
    scratch: FrictionScratch


class Signals(NamedTuple):
    """The signals of a sample, written anew at every sample: by rows, the controller's copy
    of the state xrow (B, n), the outputs y (B, n_y), the references r (B, n_r), the input u
    (B, n_u) and the controller's log (B, n_log, NaN until written; the slots' log); by columns,
    the input held over the step uc (n_u, B) (the plant's)."""

    xrow: np.ndarray
    y: np.ndarray
    r: np.ndarray
    u: np.ndarray
    log: np.ndarray
    uc: np.ndarray


class StageColumns(NamedTuple):
    """Work arrays of a Runge-Kutta step: x_{k+1} and a stage's state xs (n, B), and the stage
    derivatives k (MAX_STAGES, n, B; zero where no right-hand side writes them: the columns of
    variants with friction)."""

    x_new: np.ndarray
    xs: np.ndarray
    k: np.ndarray


class FlatViews(NamedTuple):
    """Flat views (n B,) on the (n, B) arrays of a step: the state x, a stage's state xs, x_{k+1},
    the bounds and the first four stage derivatives. The RK4 sums and the acceptance of x_{k+1}
    are one loop over every column, the inactive ones included (their values are never read
    again): a loop per state costs more than its work in a batch of a few variants."""

    x: np.ndarray
    xs: np.ndarray
    x_new: np.ndarray
    bounds: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray


class Working(NamedTuple):
    """The working storage of a kernel call, built before the call
    (:func:`nlcx.kernel.working_storage.working_storage`): the working slots, of which the first
    n_free hold the variants without friction; the signals of a sample; the stage columns and
    their flat views; the friction path's work space; the stage nodes c (s,) (t_k + c_i dt);
    the output picks (n_y,) (:func:`nlcx.kernel.stepping.output_picks`); the loop elements'
    state es (B, n_es); and the numbers of sensor and actuator elements."""

    slots: Slots
    n_free: int
    signals: Signals
    stages: StageColumns
    flat: FlatViews
    friction: FrictionWork
    c: np.ndarray
    picked: np.ndarray
    es: np.ndarray
    n_sensor: int
    n_actuator: int


#: The friction path at sample k (:class:`FrictionPath`, :data:`FRICTION_SAMPLE_SIG`).
FrictionSample: TypeAlias = Callable[
    [RightHandSide, float, int, int, int, Slots, FloatArray, PlantForces, FrictionWork, Records], None
]
#: The friction path over a step (:class:`FrictionPath`, :data:`FRICTION_STEP_SIG`).
FrictionStep: TypeAlias = Callable[
    [
        RightHandSide,
        float,
        int,
        int,
        int,
        Slots,
        FloatArray,
        FloatArray,
        PlantForces,
        FrictionWork,
        Integration,
        FloatArray,
    ],
    None,
]


class FrictionPath(NamedTuple):
    """The friction path (Appendix A), called through two function values so that a batch
    without friction never compiles it: at sample k, the breakaway of the frictional variants
    ``sample(rhs, t, k, nb, n_free, slots, u, forces, work, records)``; over the step, their
    integration ``step(rhs, t, kd, nb, n_free, slots, x_new, u, forces, work, integration, c)``.
    Working slots n_free..nb-1 are the frictional ones; u by rows."""

    sample: FrictionSample
    step: FrictionStep


IntegrationType = declare(Integration, method=I64, rk_a=MAT, rk_b=VEC, dt=F64)
PlantCallType = declare(PlantCall, rhs=RhsFn, x0=MAT, p=MAT, C=MAT, bounds=MAT)
ControllerCallType = declare(ControllerCall, step=ControllerFn, callbacks=CallbackTuple, cp=MAT, cs0=MAT, ref=ARR3)
LoopElementsType = declare(LoopElements, functions=ElementTuple, table=MAT, ep=MAT, es0=MAT, data=ARR3)
PlantForcesType = declare(PlantForces, dist=ARR4, dist_map=MAT, friction=ARR3)
RecordsType = declare(Records, X=ARR3, U=ARR3, LOG=ARR3, FRICTION=ARR3)
OutcomeType = declare(Outcome, status=IVEC, n_valid=IVEC, fail_index=IVEC)
SlotsType = declare(
    Slots, vid=IVEC, stopped=BVEC, x=MAT, p=MAT, bounds=MAT, cp=MAT, cs=MAT, log=MAT,
    axes=ARR3, mode=IMAT, direction=MAT, hold=MAT,
)  # fmt: skip
OneColumnType = declare(OneColumn, x=MAT, u=MAT, p=MAT, dx=MAT)
FrictionScratchType = declare(
    FrictionScratch, k_stage=ARR3, xs=MAT, f=VEC, work=VEC, A=MAT, rhs_s=VEC, dx=VEC, d_tmp=VEC, one=OneColumnType,
)  # fmt: skip
FrictionWorkType = declare(FrictionWork, x=MAT, x_new=MAT, x_mid=MAT, u=MAT, scratch=FrictionScratchType)
SignalsType = declare(Signals, xrow=MAT, y=MAT, r=MAT, u=MAT, log=MAT, uc=MAT)
StageColumnsType = declare(StageColumns, x_new=MAT, xs=MAT, k=ARR3)
FlatViewsType = declare(FlatViews, x=VEC, xs=VEC, x_new=VEC, bounds=VEC, k1=VEC, k2=VEC, k3=VEC, k4=VEC)
WorkingType = declare(
    Working, slots=SlotsType, n_free=I64, signals=SignalsType, stages=StageColumnsType, flat=FlatViewsType,
    friction=FrictionWorkType, c=VEC, picked=IVEC, es=MAT, n_sensor=I64, n_actuator=I64,
)  # fmt: skip

#: The friction path's two signatures (:class:`FrictionPath`).
FRICTION_SAMPLE_SIG = types.void(
    RhsFn, F64, I64, I64, I64, SlotsType, MAT, PlantForcesType, FrictionWorkType, RecordsType
)
FRICTION_STEP_SIG = types.void(
    RhsFn, F64, I64, I64, I64, SlotsType, MAT, MAT, PlantForcesType, FrictionWorkType, IntegrationType, VEC
)
FrictionPathType = declare(
    FrictionPath, sample=types.FunctionType(FRICTION_SAMPLE_SIG), step=types.FunctionType(FRICTION_STEP_SIG)
)

#: The kernel's signature: ``simulate(integration, plant, controller, elements, forces, records,
#: outcome, friction_path, working)``.
SIMULATE_SIG = types.void(
    IntegrationType, PlantCallType, ControllerCallType, LoopElementsType, PlantForcesType, RecordsType, OutcomeType,
    FrictionPathType, WorkingType,
)  # fmt: skip

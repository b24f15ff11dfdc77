"""What compiled plugins are written against: signatures, hook points, layouts, status codes.

Arrays are contiguous float64. A plant sees the batch the kernel steps in lock step (see
:mod:`nlcx.kernel.integrator`) by columns: column ``b`` of its state, input, parameter and
derivative arrays is variant ``b``, so that its equations, one loop over the columns, run in
vector code. Controllers, callbacks and loop elements see it by rows: row ``b`` of every
2-D array handed to them is variant ``b``.

The signal path of one sampling step t_k, with its hook points::

    x_k --C--> y_k --[SENSOR elements]--> y_k (measured)
        --controller--> u_k --[ACTUATOR elements]--> u_k (applied, held over the step)
        --plant f(t, x, u + friction forces) + derivative terms--> x_{k+1}

``rhs(t, x, u, p, dx, nb)``
    Plant right-hand side: ``dx[:, b] = f(t, x[:, b], u[:, b]; p[:, b])`` for the first ``nb``
    columns: x and dx (n, B), u (n_u, B), p (n_p, B), nb <= B. Columns from nb on are neither
    read nor written (they hold variants that left the batch).
``controller(t, dt, x, y, r, cp, cs, u, log, callbacks)``
    Controller sampled at t, for every row: reads the measured outputs ``y`` (and, for a
    full-information controller, the plant state ``x``) and references ``r``, updates its
    state ``cs`` in place, writes the plant input ``u`` and the values it logs. ``callbacks``
    is the controller's own table of compiled functions (the PID's gain schedules); the
    kernel passes it through untouched.
``callback(t, e, edot, p, row, offset) -> (k_p, k_i, k_d)``
    A controller callback; the PID calls its gain schedule with the parameters stored in
    ``p[row]`` from column ``offset`` on.
``element(t, dt, k, signal, vid, ep, es, data, p_off, s_off, d_off)``
    A loop element acting on the signal at its hook point (``y`` at SENSOR, ``u`` at
    ACTUATOR) for every row ``b``; row ``b`` is variant ``vid[b]``, whose parameters are
    ``ep[vid[b], p_off:]``, whose element state is ``es[vid[b], s_off:]`` and whose time
    series (sample k) is ``data[vid[b] or 0, k or 0, d_off:]`` (a length-1 axis is shared).

Hot-loop rules (they decide the speed, see benchmarks/): no array view is made per step and
per variant (a view handed to a compiled-function value costs a reference-count round
trip); a function that calls a compiled-function value does so inside its loop over the
rows, so its own reference counting is paid once per call, not once per variant; a plant's
loop over its columns reads and writes unit-stride memory only (a strided read, a branch or
numba's integer power ``x**2`` in it keeps the loop scalar; write ``x * x``); and a function
called every step that allocates nothing is compiled with :func:`nlcx._numba_compat.hot_njit`,
without numba's reference counting. A function counts every array it receives on entry and on exit, and
an inlined helper at each of its call sites, which for one or two variants costs more than
the PID step's arithmetic (``benchmarks/components.py`` times it). Such a function may slice
and pass views on, but must not allocate, nor keep an array it did not get (nothing frees it);
``tests/test_hot_loop.py`` holds the built-in plugins to this rule.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from numba import cfunc, njit, types

from nlcx._numba_compat import register_typeof
from nlcx.kernel.signatures import FloatArray, IntArray, NumbaSignature
from nlcx.layout import Layout

F64 = types.float64
VEC = types.float64[::1]
MAT = types.float64[:, ::1]
ARR3 = types.float64[:, :, ::1]
ARR4 = types.float64[:, :, :, ::1]
IVEC = types.int64[::1]
I64 = types.int64

#: Plant right-hand side ``rhs(t, x, u, p, dx, nb)`` over the first nb columns of x.
RHS_SIG = types.void(F64, MAT, MAT, MAT, MAT, I64)
#: Controller callback ``callback(t, e, edot, p, row, offset) -> (k_p, k_i, k_d)``.
CALLBACK_SIG = types.UniTuple(F64, 3)(F64, F64, F64, MAT, I64, I64)
#: Number of callback slots a controller hands the kernel (its callbacks + padding).
CALLBACK_SLOTS = 16
CallbackTuple = types.UniTuple(types.FunctionType(CALLBACK_SIG), CALLBACK_SLOTS)
#: Controller step ``controller(t, dt, x, y, r, cp, cs, u, log, callbacks)`` over the rows.
CONTROLLER_SIG = types.void(F64, F64, MAT, MAT, MAT, MAT, MAT, MAT, MAT, CallbackTuple)
#: Loop element ``element(t, dt, k, signal, vid, ep, es, data, p_off, s_off, d_off)``.
ELEMENT_SIG = types.void(F64, F64, I64, MAT, IVEC, MAT, MAT, ARR3, I64, I64, I64)
#: Number of element slots (distinct element functions in one batch + padding).
ELEMENT_SLOTS = 8
ElementTuple = types.UniTuple(types.FunctionType(ELEMENT_SIG), ELEMENT_SLOTS)

RhsFn = types.FunctionType(RHS_SIG)
ControllerFn = types.FunctionType(CONTROLLER_SIG)

#: Hook points of the signal path where loop elements act.
SENSOR = 0
ACTUATOR = 1
HOOKS = {"sensor": SENSOR, "actuator": ACTUATOR}

#: One row of the element table: hook point, function slot and where the element's
#: parameters, state and time-series columns start.
ELEMENT_ENTRY = Layout("ElementEntry", ("hook", "slot", "param_offset", "state_offset", "data_offset"))

#: Most stages of a Runge-Kutta tableau the kernel integrates with.
MAX_STAGES = 4

#: Run status codes written by the integrator.
STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_BOUND = 2


@njit(cache=True, inline="always", error_model="numpy")
def shared_row(axis_length: int, b: int) -> int:  # pragma: no cover - compiled
    """Index into an axis that is either per-variant (length B) or broadcast (length 1)."""
    return b if axis_length > 1 else 0


class Padding(types.WrapperAddressProtocol):
    """A function slot the kernel never calls: the padding of a table, the friction path of a
    batch without friction.

    numba hands a compiled function value to the kernel by looking up the function's compiled
    overload for the slot's signature, at every call; with a few dozen slots that lookup costs
    more than the work of a short call. A slot that is never called is handed over by numba's
    wrapper address protocol instead: the address of ``function`` compiled as a C callback
    (:func:`numba.cfunc`, disk-cached), read once. Called anyway, it runs ``function``.
    A padding pickles by reference, as the attribute ``name`` of the module ``module``."""

    def __init__(self, signature: NumbaSignature, function: Callable[..., object], module: str, name: str) -> None:
        self._signature = signature
        self._compiled = cfunc(signature, cache=True)(function)
        self._home = (module, name)

    def __wrapper_address__(self) -> int:
        address = self._compiled.address
        assert address is not None  # a cfunc has its address once compiled, here in __init__
        return int(address)

    def signature(self) -> NumbaSignature:
        return self._signature

    def __reduce__(self) -> tuple[Callable[[str, str], Padding], tuple[str, str]]:
        return _padding, self._home

    def __repr__(self) -> str:
        return f"Padding({'.'.join(self._home)})"


def _padding(module: str, name: str) -> Padding:
    """The padding ``name`` of ``module`` (how a :class:`Padding` unpickles)."""
    return getattr(importlib.import_module(module), name)


def _no_callback(
    t: float, e: float, edot: float, p: FloatArray, row: int, offset: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    return 0.0, 0.0, 0.0


def _no_element(
    t: float,
    dt: float,
    k: int,
    signal: FloatArray,
    vid: IntArray,
    ep: FloatArray,
    es: FloatArray,
    data: FloatArray,
    p_off: int,
    s_off: int,
    d_off: int,
) -> None:  # pragma: no cover - compiled
    return


#: Padding of an unused callback slot.
no_callback = Padding(CALLBACK_SIG, _no_callback, __name__, "no_callback")
#: Padding of an unused element slot.
no_element = Padding(ELEMENT_SIG, _no_element, __name__, "no_element")


class FunctionTable(tuple):
    """Compiled functions handed to the kernel as one argument, with the argument's numba type.

    numba types a plain tuple of function values element by element at every call of the
    kernel, a cost paid by every sweep batch and single run; a table is typed by a lookup (the
    ``typeof`` registered below). The type is the one of the kernel's signature, which the
    functions are unboxed as in either case."""

    numba_type: types.Type

    def __new__(cls, functions: tuple[object, ...], numba_type: types.Type) -> FunctionTable:
        table = super().__new__(cls, functions)
        table.numba_type = numba_type
        return table

    def __reduce__(self) -> tuple[object, ...]:
        return FunctionTable, (tuple(self), self.numba_type)


def _typeof_function_table(table: FunctionTable, context: object) -> types.Type:
    return table.numba_type


register_typeof(FunctionTable, _typeof_function_table)


def _padded(
    functions: tuple[object, ...], slots: int, padding: object, numba_type: types.Type, what: str
) -> FunctionTable:
    """``functions`` padded with ``padding`` to ``slots`` entries, as a :class:`FunctionTable`."""
    if len(functions) > slots:
        raise ValueError(f"at most {slots} {what}, got {len(functions)}")
    return FunctionTable(tuple(functions) + (padding,) * (slots - len(functions)), numba_type)


def callback_slots(functions: tuple[object, ...] = ()) -> FunctionTable:
    """A controller's callbacks padded to :data:`CALLBACK_SLOTS` (a table that already is one,
    as the PID's, unchanged)."""
    if isinstance(functions, FunctionTable) and functions.numba_type is CallbackTuple:
        return functions
    return _padded(functions, CALLBACK_SLOTS, no_callback, CallbackTuple, "controller callbacks")


def element_slots(functions: tuple[object, ...] = ()) -> FunctionTable:
    """The element functions of a batch padded to :data:`ELEMENT_SLOTS`."""
    return _padded(functions, ELEMENT_SLOTS, no_element, ElementTuple, "distinct loop element functions in one run")

"""The types of the compiled seams: the arrays the kernels pass and the compiled functions' signatures.

numba compiles from the values a function is called with and ignores annotations; these aliases
tell the type checker and the reader what a compiled function takes and returns. Each callable
alias is the Python form of one numba signature of :mod:`nlcx.kernel.abi` (or of a metric or
friction kernel); a plugin's compiled function has the alias of its kind.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from numba.core.types import Type
    from numba.cuda.dispatcher import CUDADispatcher

    from nlcx._numba_compat import DeviceNDArray, Dispatcher, Signature

#: An array of float64, the dtype of every state, signal, parameter and record.
FloatArray: TypeAlias = NDArray[np.float64]
#: An array of int64: variant indices, statuses, friction modes, index maps.
IntArray: TypeAlias = NDArray[np.int64]
#: An array of booleans: which working slots stopped.
BoolArray: TypeAlias = NDArray[np.bool_]

#: A gain schedule, :data:`~nlcx.kernel.abi.CALLBACK_SIG`: (t, e, de/dt, p, row, offset) -> (k_p, k_i, k_d).
GainSchedule: TypeAlias = Callable[[float, float, float, FloatArray, int, int], tuple[float, float, float]]
#: The controller's table of gain schedules (:data:`~nlcx.kernel.abi.CallbackTuple`).
Callbacks: TypeAlias = tuple[GainSchedule, ...]
#: A plant's right-hand side, :data:`~nlcx.kernel.abi.RHS_SIG`: (t, x, u, p, dx, nb), states by
#: columns; writes dx of the first nb columns.
RightHandSide: TypeAlias = Callable[[float, FloatArray, FloatArray, FloatArray, FloatArray, int], None]
#: A plant's equations for one variant's 1-D vectors: (t, x, u, p, dx); writes dx.
VariantEquations: TypeAlias = Callable[[float, FloatArray, FloatArray, FloatArray, FloatArray], None]
#: A controller step, :data:`~nlcx.kernel.abi.CONTROLLER_SIG`: (t, dt, x, y, r, cp, cs, u, log,
#: callbacks) over the rows of the active variants; writes u, cs and log.
ControllerStep: TypeAlias = Callable[
    [float, float, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, Callbacks], None
]
#: A loop element, :data:`~nlcx.kernel.abi.ELEMENT_SIG`: (t, dt, k, signal, vid, ep, es, data,
#: p_off, s_off, d_off); acts on ``signal`` in place.
LoopElement: TypeAlias = Callable[
    [float, float, int, FloatArray, IntArray, FloatArray, FloatArray, FloatArray, int, int, int], None
]
#: The loop elements' function table (:data:`~nlcx.kernel.abi.ElementTuple`).
ElementFunctions: TypeAlias = tuple[LoopElement, ...]
#: A control law of :func:`nlcx.controller` for one variant: (t, dt, y, r, s, p) -> (u, s_next[, signals]).
ControlLaw: TypeAlias = Callable[..., tuple[tuple[float, ...], ...]]
#: The sums of a metric's terms (:func:`nlcx.metrics.sums.pairwise_sums`): three floats.
Sums: TypeAlias = tuple[float, float, float]

# numba ships no type information: the checker sees its classes below as opaque, and these names
# say which of them a value is.

#: A function numba compiles for the CPU (a dispatcher; its Python source is ``py_func``).
NumbaFunction: TypeAlias = "Dispatcher"
#: A numba type: the type of an argument, of a structure, of a table of functions.
NumbaType: TypeAlias = "Type"
#: A numba signature (``types.void(...)``): what a compiled function takes and returns.
NumbaSignature: TypeAlias = "Signature"
#: A function numba-cuda compiles for the GPU: a device function, or a kernel launched as
#: ``kernel[blocks, threads](*args)``.
DeviceFunction: TypeAlias = "CUDADispatcher"
#: An array in the GPU's memory (``copy_to_host`` copies it back).
DeviceArray: TypeAlias = "DeviceNDArray"

"""The GPU target: numba-cuda, and nlcx's compiled plugins compiled for it from their own source.

A plant, controller, gain schedule or loop element is written once, as a numba function
(:mod:`nlcx.kernel.abi`). For the GPU, :class:`Retarget` compiles the same Python function as
a CUDA device function (``numba.cuda.jit(device=True)``): its ``py_func`` with every numba
function it calls, through its globals or its closure, retargeted the same way. Nothing of a
plugin is written a second time. A function may also be replaced for the GPU by name of its
CPU form (``overrides``): the one place the PID does so is its call of a registered schedule
through the callback table (:func:`nlcx.controllers.pid_step.via_slot`), which the GPU, which
has no function values, makes as a branch over the schedules in use.

numba-cuda is an optional dependency (``pip install 'nlcx[cuda]'``, with CUDA 13's NVVM
compiler; ``'nlcx[cuda12]'`` for CUDA 12 drivers). :func:`cuda` imports it and checks that a
GPU and NVVM are there (or numba's simulator, ``NUMBA_ENABLE_CUDASIM=1``), with a one-line
:class:`~nlcx.errors.ConfigError` otherwise.

Floating point: the GPU code is compiled without fused multiply-add contraction (numba-cuda
contracts by default; :func:`nlcx._numba_compat.cuda_without_fma`), so every addition and
multiplication rounds as on the CPU. sin, cos and exp that nlcx does not compute itself come
from CUDA's libdevice, which may differ from the CPU's libm in the last bit
(docs/guide/gpu.md says where that shows).
"""

from __future__ import annotations

import functools
import os
import re
import sys
import types as pytypes
from collections.abc import Mapping
from pathlib import Path
from typing import Protocol

from nlcx._numba_compat import is_numba_function, load_nvvm
from nlcx.errors import ConfigError
from nlcx.kernel.signatures import DeviceFunction, NumbaFunction

#: The devices a closed loop runs on (``simulation.device``, ``--device``).
DEVICES = ("cpu", "cuda")
#: Where compiled GPU kernels are kept between processes (:func:`kept`); removed with numba's
#: cache of the package when nlcx's source changes (:mod:`nlcx.compiled_cache`).
KERNEL_DIR = Path(__file__).resolve().parent.parent / "__pycache__" / "cuda-kernels"


def refused(why: str) -> ConfigError:
    """The one-line error of a closed loop that cannot run on the GPU, saying why."""
    return ConfigError("simulation.device", "cuda", why)


def simulator_enabled() -> bool:
    """Whether numba-cuda runs on its simulator (``NUMBA_ENABLE_CUDASIM=1``): the GPU code as
    plain Python on the CPU, for tests."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


@functools.cache
def cuda() -> pytypes.ModuleType:
    """numba's CUDA module, once a GPU (or the simulator) is there; a one-line ConfigError otherwise."""
    from nlcx import runtime

    runtime.gpu_shims()
    try:
        from numba import cuda as numba_cuda
    except ImportError as exc:  # pragma: no cover - numba without its CUDA module
        raise refused(f"needs numba-cuda ({exc}); install it with pip install 'nlcx[cuda]'") from None
    try:
        import numba_cuda as _  # type: ignore[import-untyped]  # noqa: F401  # the maintained CUDA target
    except ImportError:
        raise refused("needs numba-cuda; install it with pip install 'nlcx[cuda]'") from None
    if not simulator_enabled():
        try:
            available = bool(numba_cuda.is_available())
        except Exception as exc:  # the driver's own words make the one line
            raise refused(f"no usable GPU here ({exc})".splitlines()[0] + "; allowed here: cpu") from None
        if not available:
            raise refused("no CUDA GPU is available here; allowed here: cpu")
        _check_nvvm()
        runtime.gpu_compiler()
    return numba_cuda


def _check_nvvm() -> None:
    """NVVM, CUDA's compiler of the kernels, loads; a one-line ConfigError otherwise."""
    try:
        load_nvvm()
    except Exception as exc:  # numba-cuda's own words make the line
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise refused(
            f"CUDA's NVVM compiler was not found ({why}); install it with pip install 'nlcx[cuda]' (CUDA 13 "
            "drivers) or 'nlcx[cuda12]' (CUDA 12)"
        ) from None


def device_name() -> str:
    """The name of the GPU the closed loops run on ("simulator" under ``NUMBA_ENABLE_CUDASIM``)."""
    gpu = cuda()
    if simulator_enabled():
        return "numba-cuda simulator"
    name = gpu.get_current_device().name
    return name.decode() if isinstance(name, bytes) else str(name)


def _names(code: pytypes.CodeType) -> set[str]:
    """The global names ``code`` and the code objects nested in it read."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, pytypes.CodeType):
            names |= _names(const)
    return names


class Retarget:
    """CUDA device functions compiled from numba functions' source (see the module docstring).

    ``overrides`` maps a numba function to the device function that stands for it on the GPU.
    Each function is compiled once per :class:`Retarget`.

    Examples
    --------
    >>> import os
    >>> os.environ["NUMBA_ENABLE_CUDASIM"] = "1"  # doctest: +SKIP
    >>> from nlcx.plants.generated.pendulums import x_derived_rhs
    >>> rhs = Retarget().device(x_derived_rhs)  # doctest: +SKIP
    """

    def __init__(self, overrides: Mapping[object, DeviceFunction] | None = None) -> None:
        self._done: dict[object, DeviceFunction] = dict(overrides or {})

    def stand_in(self, function: object, device: DeviceFunction) -> None:
        """Let ``device`` stand for ``function`` in whatever is compiled from here on (an
        override made with device functions this :class:`Retarget` compiled)."""
        self._done[function] = device

    def device(self, function: object) -> DeviceFunction:
        """The device function compiled from ``function`` (a numba function; anything else is a
        TypeError) for the GPU."""
        if function in self._done:
            return self._done[function]
        if not is_numba_function(function):
            raise TypeError(f"{function!r} is not a numba function, so it has no source to compile for the GPU")
        py = function.py_func
        scope = dict(py.__globals__)
        for name in _names(py.__code__):
            if is_numba_function(scope.get(name)):
                scope[name] = self.device(scope[name])
        closure = py.__closure__
        if closure is not None:
            closure = tuple(self._cell(cell) for cell in closure)
        source = pytypes.FunctionType(py.__code__, scope, py.__name__, py.__defaults__, closure)
        source.__qualname__, source.__module__, source.__doc__ = py.__qualname__, py.__module__, py.__doc__
        compiled = cuda().jit(device=True)(source)
        self._done[function] = compiled
        return compiled

    def _cell(self, cell: pytypes.CellType) -> pytypes.CellType:
        value = cell.cell_contents
        return pytypes.CellType(self.device(value)) if is_numba_function(value) else cell


class Digest(Protocol):
    """What :func:`source_key` feeds: a :mod:`hashlib` hash."""

    def update(self, data: bytes, /) -> None: ...


def _code_digest(code: pytypes.CodeType, digest: Digest) -> None:
    """Feed ``code`` (its bytecode, names and constants, nested code objects too) to ``digest``."""
    digest.update(code.co_code)
    digest.update(repr((code.co_names, code.co_varnames, code.co_freevars)).encode())
    for const in code.co_consts:
        if isinstance(const, pytypes.CodeType):
            _code_digest(const, digest)
        else:
            digest.update(repr(const).encode())


def _value_digest(value: object, digest: Digest, seen: set[int]) -> None:
    """Feed a global or closure value a compiled function reads to ``digest``: a numba or plain
    function by its source graph, a module by its name, anything else by its ``repr``."""
    if is_numba_function(value):
        value = value.py_func
    while callable(value) and hasattr(value, "__wrapped__"):  # functools.cache and wraps
        value = value.__wrapped__
    if isinstance(value, pytypes.FunctionType):
        if id(value) in seen:
            return
        seen.add(id(value))
        digest.update(f"{value.__module__}.{value.__qualname__}".encode())
        _code_digest(value.__code__, digest)
        for name in sorted(_names(value.__code__)):
            if name in value.__globals__:
                digest.update(name.encode())
                _value_digest(value.__globals__[name], digest, seen)
        for cell in value.__closure__ or ():
            _value_digest(cell.cell_contents, digest, seen)
    elif isinstance(value, pytypes.ModuleType):
        digest.update(value.__name__.encode())
    elif isinstance(value, tuple | list):
        digest.update(f"{type(value).__name__}[{len(value)}]".encode())
        for item in value:
            _value_digest(item, digest, seen)
    elif isinstance(value, dict):
        digest.update(f"dict[{len(value)}]".encode())
        for key in sorted(value, key=repr):
            digest.update(repr(key).encode())
            _value_digest(value[key], digest, seen)
    else:  # an object's address is not part of what it is
        digest.update(re.sub(r" at 0x[0-9a-fA-F]+", "", repr(value)).encode())


def source_key(*parts: object) -> str:
    """A key of compiled GPU code that is the same in every process and changes with its source:
    the numba-cuda version, and each part (a numba or plain function by its code and every
    function it calls, a constant by its ``repr``)."""
    import hashlib
    from importlib.metadata import version

    versions = (version("numba-cuda"), sys.version_info[:2])
    digest = hashlib.sha256(repr(versions).encode())
    seen: set[int] = set()
    for part in parts:
        _value_digest(part, digest, seen)
    return digest.hexdigest()


def kept(kernel: DeviceFunction, *parts: object) -> DeviceFunction:
    """``kernel`` (a numba-cuda kernel built at run time) with its compiled forms kept on disk
    between processes under :func:`source_key` of ``parts`` (the GPU's name in the key too);
    the simulator compiles nothing, and keeps nothing."""
    if simulator_enabled():
        return kernel
    from nlcx._numba_compat import keep_compiled_kernels

    keep_compiled_kernels(kernel, KERNEL_DIR, source_key(device_name(), *parts))
    return kernel


def device_function(
    function: NumbaFunction, overrides: Mapping[object, DeviceFunction] | None = None
) -> DeviceFunction:
    """The CUDA device function compiled from the numba function ``function`` (:class:`Retarget`)."""
    return Retarget(overrides).device(function)

"""Compiling ahead: the kernel loaded (or compiled) on demand, and what a run needs besides it
compiled in a second process meanwhile."""

from __future__ import annotations

import numpy as np

from nlcx._numba_compat import is_numba_function
from nlcx.config import Experiment
from nlcx.engine.batching import group_key, groups_of, kernel_calls
from nlcx.engine.measure import measure_experiments
from nlcx.engine.pipeline import prepare
from nlcx.engine.prepared import items_of
from nlcx.engine.results import Run
from nlcx.kernel.abi import CALLBACK_SIG, CONTROLLER_SIG, ELEMENT_SIG


def load_kernel() -> None:
    """Load the kernel (:func:`nlcx.kernel.integrator.simulate`) from numba's disk cache, or
    compile it (seconds; loading from a warm cache is quick). Importing the engine does not: a process
    that only prepares and measures (:func:`prewarm`) never needs it."""
    from nlcx.kernel import integrator  # noqa: F401


def prewarm(exp: Experiment) -> None:
    """Compile into numba's disk cache (or load from it) what :func:`~nlcx.engine.evaluate` of ``exp`` needs
    besides the kernel and the plant's right-hand side, each function as the run compiles it,
    and nothing the run does not call:

    - the controllers' modules, which compile their general steps and the built-in gain
      schedules when they are imported (preparing the experiment imports them);
    - the controller step each kernel call runs (:func:`nlcx.engine.batching.kernel_calls`: the
      step made for a loop structure, or the general step that serves a call of several),
      its callbacks and its loop elements, for the kernel's signatures, as the kernel looks
      them up when it is called (``get_compile_result``, which keys numba's cache as the
      kernel's call does);
    - the metric functions, run on zero trajectories of the run's shapes.

    ``nlcx run`` starts this in a second process when loading the kernel takes long (an empty
    or stale cache), so that the two compile side by side; the run compiles the right-hand side
    itself once the kernel is done (:func:`nlcx.plants.base.check_rows`, before the first
    kernel call), which keeps the two processes' shares of the work about even, and waits for
    this one before it measures (:func:`nlcx.compiled_cache.wait_for_helpers`), then loads what
    it compiled from the cache (:class:`nlcx.compiled_cache.CompileHelper`). Nothing is
    simulated, so an experiment with tuners, which simulate while preparing, is left alone."""
    if any(c.tuners for c in exp.controllers):
        return
    prepared = prepare(exp)
    items = items_of(prepared)
    for call in kernel_calls(groups_of([group_key(item) for item in items]), items):
        first = items[call.indices[0]]
        for function, signature in (
            (call.step, CONTROLLER_SIG),
            *((f, CALLBACK_SIG) for f in first.controller.callbacks),
            *((e.function, ELEMENT_SIG) for e in first.elements),
        ):
            if is_numba_function(function):  # not a padding (compiled on import)
                function.get_compile_result(signature)
    n_k = prepared.grid.t.size
    runs = []
    for item in items:
        c, plant = item.controller, item.plant
        runs.append(Run(controller=c, status="ok", reason="", t=prepared.grid.t, x=np.zeros((n_k, len(plant.states))),
                        u=np.zeros((n_k, len(plant.inputs))), r=item.ref, log=np.zeros((n_k, len(c.log_names))),
                        friction=np.zeros((n_k, len(plant.inputs)))))  # fmt: skip
    measure_experiments([prepared], [runs])

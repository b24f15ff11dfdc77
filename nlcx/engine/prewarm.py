"""Compiling ahead: the kernel loaded (or compiled) on demand, and what a run needs besides it
compiled in a second process meanwhile."""

from __future__ import annotations

import numpy as np

from nlcx.config import Experiment
from nlcx.engine.measure import measure_experiments
from nlcx.engine.pipeline import prepare
from nlcx.engine.prepared import items_of
from nlcx.engine.results import Run
from nlcx.kernel.abi import CALLBACK_SIG, CONTROLLER_SIG, ELEMENT_SIG, RHS_SIG, Padding


def load_kernel() -> None:
    """Load the kernel (:func:`nlcx.kernel.integrator.simulate`) from numba's disk cache, or
    compile it (seconds; loading from a warm cache is quick). Importing the engine does not: a process
    that only prepares and measures (:func:`prewarm`) never needs it."""
    from nlcx.kernel import integrator  # noqa: F401


def prewarm(exp: Experiment) -> None:
    """Compile into numba's disk cache (or load from it) what :func:`~nlcx.engine.evaluate` of ``exp`` needs
    besides the kernel: the functions of its plant, controllers and loop elements for the
    kernel's signatures, and the metric functions, run on zero trajectories of the right shapes.

    ``nlcx run`` starts this in a second process when loading the kernel takes long (an empty
    or stale cache), so that the two compile side by side and the run then loads these from the
    cache (:class:`nlcx.compiled_cache.CompileHelper`). Nothing is simulated, so an experiment
    with tuners, which simulate while preparing, is left alone."""
    if any(c.tuners for c in exp.controllers):
        return
    prepared = prepare(exp)
    n_k = prepared.grid.t.size
    runs = []
    for item in items_of(prepared):
        c, plant = item.controller, item.plant
        for function, signature in (
            (plant.rhs, RHS_SIG),
            (c.step, CONTROLLER_SIG),
            *((f, CALLBACK_SIG) for f in c.callbacks),
            *((e.function, ELEMENT_SIG) for e in item.elements),
        ):
            # a padding is compiled on import, as is a function declared with its signature
            if not isinstance(function, Padding) and not function.signatures:
                function.compile(signature)
        runs.append(Run(controller=c, status="ok", reason="", t=prepared.grid.t, x=np.zeros((n_k, len(plant.states))),
                        u=np.zeros((n_k, len(plant.inputs))), r=item.ref, log=np.zeros((n_k, len(c.log_names))),
                        friction=np.zeros((n_k, len(plant.inputs)))))  # fmt: skip
    measure_experiments([prepared], [runs])

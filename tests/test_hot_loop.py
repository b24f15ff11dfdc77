"""The kernel's per-step calls follow the hot-loop rule of nlcx.kernel.abi: a built-in plant
right-hand side, controller step, gain schedule or loop element that allocates nothing is
compiled without numba's reference counting (``nlcx._numba_compat.hot_njit``).

Counting every array a function receives, on entry and on exit, costs the PID step more
than its arithmetic for one or two variants; a function that loses the option
still computes the same bits (the other tests), only slower, so this is where it shows."""

from __future__ import annotations

import inspect
from typing import Any

import pytest

from nlcx import registry
from nlcx.plants.pendulum import PendulumModel
from nlcx.uncertainty import actuator_lag, actuator_saturation, noise

#: The loop elements' functions (their models attach them when they apply).
ELEMENTS = [actuator_lag.first_order_lag, actuator_saturation.saturate_inputs, noise.add_samples]


def _counts_references(function: Any) -> bool:
    return function.targetoptions.get("_nrt", True) is not False


def _per_step_functions() -> list[tuple[str, Any]]:
    found = [(f"controller {n}", registry.controllers.get(n).step) for n in registry.controllers.names()]
    found += [(f"schedule {n}", registry.schedules.get(n).gains) for n in registry.schedules.names()]
    found += [(f"plant {n}", registry.plants.get(n).rhs) for n in registry.plants.names()]
    found += [(f"element {f.__name__}", f) for f in ELEMENTS]
    return found


@pytest.mark.parametrize(("name", "function"), _per_step_functions())
def test_per_step_function_compiled_without_reference_counting(name: str, function: Any) -> None:
    assert not _counts_references(function), name


def test_the_printed_pendulum_equations_are_the_exception() -> None:
    """Written for one variant's vectors, they copy a column into scratch vectors they
    allocate (``by_variant``), so they keep the reference counting; the x pendulum's printed
    equations take the batch by columns and follow the rule."""
    models = {n: registry.plants.get(n) for n in registry.plants.names()}
    pendulums = {n: m.printed_rhs for n, m in models.items() if isinstance(m, PendulumModel)}
    assert not _counts_references(pendulums.pop("x_pendulum"))
    assert pendulums and all(_counts_references(f) for f in pendulums.values())
    assert all("by_variant" in inspect.getsource(f.py_func) for f in pendulums.values())

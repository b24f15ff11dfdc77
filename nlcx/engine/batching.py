"""Which closed loops go through the kernel together.

Items that share their compiled functions and array shapes (:func:`group_key`) go through one
batched kernel call; :func:`kernel_calls` decides which controller step each call runs.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import NamedTuple, cast

from nlcx.engine.prepared import Item
from nlcx.kernel.signatures import ControllerStep

#: Rows a loop structure needs for a kernel call of its own (see :func:`kernel_calls`).
MIN_ROWS_PER_STEP = 8


class KernelCall(NamedTuple):
    """One call of the kernel: the items it simulates (their positions) and the controller step it runs."""

    indices: list[int]
    step: ControllerStep


def group_key(item: Item) -> tuple[Hashable, ...]:
    """What items simulated in one kernel call share: their compiled functions (the controller's
    general step where it has one), state, input, log and reference sizes, output matrix,
    disturbance map and loop elements."""
    c, plant = item.controller, item.plant
    elements = tuple((e.hook, id(e.function), e.params.size, e.state.size) for e in item.elements)
    data_width = 0 if item.element_data is None else item.element_data.shape[1]
    return (
        id(plant.rhs), id(c.step if c.general_step is None else c.general_step), tuple(id(f) for f in c.callbacks),
        len(plant.states), len(plant.inputs),
        plant.C.tobytes(), len(c.log_names), item.ref.shape, item.dist.shape, item.dist_map.tobytes(),
        elements, data_width,
    )  # fmt: skip


def groups_of(group_keys: list[tuple[Hashable, ...]]) -> list[list[int]]:
    """The items grouped by their key (:func:`group_key`), in order."""
    groups: dict[tuple[Hashable, ...], list[int]] = {}
    for i, key in enumerate(group_keys):
        groups.setdefault(key, []).append(i)
    return list(groups.values())


def kernel_calls(groups: list[list[int]], items: list[Item], copies: int = 1) -> list[KernelCall]:
    """The kernel calls of the groups. A group of items whose controllers share their kind but
    not their step (PIDs of different loop structures, each running the step compiled for its
    own, ``pid.step_for``) is split into a call per step when every step has at least
    :data:`MIN_ROWS_PER_STEP` rows, and is otherwise one call of the kind's general step (the
    same arithmetic, so the same bits): a call's cost per time step, shared by its rows,
    outweighs the faster step for one or two rows (``nlcx run`` of a conventional PID against an
    AGS PID is faster as one call). ``copies``: how many times each call's rows are simulated
    (the variants of an ensemble, :func:`nlcx.engine.ensembles.ensemble_calls`), which counts
    toward the rows of a step."""
    calls: list[KernelCall] = []
    for indices in groups:
        by_step: dict[int, list[int]] = {}
        for i in indices:
            by_step.setdefault(id(items[i].controller.step), []).append(i)
        if len(by_step) == 1 or all(copies * len(rows) >= MIN_ROWS_PER_STEP for rows in by_step.values()):
            calls += [KernelCall(rows, items[rows[0]].controller.step) for rows in by_step.values()]
        else:
            # steps differ within a group only where its controllers have a general step (group_key)
            calls.append(KernelCall(indices, cast(ControllerStep, items[indices[0]].controller.general_step)))
    return calls

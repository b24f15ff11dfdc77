"""Which closed loops go through the kernel together, and which are simulated only once.

Items that share their compiled functions and array shapes (:func:`group_key`) go through one
batched kernel call; an item whose closed loop equals an earlier one's bit for bit
(:func:`first_of_same_loop`) is not simulated again but shares that one's trajectory
(:func:`with_repeats`); :func:`kernel_calls` decides which controller step each call runs.
"""

from __future__ import annotations

import dataclasses
import hashlib
from typing import Any, NamedTuple

import numpy as np

from nlcx.engine.prepared import Item
from nlcx.engine.results import Run

#: Rows a loop structure needs for a kernel call of its own (see :func:`kernel_calls`).
MIN_ROWS_PER_STEP = 8


class KernelCall(NamedTuple):
    """One call of the kernel: the items it simulates (their positions) and the controller step it runs."""

    indices: list[int]
    step: Any


def group_key(item: Item) -> tuple[Any, ...]:
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


def kernel_arrays(item: Item) -> tuple[np.ndarray | None, ...]:
    """Every array of an item the kernel reads (its functions are in :func:`group_key`)."""
    c, plant = item.controller, item.plant
    elements = (a for e in item.elements for a in (e.params, e.state, e.data))
    return (plant.x0, plant.p, plant.bounds, c.cp, c.cs0, item.ref, item.dist, item.element_data, item.friction,
            *elements)  # fmt: skip


def first_of_same_loop(items: list[Item], group_keys: list[tuple[Any, ...]]) -> list[int]:
    """``first[i]``: the first item whose closed loop is item i's (the same compiled functions,
    ``group_keys[i]``, and, bit for bit, the same arrays). The kernel's result for a variant
    does not depend on the batch around it, so such a loop is simulated once (an identification
    study's candidates share their proposed controller, a reproduction's figures their
    conventional runs). Arrays are compared by a SHA-1 of their bytes, each array object hashed once."""
    hashed: list[np.ndarray] = []  # kept while hashing, so that an array's id stays its own
    digests: dict[int, tuple[Any, ...]] = {}

    def digest(a: np.ndarray | None) -> tuple[Any, ...] | None:
        if a is None:
            return None
        if id(a) not in digests:
            hashed.append(a)
            data = np.ascontiguousarray(a)
            digests[id(a)] = (a.shape, a.dtype.str, hashlib.sha1(data.data, usedforsecurity=False).digest())
        return digests[id(a)]

    first: dict[tuple[Any, ...], int] = {}
    return [
        first.setdefault((key, tuple(item.controller.log_names), *map(digest, kernel_arrays(item))), i)
        for i, (item, key) in enumerate(zip(items, group_keys, strict=True))
    ]


def distinct_groups(group_keys: list[tuple[Any, ...]], first: list[int]) -> list[list[int]]:
    """The items to simulate (each first of its loop, ``first``) grouped by their key, in order."""
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i, key in enumerate(group_keys):
        if first[i] == i:
            groups.setdefault(key, []).append(i)
    return list(groups.values())


def kernel_calls(groups: list[list[int]], items: list[Item]) -> list[KernelCall]:
    """The kernel calls of the groups. A group of items whose controllers share their kind but
    not their step (PIDs of different loop structures, each running the step compiled for its
    own, ``pid.step_for``) is split into a call per step when every step has at least
    :data:`MIN_ROWS_PER_STEP` rows, and is otherwise one call of the kind's general step (the
    same arithmetic, so the same bits): a call's cost per time step, shared by its rows,
    outweighs the faster step for one or two rows (``nlcx run`` of a conventional PID against an
    AGS PID is faster as one call)."""
    calls: list[KernelCall] = []
    for indices in groups:
        by_step: dict[int, list[int]] = {}
        for i in indices:
            by_step.setdefault(id(items[i].controller.step), []).append(i)
        if len(by_step) == 1 or all(len(rows) >= MIN_ROWS_PER_STEP for rows in by_step.values()):
            calls += [KernelCall(rows, items[rows[0]].controller.step) for rows in by_step.values()]
        else:
            calls.append(KernelCall(indices, items[indices[0]].controller.general_step))
    return calls


def with_repeats(runs: list[Run | None], items: list[Item], first: list[int]) -> list[Run]:
    """Every item's run: an item repeating the loop of item ``first[i]`` gets that run's
    trajectory under its own controller (label) and reference."""
    out = []
    for i, j in enumerate(first):
        source = runs[j]
        assert source is not None
        out.append(
            source
            if j == i
            else dataclasses.replace(source, controller=items[i].controller, r=items[i].ref[: source.t.size])
        )
    return out

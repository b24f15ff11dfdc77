"""The working storage of a kernel call, built in numpy before the call.

:func:`nlcx.kernel.working_storage.working_storage` puts the variants without friction in the
first working slots, copies each variant's arrays (a shared row to every slot), leaves the
engine's arrays alone, and hands the kernel flat views that are the very memory of its (n, B)
arrays; the stage nodes and output picks are those of their definitions.
"""

from __future__ import annotations

import numpy as np

from nlcx.kernel.abi import ACTUATOR, ELEMENT_ENTRY, MAX_STAGES, SENSOR, STATUS_OK
from nlcx.kernel.friction import FA, FRICTION_AXIS
from nlcx.kernel.stepping import output_picks, stage_nodes
from nlcx.kernel.structures import (
    ControllerCall,
    Integration,
    LoopElements,
    Outcome,
    PlantCall,
    PlantForces,
    Records,
)
from nlcx.kernel.working_storage import working_storage

N_BATCH, N, N_U, N_P, N_STEPS = 4, 3, 2, 5, 6


def _call(frictional: tuple[int, ...]) -> tuple[PlantCall, ControllerCall, LoopElements, PlantForces, Records, Outcome]:
    """A kernel call's structures (no functions: the storage does not call them), variants
    ``frictional`` with a friction model on their second input's axis."""
    rng = np.random.default_rng(3)
    plant = PlantCall(
        rhs=None, x0=rng.normal(size=(N_BATCH, N)), p=rng.normal(size=(1, N_P)),  # type: ignore[arg-type]
        C=np.array([[1.0, 0.0, 0.0], [0.0, 0.5, 0.5]]), bounds=rng.uniform(1, 2, size=(N_BATCH, N)),
    )  # fmt: skip
    controller = ControllerCall(
        step=None, callbacks=None, cp=rng.normal(size=(N_BATCH, 7)),  # type: ignore[arg-type]
        cs0=rng.normal(size=(N_BATCH, 2)), ref=np.zeros((1, N_STEPS + 1, 2)),
    )  # fmt: skip
    table = np.zeros((3, ELEMENT_ENTRY.size))
    table[:, ELEMENT_ENTRY.at.hook] = (SENSOR, ACTUATOR, SENSOR)
    elements = LoopElements(
        functions=None, table=table, ep=np.zeros((N_BATCH, 0)),  # type: ignore[arg-type]
        es0=rng.normal(size=(N_BATCH, 4)), data=np.zeros((1, 1, 0)),
    )  # fmt: skip
    friction = np.zeros((N_BATCH, N_U, FRICTION_AXIS.size))
    for v in frictional:
        friction[v, 1, FA.model] = 1.0
    forces = PlantForces(dist=np.zeros((1, 1, 4, 1)), dist_map=np.zeros((N, 1)), friction=friction)
    records = Records(
        X=np.empty((N_BATCH, N_STEPS + 1, N)), U=np.empty((N_BATCH, N_STEPS + 1, N_U)),
        LOG=np.empty((N_BATCH, N_STEPS + 1, 3)), FRICTION=np.empty((N_BATCH, 1, N_U)),
    )  # fmt: skip
    outcome = Outcome(*(np.full(N_BATCH, 99, dtype=np.int64) for _ in range(3)))
    return plant, controller, elements, forces, records, outcome


def test_the_variants_without_friction_lead_and_every_slot_holds_a_copy_of_its_variant() -> None:
    plant, controller, elements, forces, records, outcome = _call(frictional=(0, 2))
    before = [a.copy() for a in (plant.x0, plant.p, plant.bounds, controller.cp, controller.cs0, elements.es0)]
    tableau = np.array([[0.0, 0.0], [1.0, 0.0]])
    integration = Integration(method=0, rk_a=tableau, rk_b=np.array([0.5, 0.5]), dt=0.1)
    w = working_storage(integration, plant, controller, elements, forces, records, outcome)
    slots = w.slots
    assert slots.vid.tolist() == [1, 3, 0, 2] and w.n_free == 2
    assert np.array_equal(slots.x, plant.x0[slots.vid].T) and np.array_equal(w.signals.xrow, plant.x0[slots.vid])
    assert np.array_equal(slots.p, np.repeat(plant.p.T, N_BATCH, axis=1))  # a shared row in every slot
    assert np.array_equal(slots.bounds, plant.bounds[slots.vid].T)
    assert np.array_equal(slots.cp, controller.cp[slots.vid]) and np.array_equal(slots.cs, controller.cs0[slots.vid])
    assert np.array_equal(slots.axes, forces.friction[slots.vid])
    assert not slots.stopped.any() and not slots.mode.any() and np.isnan(slots.log).all()
    assert w.signals.log is slots.log and w.signals.uc.shape == (N_U, N_BATCH)
    # the kernel writes its working arrays, never the engine's
    for a in (slots.x, slots.p, slots.bounds, slots.cp, slots.cs, w.signals.xrow, w.es):
        a[...] = -1.0
    after = (plant.x0, plant.p, plant.bounds, controller.cp, controller.cs0, elements.es0)
    assert all(np.array_equal(a, b) for a, b in zip(before, after, strict=True))
    # the flat views are the (n, B) arrays' memory
    flat, stages = w.flat, w.stages
    assert stages.k.shape == (MAX_STAGES, N, N_BATCH) and not stages.k.any()
    for view, array in ((flat.x, slots.x), (flat.bounds, slots.bounds), (flat.xs, stages.xs),
                        (flat.x_new, stages.x_new), (flat.k1, stages.k[0]), (flat.k4, stages.k[3])):  # fmt: skip
        array[...] = np.arange(array.size).reshape(array.shape)
        assert view.shape == (N * N_BATCH,) and np.array_equal(view, np.arange(view.size))
    assert outcome.status.tolist() == [STATUS_OK] * N_BATCH and outcome.fail_index.tolist() == [-1] * N_BATCH
    assert outcome.n_valid.tolist() == [N_STEPS + 1] * N_BATCH
    assert (w.n_sensor, w.n_actuator) == (2, 1)
    assert w.c.tolist() == [0.0, 1.0] and w.picked.tolist() == [0, -1]
    assert w.friction.scratch.k_stage.shape == (2, N, 1) and w.friction.scratch.d_tmp.shape == (1,)


def test_without_friction_the_slots_keep_the_variants_order() -> None:
    plant, controller, elements, forces, records, outcome = _call(frictional=())
    integration = Integration(method=1, rk_a=np.zeros((4, 4)), rk_b=np.full(4, 0.25), dt=0.1)
    w = working_storage(integration, plant, controller, elements, forces, records, outcome)
    assert w.slots.vid.tolist() == list(range(N_BATCH)) and w.n_free == N_BATCH


def test_stage_nodes_and_output_picks_follow_their_definitions() -> None:
    """c_i = sum_j a_ij; picked[i] = j where row i of C is e_j, else -1."""
    a = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [-1.0, 2.0, 0.0]])
    assert stage_nodes(a).tolist() == [0.0, 0.5, 1.0]
    C = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 0.0, 2.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    assert output_picks(C).tolist() == [1, -1, -1, -1, -1] and output_picks(C).dtype == np.int64

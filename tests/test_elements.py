"""Loop elements at the hook points, added by a third-party package through an entry point.

The package below knows nothing of the integrator: it compiles two elements against
``nlcx.kernel.abi.ELEMENT_SIG`` (a measurement quantiser at the sensor hook and a dead zone at
the actuator hook), declares their parameters as named layouts and registers them in the
``nlcx.uncertainties`` entry-point group. Each test checks the element's law on the run.
"""

from __future__ import annotations

import copy
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from nlcx import config, engine, registry

PACKAGE = '''
import numpy as np
from typing import Literal
from numba import njit
from pydantic import Field
from nlcx.kernel.abi import ELEMENT_SIG
from nlcx.layout import Layout
from nlcx.uncertainty.base import Element, UncertaintyConfig, UncertaintyModel

QUANTISER = Layout("Quantiser", ("step",))
Q = QUANTISER.at
DEAD_ZONE = Layout("DeadZone", ("width",))
D = DEAD_ZONE.at


@njit(ELEMENT_SIG, cache=False)
def quantise(t, dt, k, signal, vid, ep, es, data, p_off, s_off, d_off):
    for b in range(signal.shape[0]):
        q = ep[vid[b], p_off + Q.step]
        for j in range(signal.shape[1]):
            signal[b, j] = q * np.round(signal[b, j] / q)


@njit(ELEMENT_SIG, cache=False)
def dead_zone(t, dt, k, signal, vid, ep, es, data, p_off, s_off, d_off):
    for b in range(signal.shape[0]):
        w = ep[vid[b], p_off + D.width]
        for j in range(signal.shape[1]):
            u = signal[b, j]
            signal[b, j] = 0.0 if abs(u) <= w else u - w * np.sign(u)


class QuantiserConfig(UncertaintyConfig):
    kind: Literal["quantiser"] = "quantiser"
    step: float = Field(gt=0)


class Quantiser(UncertaintyModel):
    """Measurement quantiser y -> q round(y / q) (third-party sensor element)."""
    Config = QuantiserConfig

    def apply(self, cfg, hooks, path):
        hooks.add_element(Element("sensor", quantise, params=QUANTISER.pack(step=cfg.step), name="quantiser"))


class DeadZoneConfig(UncertaintyConfig):
    kind: Literal["dead_zone"] = "dead_zone"
    width: float = Field(ge=0)


class DeadZone(UncertaintyModel):
    """Actuator dead zone (third-party actuator element)."""
    Config = DeadZoneConfig

    def apply(self, cfg, hooks, path):
        hooks.add_element(Element("actuator", dead_zone, params=DEAD_ZONE.pack(width=cfg.width), name="dead zone"))
'''


@pytest.fixture
def third_party(tmp_path: Path) -> Iterator[None]:
    """Install the package above as a distribution with two nlcx.uncertainties entry points."""
    (tmp_path / "loopparts.py").write_text(textwrap.dedent(PACKAGE))
    dist = tmp_path / "loopparts-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: loopparts\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(
        "[nlcx.uncertainties]\nquantiser = loopparts:Quantiser\ndead_zone = loopparts:DeadZone\n"
    )
    sys.path.insert(0, str(tmp_path))
    registry.uncertainties._scanned = False
    try:
        yield
    finally:
        sys.path.remove(str(tmp_path))
        for name in ("quantiser", "dead_zone"):
            registry.uncertainties._entries.pop(name, None)
            registry.uncertainties._loaded.pop(name, None)
        sys.modules.pop("loopparts", None)


def _run(raw: dict, uncertainty: dict) -> engine.ExperimentResult:
    raw = copy.deepcopy(raw)
    raw["uncertainty"] = uncertainty
    raw["simulation"]["t_end"] = 5.0
    return engine.run_experiment(config.build(raw))


def test_entry_point_elements_are_listed(third_party: None) -> None:
    assert {"quantiser", "dead_zone"} <= set(registry.uncertainties.names())


def test_quantiser_at_the_sensor_hook_feeds_the_controller(third_party: None, x_error_raw: dict) -> None:
    """The error-AGS gains logged by the PID are eq. 2.20 of the quantised measurement."""
    q = 0.01
    result = _run(x_error_raw, {"quantiser": {"kind": "quantiser", "step": q}})
    plain = _run(x_error_raw, {})
    run = next(r for r in result.runs if r.label == "proposed")
    sched = result.prepared.experiment.resolved()["controllers"]["proposed"]["loops"]["x"]["schedule"]
    x = run.x[:, result.prepared.plant.state_index("x")]
    e = run.r[:, run.controller.reference_signals.index("x")] - q * np.round(x / q)
    kp_min, kp_max, rate = sched["kp"]["min"], sched["kp"]["max"], sched["rate"]["kp"]
    expected = kp_max - (kp_max - kp_min) * np.exp(-rate * np.abs(e))
    logged = run.log[:, run.controller.log_names.index("x.kp")]
    assert np.allclose(logged, expected, rtol=0, atol=1e-12)
    assert not np.array_equal(run.x, next(r for r in plain.runs if r.label == "proposed").x)


def test_dead_zone_at_the_actuator_hook_acts_on_the_applied_force(third_party: None, x_error_raw: dict) -> None:
    """The applied force is the dead zone of the controller's summed loop outputs."""
    w = 0.5
    result = _run(x_error_raw, {"dz": {"kind": "dead_zone", "width": w}})
    assert [run.label for run in result.runs] == ["conventional", "proposed"]
    for run in result.runs:
        names = run.controller.log_names
        commanded = run.log[:, names.index("theta.u")] + run.log[:, names.index("x.u")]
        expected = np.where(np.abs(commanded) <= w, 0.0, commanded - w * np.sign(commanded))
        assert np.allclose(run.u[:, 0], expected, rtol=0, atol=1e-12)
        assert np.any(run.u[:, 0] == 0.0) and np.any(run.u[:, 0] != 0.0)


def test_elements_act_in_a_batch_as_alone(third_party: None, x_error_raw: dict) -> None:
    """Variants with different element parameters in one kernel call equal separate runs."""
    a = _run(x_error_raw, {"quantiser": {"kind": "quantiser", "step": 0.01}})
    b = _run(x_error_raw, {"quantiser": {"kind": "quantiser", "step": 0.05}})
    items = engine.items_of(a.prepared) + engine.items_of(b.prepared)
    runs = engine.simulate_items(items, a.prepared.grid, "rk4")
    for batched, alone in zip(runs, [*a.runs, *b.runs], strict=True):
        assert np.array_equal(batched.x, alone.x) and np.array_equal(batched.u, alone.u)

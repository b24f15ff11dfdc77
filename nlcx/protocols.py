"""What each kind of plugin provides: one :class:`typing.Protocol` a kind.

The config loader and the engine reach a registered plugin only through the members its kind's
protocol names: a plant's parameter model, signals and ``build``; a controller's configuration
model, ``normalize`` and ``build``; and so on. A plugin need not subclass anything; nlcx's base
classes (:class:`~nlcx.plants.base.PlantModel`, :class:`~nlcx.controllers.base.ControllerModel`,
:class:`~nlcx.controllers.schedules.ScheduleModel`, :class:`~nlcx.uncertainty.base.UncertaintyModel`,
:class:`~nlcx.references.base.ReferenceModel`, :class:`~nlcx.tuning.base.TunerModel`) satisfy them
and supply the defaults. A registry checks a plugin against its kind's protocol when it first loads
it (:func:`missing_members`), so a plugin that lacks a member is refused in one line that names it.

A plugin's validated configuration reaches its methods as ``cfg``, an instance of the plugin's own
``Config`` (``Params`` for a plant): each plugin narrows it to its model, so the protocols type it
as ``Any``.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    import numpy as np
    from pydantic import BaseModel

    from nlcx.controllers.base import ControllerConfig, ControllerInstance, ControllerModel
    from nlcx.kernel.signatures import GainSchedule
    from nlcx.plants.base import Plant, PlantModel, PlantParams, Signal
    from nlcx.references.base import ReferenceConfig, ReferenceModel, SignalPlan
    from nlcx.tuning.base import TuneContext, TunerConfig, TunerModel
    from nlcx.uncertainty.base import Hooks, UncertaintyConfig, UncertaintyModel


class PlantPlugin(Protocol):
    """A plant: its parameter model, its signals, and :meth:`build`, which makes the numeric
    :class:`~nlcx.plants.base.Plant` the engine integrates (:class:`~nlcx.plants.base.PlantModel`)."""

    @property
    def Params(self) -> type[PlantParams]:
        """The pydantic model of ``plant.params`` (the one place the parameters' defaults live)."""
        ...

    @property
    def states(self) -> tuple[Signal, ...]:
        """The states, in the order of the state vector, with their units."""
        ...

    @property
    def inputs(self) -> tuple[Signal, ...]:
        """The inputs, in the order of the input vector, with their units."""
        ...

    @property
    def outputs(self) -> tuple[str, ...]:
        """The outputs, each the name of a measured state."""
        ...

    def build(
        self,
        name: str,
        params: Any,
        x0: Mapping[str, float],
        bounds: Mapping[str, float],
        path: str = "plant",
    ) -> Plant:
        """The plant registered as ``name`` with the validated ``params``, initial state and
        divergence bounds (states by name)."""
        ...


class ControllerPlugin(Protocol):
    """A controller: its configuration model, :meth:`normalize` and :meth:`build`
    (:class:`~nlcx.controllers.base.ControllerModel`)."""

    @property
    def Config(self) -> type[ControllerConfig]:
        """The pydantic model of a ``controllers.<label>`` section."""
        ...

    def normalize(self, cfg: Any, path: str) -> ControllerConfig:
        """``cfg`` with its nested plugin sections (e.g. gain schedules) validated and completed."""
        ...

    def build(self, label: str, cfg: Any, plant: Plant, path: str, dt: float | None = None) -> ControllerInstance:
        """The controller for ``plant``: its compiled step, parameter row and initial state;
        ``dt`` is the simulation step."""
        ...


class SchedulePlugin(Protocol):
    """A gain schedule of the PID: its configuration model, :meth:`pack` and the compiled
    :attr:`gains` (:class:`~nlcx.controllers.schedules.ScheduleModel`)."""

    @property
    def Config(self) -> type[BaseModel]:
        """The pydantic model of a loop's ``schedule`` section: a subclass of
        :class:`~nlcx.controllers.schedules.ScheduleConfig` (typed as any pydantic model: the
        module that defines it imports the registry, which imports this module)."""
        ...

    @property
    def gains(self) -> GainSchedule:
        """(t, e, de/dt, p, row, offset) -> (k_p, k_i, k_d), :data:`nlcx.kernel.abi.CALLBACK_SIG`."""
        ...

    def pack(self, cfg: Any) -> np.ndarray:
        """The parameter block :attr:`gains` reads."""
        ...


class UncertaintyPlugin(Protocol):
    """An uncertainty or loop element: its configuration model and :meth:`apply`
    (:class:`~nlcx.uncertainty.base.UncertaintyModel`)."""

    @property
    def Config(self) -> type[UncertaintyConfig]:
        """The pydantic model of an ``uncertainty.<label>`` section."""
        ...

    def apply(self, cfg: Any, hooks: Hooks, path: str) -> None:
        """Add this uncertainty's elements, derivative terms or forces to ``hooks``."""
        ...


class ReferencePlugin(Protocol):
    """A reference: its configuration model, r(t) and how a signal following it is measured
    (:class:`~nlcx.references.base.ReferenceModel`)."""

    @property
    def Config(self) -> type[ReferenceConfig]:
        """The pydantic model of a ``reference.<signal>`` section."""
        ...

    def values(self, cfg: Any, t: np.ndarray) -> np.ndarray:
        """r(t) at the times ``t``."""
        ...

    def signal_plan(self, cfg: Any) -> SignalPlan:
        """Step, regulation or tracking metrics for a signal following this reference."""
        ...


class TunerPlugin(Protocol):
    """A tuner: its configuration model and :meth:`tune` (:class:`~nlcx.tuning.base.TunerModel`)."""

    @property
    def Config(self) -> type[TunerConfig]:
        """The pydantic model of an entry of a controller's ``tune`` list."""
        ...

    def tune(self, controller: dict[str, Any], cfg: Any, ctx: TuneContext) -> dict[str, Any]:
        """The controller's configuration with this tuner's numbers filled in."""
        ...


def protocol_members(protocol: type) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(attributes, methods) a plugin kind's protocol declares, in declaration order: its
    properties (a plugin may hold them as class attributes) and its other public functions."""
    members = [(name, value) for name, value in vars(protocol).items() if not name.startswith("_")]
    attributes = tuple(name for name, value in members if isinstance(value, property))
    methods = tuple(name for name, value in members if inspect.isfunction(value))
    return attributes, methods


def missing_members(plugin: object, protocol: type) -> list[str]:
    """What ``plugin`` lacks of ``protocol``, in words; empty when it has every member.

    An absent member is named as it is; a method that is not callable and a ``Config`` or
    ``Params`` that is not a pydantic model class are named with what is wrong with them."""
    attributes, methods = protocol_members(protocol)
    problems = []
    for name in (*attributes, *methods):
        if not hasattr(plugin, name):
            problems.append(name)
        elif name in methods and not callable(getattr(plugin, name)):
            problems.append(f"{name} (not callable)")
        elif name in _MODELS and not _is_model(getattr(plugin, name)):
            problems.append(f"{name} (not a pydantic model class)")
    return problems


#: The members that hold a plugin's pydantic model (its configuration's or a plant's parameters').
_MODELS = ("Config", "Params")


def _is_model(value: object) -> bool:
    from pydantic import BaseModel

    return isinstance(value, type) and issubclass(value, BaseModel)


if TYPE_CHECKING:
    # nlcx's base classes satisfy the protocols: checked by mypy, never run. ScheduleModel's module
    # imports the registry (and so this module), which keeps it out of this check.
    def _base_classes_conform(
        plant: PlantModel[PlantParams],
        controller: ControllerModel,
        uncertainty: UncertaintyModel,
        reference: ReferenceModel,
        tuner: TunerModel,
    ) -> tuple[PlantPlugin, ControllerPlugin, UncertaintyPlugin, ReferencePlugin, TunerPlugin]:
        return plant, controller, uncertainty, reference, tuner

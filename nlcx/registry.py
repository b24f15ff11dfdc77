"""Plugin registries, in the manner of gymnasium's ``register(id, entry_point)``.

A plugin is registered under the name the YAML uses, either as an object or as a lazy
``"package.module:attribute"`` string. Third-party packages add plugins through
``importlib.metadata`` entry points in the groups ``nlcx.plants``, ``nlcx.controllers``,
``nlcx.schedules``, ``nlcx.uncertainties`` and ``nlcx.references``; the entry point's name is
the registered name and its value the entry point, e.g. in a third party's pyproject.toml::

    [project.entry-points."nlcx.plants"]
    furuta = "mypkg.furuta:FurutaPendulum"
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Iterator
from importlib.metadata import entry_points
from typing import Any, Generic, TypeVar

from nlcx.errors import ConfigError

T = TypeVar("T")


def load_entry_point(entry_point: str) -> Any:
    """Import ``"package.module:attribute"`` and return the attribute."""
    module_name, _, attribute = entry_point.partition(":")
    obj: Any = importlib.import_module(module_name)
    for part in filter(None, attribute.split(".")):
        obj = getattr(obj, part)
    return obj


class Registry(Generic[T]):
    """Names the YAML may use for one kind of plugin, mapped to their entry points."""

    def __init__(self, kind: str, group: str) -> None:
        self.kind = kind
        self.group = group
        self._entries: dict[str, Any] = {}
        self._loaded: dict[str, T] = {}
        self._scanned = False

    def register(self, name: str, entry_point: str | T, *, replace: bool = False) -> None:
        """Register ``entry_point`` (an object or a ``"module:attr"`` string) as ``name``."""
        if name in self._entries and not replace:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self._entries[name] = entry_point
        self._loaded.pop(name, None)

    def _scan_entry_points(self) -> None:
        if self._scanned:
            return
        self._scanned = True
        for ep in entry_points(group=self.group):
            if ep.name not in self._entries:
                self._entries[ep.name] = ep.value

    def names(self) -> list[str]:
        """Registered names in registration order (built-ins first, then entry points)."""
        self._scan_entry_points()
        return list(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self.names()

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def get(self, name: str, *, path: str = "") -> T:
        """The plugin registered as ``name`` (a class is instantiated once, without arguments).

        A ConfigError at ``path`` if nothing is registered under ``name``.
        """
        if name not in self.names():
            raise ConfigError(path, name, self.unknown_message(name))
        if name not in self._loaded:
            entry = self._entries[name]
            obj = load_entry_point(entry) if isinstance(entry, str) else entry
            self._loaded[name] = obj() if isinstance(obj, type) else obj
        return self._loaded[name]

    def unknown_message(self, name: object) -> str:
        """'unknown <kind>; allowed: ...' with a close match suggested when there is one."""
        names = self.names()
        message = f"unknown {self.kind}; allowed: {', '.join(sorted(names))}"
        if isinstance(name, str):
            close = difflib.get_close_matches(name, names, n=1)
            if close:
                message += f" (did you mean {close[0]!r}?)"
        return message

    def describe(self) -> list[tuple[str, str]]:
        """(name, first line of the plugin's docstring) for ``nlcx list``."""
        rows = []
        for name in self.names():
            try:
                doc = (self.get(name).__doc__ or "").strip().splitlines()
                summary = doc[0] if doc else ""
            except Exception as exc:  # a broken third-party plugin must not break `list`
                summary = f"<failed to load: {exc}>"
            rows.append((name, summary))
        return rows


plants: Registry[Any] = Registry("plant", "nlcx.plants")
controllers: Registry[Any] = Registry("controller", "nlcx.controllers")
schedules: Registry[Any] = Registry("gain schedule", "nlcx.schedules")
uncertainties: Registry[Any] = Registry("uncertainty", "nlcx.uncertainties")
references: Registry[Any] = Registry("reference", "nlcx.references")
tuners: Registry[Any] = Registry("tuner", "nlcx.tuners")

ALL: dict[str, Registry[Any]] = {
    "plants": plants,
    "controllers": controllers,
    "schedules": schedules,
    "uncertainties": uncertainties,
    "references": references,
    "tuners": tuners,
}


def register_builtins() -> None:
    """Register nlcx's own plugins (idempotent)."""
    if "x_pendulum" in plants._entries:
        return
    plants.register("x_pendulum", "nlcx.plants.x_pendulum:XPendulum")
    plants.register("xy_pendulum", "nlcx.plants.xy_pendulum:XYPendulum")
    plants.register("xz_pendulum", "nlcx.plants.xz_pendulum:XZPendulum")
    plants.register("xyz_pendulum", "nlcx.plants.xyz_pendulum:XYZPendulum")
    plants.register("transfer_function", "nlcx.plants.transfer_function:TransferFunction")
    plants.register("cstr", "nlcx.plants.cstr:CSTR")
    controllers.register("pid", "nlcx.controllers.pid:MultiLoopPID")
    controllers.register("open_loop", "nlcx.controllers.open_loop:OpenLoop")
    controllers.register("single_neuron", "nlcx.controllers.neuron:SingleNeuron")
    controllers.register("preview", "nlcx.controllers.preview:Preview")
    schedules.register("constant", "nlcx.controllers.schedules:Constant")
    schedules.register("time_ags", "nlcx.controllers.schedules:TimeAGS")
    schedules.register("error_ags", "nlcx.controllers.schedules:ErrorAGS")
    schedules.register("fuzzy", "nlcx.controllers.fuzzy:Fuzzy")
    schedules.register("anfis", "nlcx.controllers.anfis:ANFIS")
    uncertainties.register("disturbance", "nlcx.uncertainty.disturbance:Disturbance")
    uncertainties.register("noise", "nlcx.uncertainty.noise:Noise")
    uncertainties.register("friction", "nlcx.uncertainty.friction:Friction")
    uncertainties.register("actuator_lag", "nlcx.uncertainty.actuator_lag:ActuatorLag")
    uncertainties.register("actuator_saturation", "nlcx.uncertainty.actuator_saturation:ActuatorSaturation")
    references.register("constant", "nlcx.references.basic:Constant")
    references.register("step", "nlcx.references.basic:Step")
    references.register("filtered_step", "nlcx.references.basic:FilteredStep")
    references.register("sine", "nlcx.references.basic:Sine")
    tuners.register("ziegler_nichols", "nlcx.tuning.ziegler_nichols:ZieglerNichols")
    tuners.register("ga", "nlcx.tuning.ga:GATuner")
    tuners.register("anfis", "nlcx.tuning.anfis_tuner:AnfisTuner")


register_builtins()

"""One PID implementation for every loop structure and every gain schedule: its plugin.

Each loop regulates one plant output to its reference and contributes a force to one plant
input; contributions to the same input are summed (Figs. 2.2, 3.2, 3.25, 4.2). The section a
user writes is :class:`~nlcx.controllers.pid_config.PIDConfig`, validated with its schedules
there (:func:`~nlcx.controllers.pid_config.normalize`); :meth:`MultiLoopPID.build` packs it into
the parameter row ``cp`` that the compiled step of :mod:`nlcx.controllers.pid_step` reads (that
module documents the control law and the row's layout, which this one re-exports).
"""

from __future__ import annotations

import itertools
import math
from collections import OrderedDict

import numpy as np

from nlcx import registry
from nlcx.controllers.base import ControllerInstance, ControllerModel
from nlcx.controllers.pid_config import LoopConfig, PIDConfig, normalize, schedule_of
from nlcx.controllers.pid_step import (
    ANTI_WINDUP,
    DIRECT,
    DIRECT_CONSTANT,
    DIRECT_ERROR_AGS,
    DIRECT_TIME_AGS,
    FORMS,
    HEAD,
    INPUT,
    LOOP,
    LOOP_LOG,
    LOOP_STATE,
    VIA_SLOT,
    G,
    H,
    I,
    L,
    S,
    Structure,
    pid_step,
    step_for,
    structure_of,
)
from nlcx.controllers.schedules import (
    schedule_index,
    schedule_slots,
)
from nlcx.errors import ConfigError, did_you_mean
from nlcx.plants.base import Plant, equilibrium_input
from nlcx.validation import join

__all__ = [
    "ANTI_WINDUP", "DIRECT_CONSTANT", "DIRECT_ERROR_AGS", "DIRECT_TIME_AGS", "FORMS", "HEAD", "INPUT", "LOOP",
    "LOOP_LOG", "LOOP_STATE", "VIA_SLOT", "BuiltControllers", "G", "H", "I", "L", "LoopConfig", "MultiLoopPID",
    "PIDConfig", "S", "Structure", "input_blocks", "pid_step", "step_for", "structure_of",
]  # fmt: skip


class BuiltControllers:
    """The PIDs built so far, so that the variants of a sweep that change only the plant's
    numbers share one controller (the arrays it holds are read-only).

    An entry's key is what :meth:`MultiLoopPID.build` reads: the validated config *object*
    (by identity: a sweep's variants share their validated controller section, see
    ``config.build(raw, like=base)``; the entry holds it, so its id stays its own), the label,
    the config path, the simulation step and the plant's name, output and input names and
    constant input bias (the equilibrium feed-forward follows the plant's numbers). At most
    ``size`` entries; the least recently used is dropped first."""

    def __init__(self, size: int = 256) -> None:
        self.size = size
        self._entries: OrderedDict[tuple[object, ...], tuple[PIDConfig, ControllerInstance]] = OrderedDict()

    @staticmethod
    def key(
        label: str, cfg: PIDConfig, plant: Plant, path: str, dt: float | None, bias: np.ndarray
    ) -> tuple[object, ...]:
        """The entry's key (see the class docstring)."""
        return (id(cfg), label, path, dt, plant.name, tuple(plant.output_names), tuple(plant.input_names),
                bias.tobytes())  # fmt: skip

    def get(self, key: tuple[object, ...]) -> ControllerInstance | None:
        """The controller built for ``key``, or None."""
        entry = self._entries.get(key)
        if entry is None:
            return None
        self._entries.move_to_end(key)
        return entry[1]

    def put(self, key: tuple[object, ...], cfg: PIDConfig, controller: ControllerInstance) -> ControllerInstance:
        """Keep ``controller``, built from ``cfg`` for ``key``; returns it."""
        self._entries[key] = (cfg, controller)
        if len(self._entries) > self.size:
            self._entries.popitem(last=False)
        return controller

    def clear(self) -> None:
        """Forget every controller."""
        self._entries.clear()


#: The controllers :meth:`MultiLoopPID.build` built so far.
_BUILT = BuiltControllers()


class MultiLoopPID(ControllerModel):
    """PID loops summed per input; gains from a schedule (constant, time_ags, error_ags, ...)."""

    Config = PIDConfig
    step = staticmethod(pid_step)

    #: Each loop's gain schedule validated by its registered model (in the config module).
    normalize = staticmethod(normalize)

    def build(self, label: str, cfg: PIDConfig, plant: Plant, path: str, dt: float | None = None) -> ControllerInstance:
        """The controller for ``plant``, from ``cfg`` as ``config.build`` leaves it (its schedules
        validated by :meth:`normalize`; one whose schedules are still mappings is normalized here).

        The parameter row ``cp`` is the :data:`HEAD` block, an :data:`INPUT` block per input,
        a :data:`LOOP` block per loop and each loop's schedule block, each packed from its config
        section in one place (:meth:`_head`, :meth:`_loop_block`, the schedule's ``pack``). A
        controller is built once for a validated config and the plant's signals and equilibrium
        bias (:class:`BuiltControllers`)."""
        bias = self._bias(cfg, plant, path)
        entry = _BUILT.key(label, cfg, plant, path, dt, bias)
        built = _BUILT.get(entry)
        if built is not None:
            return built
        if dt is not None and 0.0 < cfg.sample_time < dt:
            allowed = f"allowed: 0 (updated every step) or a period >= simulation.dt = {dt:g} s"
            raise ConfigError(join(path, "sample_time"), cfg.sample_time, allowed)
        normalized = self.normalize(cfg, path)
        loops = self._resolve_loops(normalized, plant, path)
        head = self._head(normalized, plant, path, bias)
        schedules = [registry.schedules.get(schedule_of(loop).kind).pack(schedule_of(loop)) for _, loop, _, _ in loops]
        starts = itertools.accumulate(map(len, schedules[:-1]), initial=head.size + LOOP.size * len(loops))
        blocks = [
            self._loop_block(normalized, loop, plant, signal, input_name, start, len(sp))
            for (_, loop, signal, input_name), start, sp in zip(loops, starts, schedules, strict=True)
        ]
        cp = np.concatenate([head, *blocks, *(np.asarray(sp, dtype=float) for sp in schedules)])
        units = [_log_units(plant.unit_of(input_name), plant.unit_of(signal)) for _, _, signal, input_name in loops]
        controller = ControllerInstance(
            label=label,
            kind="pid",
            step=step_for(structure_of(cp)),
            general_step=step_for(None),
            cp=cp,
            cs0=np.zeros(LOOP_STATE.size * len(loops)),
            reference_signals=tuple(plant.output_names),
            log_names=tuple(f"{key}.{name}" for key, _, _, _ in loops for name in LOOP_LOG.fields),
            log_units=tuple(unit for loop_units in units for unit in loop_units),
            config=normalized.model_dump(),
            callbacks=schedule_slots(schedule_of(loop).kind for _, loop, _, _ in loops if _via_slot(loop)),
        )
        return _BUILT.put(entry, cfg, controller)

    @staticmethod
    def _head(cfg: PIDConfig, plant: Plant, path: str, bias: np.ndarray) -> np.ndarray:
        """The :data:`HEAD` block and each input's :data:`INPUT` block: its constant ``bias`` and
        its saturation limit |u_j| <= limit_j (inf where none is set)."""
        inputs = plant.input_names
        sat = cfg.saturation
        limits = sat.limits if sat else {}
        for name, value in limits.items():
            where = join(path, "saturation", "limits", name)
            if name not in inputs:  # the limit itself is > 0 by its model (pid_config.SaturationConfig)
                hint = did_you_mean(name, inputs)
                raise ConfigError(where, value, f"unknown input{hint}; allowed: {', '.join(inputs)}")
        return np.concatenate([
            HEAD.pack(
                n_loops=len(cfg.loops), n_inputs=len(inputs),
                anti_windup=ANTI_WINDUP[sat.anti_windup if sat else "off"], kb=sat.kb if sat else 0.0,
                sample_time=cfg.sample_time,
            ),
            *(INPUT.pack(bias=b, limit=limits.get(name, math.inf)) for name, b in zip(inputs, bias, strict=True)),
        ])  # fmt: skip

    @staticmethod
    def _bias(cfg: PIDConfig, plant: Plant, path: str) -> np.ndarray:
        """The constant part of each input: the equilibrium feed-forward plus ``bias``."""
        inputs = plant.input_names
        bias = equilibrium_input(plant) if cfg.feedforward == "equilibrium" else np.zeros(len(inputs))
        for name, value in cfg.bias.items():
            if name not in inputs:
                problem = f"unknown input{did_you_mean(name, inputs)}; allowed: {', '.join(inputs)}"
                raise ConfigError(join(path, "bias", name), value, problem)
            bias[inputs.index(name)] += value
        return bias

    @staticmethod
    def _loop_block(
        cfg: PIDConfig, loop: LoopConfig, plant: Plant, signal: str, input_name: str, offset: int, length: int
    ) -> np.ndarray:
        """One loop's :data:`LOOP` block; its schedule's parameters sit at ``offset``."""
        deriv = loop.derivative or cfg.derivative
        kind = schedule_of(loop).kind
        return LOOP.pack(
            y_index=plant.output_names.index(signal),
            r_index=plant.output_names.index(signal),
            u_index=plant.input_names.index(input_name),
            sign=loop.sign,
            schedule_slot=schedule_index(kind),
            filtered=deriv.method == "filtered",
            N=deriv.N,
            on_measurement=deriv.on == "measurement",
            gain_inside=cfg.integral == "inside",
            schedule_offset=offset,
            schedule_length=length,
            setpoint_weight=cfg.setpoint_weight,
            direct_schedule=DIRECT.get(registry.schedules.get(kind).gains, VIA_SLOT),
            form=FORMS[cfg.form],
            scale=loop.scale,
            integral_limit=math.inf if loop.integral_limit is None else loop.integral_limit,
        )

    @staticmethod
    def _resolve_loops(cfg: PIDConfig, plant: Plant, path: str) -> list[tuple[str, LoopConfig, str, str]]:
        """(key, loop, output, input) per loop; exactly one loop per plant output."""
        outputs = plant.output_names
        inputs = plant.input_names
        resolved = []
        for key, loop in cfg.loops.items():
            signal = loop.signal or key
            if signal not in outputs:
                where = join(path, "loops", key, "signal") if loop.signal else join(path, "loops", key)
                hint = did_you_mean(signal, outputs)
                raise ConfigError(where, signal, f"not an output of {plant.name}{hint}; allowed: {', '.join(outputs)}")
            input_name = loop.input or plant.features.loop_inputs.get(signal)
            if input_name is None and len(inputs) == 1:
                input_name = inputs[0]
            if input_name not in inputs:
                raise ConfigError(
                    join(path, "loops", key, "input"),
                    loop.input,
                    f"must name an input of {plant.name}{did_you_mean(loop.input, inputs)}; "
                    f"allowed: {', '.join(inputs)}",
                )
            resolved.append((key, loop, signal, input_name))
        signals = [s for _, _, s, _ in resolved]
        if sorted(signals) != sorted(outputs):
            raise ConfigError(
                join(path, "loops"),
                list(cfg.loops),
                f"{plant.name} needs exactly one loop per output ({len(outputs)}: "
                f"{', '.join(outputs)}); got {len(signals)} loop(s) on {', '.join(signals)}",
            )
        return resolved


def _via_slot(loop: LoopConfig) -> bool:
    """Whether the PID calls the loop's schedule through its callback slot (not a built-in)."""
    return registry.schedules.get(schedule_of(loop).kind).gains not in DIRECT


def input_blocks(cp: np.ndarray) -> list[dict[str, float]]:
    """Each input's :data:`INPUT` block (bias, limit) of a PID's parameter row."""
    head = HEAD.unpack(cp)
    return [INPUT.unpack(cp, HEAD.size + INPUT.size * j) for j in range(int(head["n_inputs"]))]


def _log_units(unit_in: str, unit_sig: str) -> list[str]:
    """Units of a loop's logged k_p, k_i, k_d and output (:data:`LOOP_LOG`)."""
    return [f"{unit_in}/{unit_sig}", f"{unit_in}/({unit_sig}*s)", f"{unit_in}*s/{unit_sig}", unit_in]

"""Full-state feedback baselines: ``state_feedback`` (a given K), ``lqr`` and ``pole_placement``.

Each is a control law written with the mechanism of :mod:`nlcx.controllers.law`, one law per
shape of plant (numbers of states, references, inputs and integrators), generated once and
compiled for the CPU's kernel and the GPU from the same source. The law is

    u = u_0 - K (x - x_ref) - K_i z,        dz/dt = y_I - r_I                      (1)

with x the plant's state (an output read after the sensor elements, every other state read
from the true state: full-state feedback), x_ref the referenced states at their reference and
every other state at the operating point x_op, u_0 the input that holds the plant there
(:func:`nlcx.plants.base.equilibrium_input`: gravity compensation for the x-z pendulums), and
z the integral of the error of each output named in ``integral`` (z_k integrated by the
forward Euler step of the law's period, as the PID's integrators are).

K = [K, K_i] is designed on the plant linearised about its operating point, dx/dt = A x + B u
(:func:`nlcx.analysis.linear.plant_system`), augmented with the integrators,

    A_a = [[A, 0], [C_I, 0]],    B_a = [[B], [0]],                                  (2)

- ``lqr``: python-control's ``lqr(A_a, B_a, Q, R)``, Q = diag(q) in the plant's state order
  then the integrators', R = diag(r) in its input order: the gain that minimises
  ∫ (x_aᵀ Q x_a + uᵀ R u) dt on (2) (the solution of the continuous algebraic Riccati
  equation);
- ``pole_placement``: python-control's ``place(A_a, B_a, poles)``;
- ``state_feedback``: K given, ``gain`` rows in the plant's input order.

The design model is the plant of the run, or the one ``design`` sets parameters of: a design
frozen at nominal parameters (a sweep of the plant's parameters then tests one controller
against many plants). The designed K, the closed-loop poles of (2) and the model's
parameters are written to tuning.csv.
"""

from __future__ import annotations

import functools
from typing import Any, Literal

import numpy as np
from pydantic import Field

from nlcx import registry
from nlcx.controllers.base import ControllerConfig, ControllerInstance
from nlcx.controllers.law import LawController, LawShape, law_model
from nlcx.errors import ConfigError
from nlcx.kernel.signatures import ControllerStep
from nlcx.plants.base import Plant, equilibrium_input
from nlcx.validation import join

__all__ = ["LQR", "PolePlacement", "StateFeedback", "design_model", "feedback_law_source"]


class FeedbackConfig(ControllerConfig):
    """What the three designs share: integral action, the design model and the law's period."""

    integral: list[str] = Field(
        default=[], description="outputs with integral action (each needs a reference), in the order of K_i's columns"
    )
    design: dict[str, float] = Field(
        default={}, description="parameters of the design model (default: the run's plant's); e.g. nominal values"
    )
    sample_time: float | None = Field(
        None, gt=0, description="period of the law, s; None: every integration step", json_schema_extra={"unit": "s"}
    )


class StateFeedbackConfig(FeedbackConfig):
    kind: Literal["state_feedback"] = Field("state_feedback", description="registered name of this controller")
    gain: list[list[float]] = Field(
        description="K: one row per plant input, one column per plant state then per integrator (eq. 1)"
    )


class LQRConfig(FeedbackConfig):
    kind: Literal["lqr"] = Field("lqr", description="registered name of this controller")
    q: list[float] = Field(description="diagonal of Q: one weight per plant state, then per integrator (>= 0)")
    r: list[float] = Field(description="diagonal of R: one weight per plant input (> 0)")


class PolePlacementConfig(FeedbackConfig):
    kind: Literal["pole_placement"] = Field("pole_placement", description="registered name of this controller")
    poles: list[float | str] = Field(
        description="closed-loop poles of eq. 2, one per plant state and integrator: numbers, or complex as '-1+2j'"
    )


def feedback_law_source(n_x: int, n_r: int, n_u: int, n_z: int) -> str:
    """Source of eq. 1 for a plant of ``n_x`` states, ``n_r`` references, ``n_u`` inputs and
    ``n_z`` integrators. ``p`` holds, in order: u_0 (n_u), x_op (n_x), each state's reference
    (an index into r, -1 for none; n_x), each integrator's output (an index into x; n_z) and its
    reference (an index into r; n_z), K by rows (n_u x n_x), K_i by rows (n_u x n_z)."""
    xop, rmap = n_u, n_u + n_x
    imap, iref = rmap + n_x, rmap + n_x + n_z
    k0, ki0 = iref + n_z, iref + n_z + n_u * n_x
    lines = ["def law(t, dt, y, r, s, p):"]
    lines += [f"    u{j} = p[{j}]" for j in range(n_u)]
    lines.append(f"    for i in range({n_x}):")
    ref = f"r[int(p[{rmap} + i])] if p[{rmap} + i] >= 0.0 else p[{xop} + i]" if n_r else f"p[{xop} + i]"
    lines.append(f"        e = y[i] - ({ref})")
    lines += [f"        u{j} -= p[{k0 + j * n_x} + i] * e" for j in range(n_u)]
    if n_z:
        lines.append(f"    for k in range({n_z}):")
        lines += [f"        u{j} -= p[{ki0 + j * n_z} + k] * s[k]" for j in range(n_u)]
    nexts = [f"s[{k}] + dt * (y[int(p[{imap + k}])] - r[int(p[{iref + k}])])" for k in range(n_z)]
    lines.append(f"    return ({''.join(f'u{j}, ' for j in range(n_u))}), ({''.join(f'{n}, ' for n in nexts)})")
    return "\n".join(lines) + "\n"


@functools.cache
def _compiled_law(n_x: int, n_r: int, n_u: int, n_z: int) -> LawController:
    """The law of eq. 1 for this shape, compiled once per process (:func:`nlcx.controllers.law.law_model`)."""
    namespace: dict[str, Any] = {}  # exec fills it: the generated law
    exec(compile(feedback_law_source(n_x, n_r, n_u, n_z), f"<nlcx feedback {n_x}x{n_u}>", "exec"), namespace)
    n_p = n_u + 2 * n_x + 2 * n_z + n_u * n_x + n_u * n_z
    shape = LawShape(
        name="feedback",
        measures=tuple(f"x{i}" for i in range(n_x)),
        references=tuple(f"r{k}" for k in range(n_r)),
        inputs=tuple(f"u{j}" for j in range(n_u)),
        states=tuple((f"z{k}", 0.0) for k in range(n_z)),
        params=tuple((f"p{k}", 0.0, "", "") for k in range(n_p)),
        named_params=False,
    )
    return law_model(namespace["law"], shape, doc="u = u0 - K (x - x_ref) - Ki z (eq. 1)")


def design_model(plant: Plant, design: dict[str, float], path: str) -> Plant:
    """The plant the design is made on: ``plant``, or the same plant with the parameters
    ``design`` sets (its unknown keys a one-line error naming them)."""
    if not design:
        return plant
    model = registry.plants.get(plant.name)
    from nlcx.validation import validate_model

    params = validate_model(model.Params, {**plant.params, **design}, join(path, "design"))
    return model.build(plant.name, params, {}, {})


class _Feedback(LawController):
    """Eq. 1 with a K from :meth:`gains`; the law of the plant's shape (:func:`_compiled_law`)."""

    @property
    def step(self) -> ControllerStep:
        """The step of eq. 1 for one state, reference, input and integrator: every shape's step is
        generated from the same source (a built controller carries its plant's)."""
        return _compiled_law(1, 1, 1, 1).step

    def gains(self, cfg: Any, A: np.ndarray, B: np.ndarray, path: str) -> np.ndarray:
        """K = [K, K_i] of the augmented model (eq. 2), n_u rows."""
        raise NotImplementedError

    def build(
        self, label: str, cfg: FeedbackConfig, plant: Plant, path: str, dt: float | None = None
    ) -> ControllerInstance:
        from nlcx.analysis.linear import plant_system

        states, outputs, inputs = plant.state_names, plant.output_names, plant.input_names
        refs = [o for o in outputs if o in states]
        for name in cfg.integral:
            if name not in refs:
                raise ConfigError(join(path, "integral"), name, f"an output of {plant.name} that is a state; "
                                  f"allowed: {', '.join(refs)}")  # fmt: skip
        model = design_model(plant, cfg.design, path)
        linear = plant_system(model)
        n_x, n_u, n_z = len(states), len(inputs), len(cfg.integral)
        C_I = np.array([[1.0 if s == o else 0.0 for s in states] for o in cfg.integral]).reshape(n_z, n_x)
        A_a = np.block([[linear.A, np.zeros((n_x, n_z))], [C_I, np.zeros((n_z, n_z))]])
        B_a = np.vstack([linear.B, np.zeros((n_z, n_u))])
        K = np.atleast_2d(np.asarray(self.gains(cfg, A_a, B_a, path), dtype=float))
        if K.shape != (n_u, n_x + n_z) or not np.all(np.isfinite(K)):
            wanted = f"{n_u} x {n_x + n_z} (inputs x (states + integrators)), every entry finite"
            raise ConfigError(path, cfg.kind, f"its gain is {K.shape[0]} x {K.shape[1]}; allowed: {wanted}")
        x_op = model.features.x_op if model.features.x_op is not None else np.zeros(n_x)
        u_0 = equilibrium_input(model, x_op)
        rmap = [float(refs.index(s)) if s in refs else -1.0 for s in states]
        imap = [float(states.index(o)) for o in cfg.integral]
        iref = [float(refs.index(o)) for o in cfg.integral]
        params = [*u_0, *x_op, *rmap, *imap, *iref, *K[:, :n_x].ravel(), *K[:, n_x:].ravel()]
        law = _compiled_law(n_x, len(refs), n_u, n_z)
        hold = 1 if cfg.sample_time is None or dt is None else _hold(cfg.sample_time, dt, path)
        codes = [(-1.0 - outputs.index(s)) if s in outputs else float(i) for i, s in enumerate(states)]
        cp = np.array([*codes, *range(n_u), float(hold), cfg.sample_time or 0.0, *params], dtype=float)
        poles = np.linalg.eigvals(A_a - B_a @ K)
        return ControllerInstance(
            label=label,
            kind=cfg.kind,
            step=law.step,
            cp=cp,
            cs0=np.zeros(1 + n_u + n_z),
            reference_signals=tuple(refs),
            log_names=tuple(f"{cfg.kind}.z_{o}" for o in cfg.integral),
            log_units=tuple("" for _ in cfg.integral),
            config=cfg.model_dump(),
            records=self.design_records(K, states, inputs, cfg.integral, poles, model),
            law=law,
        )

    @staticmethod
    def design_records(
        K: np.ndarray, states: list[str], inputs: list[str], integral: list[str], poles: np.ndarray, model: Plant
    ) -> dict[str, object]:
        """tuning.csv's rows: every entry of K by input and state (or integrator), the poles of
        the design's closed loop (eq. 2) and the design model's parameters."""
        columns = [*states, *(f"z_{o}" for o in integral)]
        rows: dict[str, object] = {
            f"K[{u},{c}]": float(K[i, j]) for i, u in enumerate(inputs) for j, c in enumerate(columns)
        }
        order = np.argsort(-poles.real, kind="stable")
        rows |= {f"pole_{k}": complex(poles[i]).__repr__().strip("()") for k, i in enumerate(order)}
        rows |= {f"design.{name}": value for name, value in model.params.items() if isinstance(value, int | float)}
        return rows


def _hold(sample_time: float, dt: float, path: str) -> int:
    from nlcx.controllers.base import check_sample_time

    return check_sample_time(sample_time, dt, path)


class StateFeedback(_Feedback):
    """State feedback with a given gain: u = u0 - K (x - x_ref) - Ki z (see the module docstring)."""

    Config = StateFeedbackConfig

    def gains(self, cfg: StateFeedbackConfig, A: np.ndarray, B: np.ndarray, path: str) -> np.ndarray:
        return np.array(cfg.gain, dtype=float)


class LQR(_Feedback):
    """Linear-quadratic regulator on the linearised plant, with integral action (python-control's lqr)."""

    Config = LQRConfig

    def gains(self, cfg: LQRConfig, A: np.ndarray, B: np.ndarray, path: str) -> np.ndarray:
        import control as ct

        n, m = A.shape[0], B.shape[1]
        if len(cfg.q) != n or min(cfg.q) < 0:
            raise ConfigError(join(path, "q"), cfg.q, f"{n} weights >= 0: one per plant state, then per integrator")
        if len(cfg.r) != m or min(cfg.r) <= 0:
            raise ConfigError(join(path, "r"), cfg.r, f"{m} weights > 0: one per plant input")
        try:
            K, _, _ = ct.lqr(A, B, np.diag(cfg.q), np.diag(cfg.r))
        except Exception as exc:  # python-control's words: not stabilisable, not detectable
            raise ConfigError(path, "lqr", f"no LQR gain for these weights: {str(exc).splitlines()[0]}") from None
        return np.asarray(K)


class PolePlacement(_Feedback):
    """State feedback whose closed loop has the given poles (python-control's place)."""

    Config = PolePlacementConfig

    def gains(self, cfg: PolePlacementConfig, A: np.ndarray, B: np.ndarray, path: str) -> np.ndarray:
        import control as ct

        try:
            poles = np.array([complex(str(p).replace(" ", "")) for p in cfg.poles])
        except ValueError:
            raise ConfigError(join(path, "poles"), cfg.poles, "numbers, or complex numbers as '-1+2j'") from None
        if poles.size != A.shape[0]:
            raise ConfigError(join(path, "poles"), cfg.poles, f"{A.shape[0]} poles: one per plant state and integrator")
        try:
            return np.asarray(ct.place(A, B, poles))
        except Exception as exc:  # python-control's words: not controllable, conjugates missing
            raise ConfigError(join(path, "poles"), cfg.poles, f"cannot be placed: {str(exc).splitlines()[0]}") from None

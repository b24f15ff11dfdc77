"""The section models of an experiment config: what each top-level key holds, its defaults and its checks.

Every default of the generic sections lives here (a plugin's own keys live in the plugin's
model). Each field's ``description`` (with its ``unit`` in the JSON schema where it has one)
is what the configuration reference documents. The plugin sections (``controllers``,
``uncertainty``, ``reference``) hold raw mappings here; :func:`nlcx.config.build` validates
each by the model of the plugin its ``kind`` selects.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

#: The most integration steps a run may have (t_end / dt); memory refuses most runs far sooner
#: (:mod:`nlcx.preflight`), this bounds the arithmetic that counts them.
MAX_STEPS = 1e12


class Section(BaseModel):
    """Base of the section models: unknown keys are errors.

    Each field's ``description`` (with its ``unit`` in the JSON schema where it has one) is what
    the configuration reference documents.
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class PlantSection(Section):
    """The plant: a registered model by name, its parameters and its initial state.

    The parameters are validated by the plant's own parameter model, which holds their defaults
    and units.
    """

    name: str = Field(description="Registered plant name (``nlcx list plants``).")
    params: dict[str, object] = Field(
        default={}, description="Parameter overrides; the defaults come from the plant's parameter model."
    )
    x0: dict[str, float] = Field(
        default={}, description="Initial state by state name, in the state's units; unlisted states start at 0."
    )


class SimulationSection(Section):
    """Time grid, integrator and stability bounds of a run.

    The controllers are sampled at every integration step, so ``dt`` is also the sampling
    period; ``t_end`` must be a whole number of steps.
    """

    t_end: float = Field(20.0, gt=0, description="Final time, s.", json_schema_extra={"unit": "s"})
    dt: float = Field(
        1e-3,
        gt=0,
        description="Integration step and controller sampling period, s.",
        json_schema_extra={"unit": "s"},
    )
    integrator: Literal["rk4", "heun", "euler"] = Field("rk4", description="Fixed-step explicit Runge-Kutta method.")
    device: Literal["cpu", "cuda"] = Field(
        "cpu",
        description=(
            "Where the closed loops are integrated: on the CPU, or one GPU thread a loop with numba-cuda "
            "(pip install 'nlcx[cuda]'; docs/guide/gpu.md)."
        ),
    )
    bounds: dict[str, float] = Field(
        default={},
        description=(
            "Bound on |state| by state name, in the state's units: a run stops as unstable when a state "
            "exceeds its bound or becomes non-finite (plants add defaults, e.g. |theta| <= pi/2 for the pendulums)."
        ),
    )

    @field_validator("dt")
    @classmethod
    def _countable_steps(cls, dt: float, info: ValidationInfo) -> float:
        t_end = info.data.get("t_end")
        steps = t_end / dt if isinstance(t_end, float) else 0.0
        if not steps <= MAX_STEPS:
            raise ValueError(
                f"t_end / dt = {t_end:g} / {dt:g} = {steps:.3g} steps; allowed: at most {MAX_STEPS:.0e} steps "
                "(a longer step, or a shorter run)"
            )
        return dt

    @field_validator("bounds")
    @classmethod
    def _positive_bounds(cls, bounds: dict[str, float]) -> dict[str, float]:
        for key, value in bounds.items():
            if not value > 0:
                raise ValueError(f"bound of {key} must be > 0")
        return bounds


class MetricsSection(Section):
    """Definitions of the step-response metrics, see docs/metrics.md.

    The settling band and the rise limits are fractions of the step (step signals) or of the
    peak deviation (regulated signals); the steady-state window is in seconds; the event times
    of a step response are measured from its step or from the start of the run (``time_origin``).
    """

    settling_band: float = Field(
        0.02,
        gt=0,
        lt=1,
        description=(
            "Settling band as a fraction of the step size (step signals) or of the peak deviation (regulated signals)."
        ),
    )
    rise_limits: tuple[float, float] = Field(
        (0.1, 0.9), description="Rise time between these fractions of the step, low and high."
    )
    ss_window: float = Field(
        1.0,
        gt=0,
        description="Window at the end of the run over which the steady-state value is averaged, s.",
        json_schema_extra={"unit": "s"},
    )
    regulation_abs_tol: float = Field(
        0.0, ge=0, description="Absolute floor of the settling band of a regulated signal, in the signal's units."
    )
    time_origin: Literal["start", "step"] = Field(
        "step",
        description=(
            "Origin of the event times, s (settling_time and peak_time) of a signal measured as a step response: "
            "step: the time of the step it responds to (its step or filtered_step reference's time; for an output "
            "measured after an open-loop input step, that step's time); start: t = 0, the start of the run, so each "
            "is the step's time later than under step. rise_time, a duration, is the same under both; regulated "
            "signals are measured from t = 0 under both."
        ),
    )

    @field_validator("rise_limits")
    @classmethod
    def _ordered(cls, limits: tuple[float, float]) -> tuple[float, float]:
        lo, hi = limits
        if not 0 <= lo < hi <= 1:
            raise ValueError("rise_limits must satisfy 0 <= low < high <= 1")
        return limits


class OutputsSection(Section):
    """What a run writes into its run directory besides metrics.csv and config.yaml."""

    dir: str | None = Field(None, description="Run directory; default results/<name>. ``--out`` overrides it.")
    timeseries: bool = Field(True, description="Write the time series (every sample of every controller).")
    timeseries_format: Literal["csv", "parquet"] = Field(
        "csv",
        description=(
            "File of the time series: timeseries.csv, or timeseries.parquet (binary, every float exact, zstd: "
            "about 40 % of the CSV's size and a third of its writing time; for long or many runs)."
        ),
    )
    figure: bool = Field(True, description="Write the thesis-style figure (figure.png).")
    gains_figure: bool = Field(
        False,
        description=(
            "Also write gains.png: every input and every logged gain against time, one panel each "
            "(off by default: it is slow to draw when there are many panels)."
        ),
    )
    figure_inputs: bool = Field(False, description="Add an axes per plant input to figure.png, below the outputs.")
    figure_metrics: list[str] = Field(
        default_factory=list, description="Metrics quoted in figure.png's legend, e.g. [ise, control_effort]."
    )


class ExperimentSection(Section):
    """A whole experiment: one plant, the controllers compared on it, and how it is run.

    The plugin sections (``controllers``, ``uncertainty``, ``reference``) hold raw mappings here;
    :func:`build` validates each by the model of the plugin its ``kind`` selects.
    """

    imports: list[str] = Field(
        default=[],
        description="Plugin files (a .py file relative to the config) and modules to import before the config is "
        "validated, so the plants and controllers they register can be named here.",
    )
    name: str = Field(
        pattern=r"^[A-Za-z0-9_.\-]+$",
        description="Experiment name (letters, digits, _, . and -); the default run directory is results/<name>.",
    )
    title: str | None = Field(None, description="Figure title (e.g. the thesis's caption).")
    seed: int = Field(0, ge=0, description="Root of numpy.random.SeedSequence for everything random in the run.")
    plant: PlantSection = Field(description="The plant and its parameters.")
    controllers: dict[str, dict[str, object]] = Field(
        min_length=1, description="Controllers compared side by side, by label (e.g. conventional, proposed)."
    )
    uncertainty: dict[str, dict[str, object]] = Field(
        default={}, description="Uncertainties by label; each has ``kind`` (default: the label)."
    )
    reference: dict[str, dict[str, object]] = Field(
        default={}, description="References by signal name; outputs not listed are regulated to 0."
    )
    simulation: SimulationSection = Field(
        default_factory=SimulationSection, description="Time grid, integrator and stability bounds."
    )
    metrics: MetricsSection = Field(default_factory=MetricsSection, description="Definitions of the metrics.")
    outputs: OutputsSection = Field(default_factory=OutputsSection, description="What the run directory holds.")

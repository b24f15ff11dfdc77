"""The metrics' names, in the order each function of :mod:`nlcx.metrics` reports them, and their units."""

from __future__ import annotations

#: Unit of every metric.  "signal" and "input" stand for the unit of the measured signal
#: (or error) and of the control input; the caller substitutes them (e.g. "rad", "N").
METRIC_UNITS: dict[str, str] = {
    # step_response_metrics
    "rise_time": "s",
    "settling_time": "s",
    "overshoot": "%",
    "undershoot": "%",
    "peak": "signal",
    "peak_time": "s",
    "steady_state_error": "signal",
    # regulation_metrics (also settling_time, peak_time, steady_state_error)
    "peak_deviation": "signal",
    # error_integrals
    "ise": "signal^2*s",
    "iae": "signal*s",
    "itae": "signal*s^2",
    "max_abs_error": "signal",
    "rms_error": "signal",
    # input_metrics
    "control_effort": "input^2*s",
    "peak_input": "input",
    "total_variation": "input",
}

STEP_METRICS: tuple[str, ...] = (
    "rise_time",
    "settling_time",
    "overshoot",
    "undershoot",
    "peak",
    "peak_time",
    "steady_state_error",
)
REGULATION_METRICS: tuple[str, ...] = (
    "peak_deviation",
    "peak_time",
    "settling_time",
    "steady_state_error",
)
STEP_INFO_METRICS: tuple[str, ...] = (
    "rise_time",
    "settling_time",
    "overshoot",
    "undershoot",
    "peak",
    "peak_time",
    "steady_state_value",
    "settling_min",
    "settling_max",
)
#: Unit of every :func:`nlcx.metrics.step_info` value ("signal": the unit of the measured signal).
STEP_INFO_UNITS: dict[str, str] = {
    "rise_time": "s",
    "settling_time": "s",
    "overshoot": "%",
    "undershoot": "%",
    "peak": "signal",
    "peak_time": "s",
    "steady_state_value": "signal",
    "settling_min": "signal",
    "settling_max": "signal",
}
#: The metrics that are times of events, measured from an origin (the step, or the start of the
#: run: :func:`nlcx.metrics.measured_from`); ``rise_time`` is a duration, the same from any origin.
EVENT_TIMES: tuple[str, ...] = ("settling_time", "peak_time")
ERROR_METRICS: tuple[str, ...] = ("ise", "iae", "itae", "max_abs_error", "rms_error")
INPUT_METRICS: tuple[str, ...] = ("control_effort", "peak_input", "total_variation")

"""A SISO transfer function G(s) = num(s)/den(s), simulated in controllable canonical form."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from pydantic import Field, field_validator, model_validator

from nlcx._numba_compat import hot_njit
from nlcx.kernel.signatures import FloatArray
from nlcx.plants.base import (
    Plant,
    PlantModel,
    PlantParams,
    Signal,
    divergence_bounds,
    initial_state,
)


class TransferFunctionParams(PlantParams):
    """Numerator and denominator coefficients in descending powers of s."""

    num: list[float] = Field(min_length=1, description="numerator coefficients, highest power first")
    den: list[float] = Field(min_length=2, description="denominator coefficients, highest power first")
    input_name: str = Field("u", description="name of the plant's input")
    input_unit: str = Field("", description="unit of the input")
    output_name: str = Field("y", description="name of the plant's output")
    output_unit: str = Field("", description="unit of the output")

    @field_validator("den")
    @classmethod
    def _leading_nonzero(cls, den: list[float]) -> list[float]:
        if den[0] == 0:
            raise ValueError("the leading denominator coefficient must be non-zero")
        return den

    @model_validator(mode="after")
    def _strictly_proper(self) -> TransferFunctionParams:
        num = np.trim_zeros(np.asarray(self.num, dtype=float), "f")
        if num.size >= len(self.den):
            raise ValueError(
                "must be strictly proper (degree of num < degree of den): the controller is "
                "sampled with a zero-order hold, so a direct feedthrough would be an algebraic loop"
            )
        return self


@hot_njit(cache=True, error_model="numpy")
def companion_rhs(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, nb: int
) -> None:  # pragma: no cover - compiled
    """Controllable canonical form for each of the first nb columns (variants) b:
    x_i' = x_{i+1}, x_n' = -sum_j a_j x_{j+1} + u, p[:, b] = a_0..a_{n-1}."""
    n = x.shape[0]
    for b in range(nb):
        dx[n - 1, b] = u[0, b]
    for j in range(n):  # each loop runs along a row, over the variants
        for b in range(nb):
            dx[n - 1, b] -= p[j, b] * x[j, b]
    for i in range(n - 1):
        for b in range(nb):
            dx[i, b] = x[i + 1, b]


def canonical_form(num: list[float], den: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """(a, b): den/den[0] = s^n + a_{n-1}s^{n-1} + ... + a_0 and y = sum_j b_j x_{j+1}."""
    den_arr = np.asarray(den, dtype=float)
    num_arr = np.asarray(num, dtype=float) / den_arr[0]
    den_arr = den_arr / den_arr[0]
    n = den_arr.size - 1
    a = den_arr[1:][::-1].copy()
    b = np.zeros(n)
    trimmed = np.trim_zeros(num_arr, "f")
    b[: trimmed.size] = trimmed[::-1]
    return a, b


class TransferFunction(PlantModel):
    """Generic SISO transfer function num(s)/den(s) (strictly proper)."""

    Params = TransferFunctionParams
    rhs = staticmethod(companion_rhs)

    def build(
        self,
        name: str,
        params: TransferFunctionParams,
        x0: Mapping[str, float],
        bounds: Mapping[str, float],
        path: str = "plant",
    ) -> Plant:
        a, b = canonical_form(params.num, params.den)
        n = a.size
        states = tuple(Signal(f"x{i + 1}", "") for i in range(n))
        names = [s.name for s in states]
        x_init = initial_state(names, x0, path)
        bound_vec = divergence_bounds(names, bounds)
        return Plant(
            name=name,
            states=states,
            inputs=(Signal(params.input_name, params.input_unit),),
            outputs=(Signal(params.output_name, params.output_unit),),
            rhs=self.rhs,
            p=a,
            C=b[None, :].copy(),
            x0=x_init,
            params=params.model_dump(),
            param_units={"num": "", "den": ""},
            bounds=bound_vec,
        )

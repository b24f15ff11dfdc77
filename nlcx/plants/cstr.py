"""The Van de Vusse CSTR of section 5.2 (Bequette, 2003): A -> B -> C, 2A -> D.

dC_A/dt = (F/V)(C_Af - C_A) - k1 C_A - k3 C_A^2      (eq. 5.1)
dC_B/dt = -(F/V) C_B + k1 C_A - k2 C_B                (eq. 5.2)

States C_A, C_B (gmol/L), input the dilution rate u = F/V (1/min), output C_B. The thesis
prints the rate constants rounded (k1 = 0.83, k2 = 1.66, k3 = 0.16); its linearisation
(eqs. 5.3-5.4: -2.4048, 0.8333, -2.2381, 7, -1.117) comes from Bequette's exact values
k1 = 5/6, k2 = 5/3 (1/min), k3 = 1/6 (L/(gmol min)) with C_Af = 10 gmol/L, which give the
printed operating point C_As = 3, C_Bs = 1.117 at F_s/V = 4/7 = 0.5714. Those exact values
are the defaults (docs/assumptions.md A20).
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from nlcx._numba_compat import hot_njit
from nlcx.kernel.signatures import FloatArray
from nlcx.layout import Layout
from nlcx.plants.base import PlantModel, PlantParams, Signal


class CSTRParams(PlantParams):
    k1: float = Field(5 / 6, gt=0, description="rate constant A -> B", json_schema_extra={"unit": "1/min"})
    k2: float = Field(5 / 3, gt=0, description="rate constant B -> C", json_schema_extra={"unit": "1/min"})
    k3: float = Field(1 / 6, gt=0, description="rate constant 2A -> D", json_schema_extra={"unit": "L/(gmol min)"})
    CAf: float = Field(10.0, gt=0, description="feed concentration of A", json_schema_extra={"unit": "gmol/L"})
    u_s: float = Field(4 / 7, gt=0, description="operating dilution rate F_s/V", json_schema_extra={"unit": "1/min"})


#: The parameter vector p: the rate constants and the feed concentration (section 5.2).
PARAMS = Layout("cstr", ("k1", "k2", "k3", "CAf"))
K = PARAMS.at


@hot_njit(cache=True, error_model="numpy")
def cstr_rhs(
    t: float, x: FloatArray, u: FloatArray, p: FloatArray, dx: FloatArray, nb: int
) -> None:  # pragma: no cover - compiled
    """Eqs. 5.1-5.2 for each of the first nb columns (variants) b: p[:, b] a :data:`PARAMS`
    block, u[:, b] = (F/V,)."""
    for b in range(nb):
        k1, k2, k3, caf = p[K.k1, b], p[K.k2, b], p[K.k3, b], p[K.CAf, b]
        ca, cb = x[0, b], x[1, b]
        d = u[0, b]
        dx[0, b] = d * (caf - ca) - k1 * ca - k3 * ca * ca  # eq. 5.1
        dx[1, b] = -d * cb + k1 * ca - k2 * cb  # eq. 5.2


def steady_state(params: CSTRParams) -> tuple[float, float]:
    """(C_As, C_Bs) at the dilution rate u_s: the positive root of eq. 5.1 = 0, then eq. 5.2 = 0."""
    u = params.u_s
    a, b, c = params.k3, params.k1 + u, -u * params.CAf
    ca = (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)
    cb = params.k1 * ca / (u + params.k2)
    return ca, cb


class CSTR(PlantModel):
    """Van de Vusse CSTR, eqs. 5.1-5.2 (section 5.2 operating point)."""

    Params = CSTRParams
    states = (Signal("C_A", "gmol/L", "Concentration C_A"), Signal("C_B", "gmol/L", "Concentration C_B"))
    inputs = (Signal("u", "1/min", "Dilution rate F/V"),)
    outputs = ("C_B",)
    rhs = staticmethod(cstr_rhs)

    def parameter_vector(self, params: CSTRParams) -> np.ndarray:
        return PARAMS.pack(k1=params.k1, k2=params.k2, k3=params.k3, CAf=params.CAf)

    def operating_point(self, params: CSTRParams) -> dict[str, float]:
        ca, cb = steady_state(params)
        return {"C_A": ca, "C_B": cb}

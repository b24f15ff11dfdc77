"""nlcx: reproducible experiments on the control of nonlinear systems."""

from nlcx.compiled_cache import ensure_consistent

__version__ = "0.1.0"

# before any compiled function is loaded from numba's disk cache (see nlcx.compiled_cache)
ensure_consistent()

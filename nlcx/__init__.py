"""nlcx: reproducible experiments on the control of nonlinear systems."""

__version__ = "0.1.0"

"""Uncertainties (disturbance, noise, friction), registered by name and combinable."""

"""Tuners: calibration of unprinted numbers and (chapter 5) controller tuning."""

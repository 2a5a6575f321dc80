"""Calibrations done once and applied to many measurements."""

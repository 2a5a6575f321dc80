"""Corrections for the next cutting or polishing run from a form-error map (docs/conventions.md,
Correction): the math (compute), the corrected nominal (refit), the files (files) and a simulated
machine to close the loop on (loop)."""
from .compute import (
                      Correction,
                      CorrectionInputError,
                      ErrorMap,
                      azimuthal_mean,
                      compute_correction,
                      error_map,
                      gaussian_sigma,
                      pv,
                      radial_remainder,
                      regular_grid,
                      removal_map,
                      rms,
)
from .refit import refit_surface, spec_of

__all__ = ["Correction", "CorrectionInputError", "ErrorMap", "azimuthal_mean", "compute_correction",
           "error_map", "gaussian_sigma", "pv", "radial_remainder", "regular_grid", "removal_map", "rms",
           "refit_surface", "spec_of"]

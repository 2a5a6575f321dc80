"""The numbers opticians quote: PV, RMS, PVr, slope RMS, Zernike terms, profiles and PSDs."""
from . import zernike
from .form import form_metrics, pvr

__all__ = ["form_metrics", "pvr", "zernike"]

"""The numbers opticians quote: PV, RMS, PVr, slope RMS, Zernike terms, profiles and PSDs."""
from .form import form_metrics, pvr
from . import zernike

__all__ = ["form_metrics", "pvr", "zernike"]

"""Lengths for people: a value in mm written in the unit its size asks for ("43.9 nm", not
"4.39e-05 mm"). Files keep their stated unit; this is for messages, titles and labels only."""
from __future__ import annotations

import math

_STEPS = ((1e3, "m"), (1.0, "mm"), (1e-3, "µm"), (1e-6, "nm"))  # sub-nm stays in nm (0.72 nm)


def length_unit(v_mm: float) -> tuple[float, str]:
    """(scale, unit) so that v_mm / scale lies in [1, 1000) — below 1 nm still nm, and mm up to 10 m
    (a 1300 mm mirror is "1.3e+03 mm" in a drawing's unit)."""
    a = abs(v_mm)
    if not math.isfinite(a) or a == 0:
        return 1.0, "mm"
    if a >= 1e4:
        return 1e3, "m"
    for scale, unit in _STEPS[1:]:
        if a >= scale:
            return scale, unit
    return 1e-6, "nm"


def format_length(v_mm: float, digits: int = 3) -> str:
    """``v_mm`` (mm) with ``digits`` significant digits in its own unit: 4.39e-5 → '43.9 nm'."""
    v = float(v_mm)
    if not math.isfinite(v):
        return f"{v} mm"
    scale, unit = length_unit(v)
    return f"{v / scale:.{digits}g} {unit}"

"""Lengths for people: a value in mm written in the unit its size asks for ("43.9 nm", not
"4.39e-05 mm"). Files keep their stated unit; this is for messages, titles and labels only."""
from __future__ import annotations

import math

_STEPS = ((1e3, "m"), (1.0, "mm"), (1e-3, "µm"), (1e-6, "nm"))  # sub-nm stays in nm (0.72 nm)


def length_unit(v_mm: float) -> tuple[float, str]:
    """(scale, unit) so that v_mm / scale lies in [1, 1000) — below 1 nm still nm, and mm up to 10 m
    (a 1300 mm mirror is "1300 mm", in a drawing's unit)."""
    a = abs(v_mm)
    if not math.isfinite(a) or a == 0:
        return 1.0, "mm"
    if a >= 1e4:
        return 1e3, "m"
    for scale, unit in _STEPS[1:]:
        if a >= scale:
            return scale, unit
    return 1e-6, "nm"


#: points a display unit is chosen from at most (every k-th value)
UNIT_SAMPLE = 200_000


def display_unit(v_mm) -> str:
    """The unit ("nm", "µm" or "mm") lengths (mm) read best in on an axis, a colour bar or a view:
    that of their robust spread (0.5–99.5 %), so a 44 nm PV reads "43.9 nm", not "4.39e-05 mm", and
    one spike does not switch a 50 nm map to µm; mm from 1 mm up. The report's figures
    (core.figures.length_axis) and the window's views (app.display) share it."""
    import numpy as np

    v = np.asarray(v_mm, dtype=np.float64).ravel()
    if v.size > 2 * UNIT_SAMPLE:  # a fixed, evenly spread sample: the same unit in every view
        v = v[:: v.size // UNIT_SAMPLE]
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "mm"
    lo, hi = np.percentile(v, [0.5, 99.5]) if v.size > 200 else (v.min(), v.max())
    span = float(hi - lo) or float(np.max(np.abs(v)))
    if span == 0.0:
        return "nm"  # all zero (a flat map, a noise-free fit): "0 nm", never a colour bar of ±1e-12 mm
    unit = length_unit(span)[1]
    return unit if unit in ("mm", "µm", "nm") else ("mm" if unit == "m" else "nm")


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def superscript(n) -> str:
    """A whole number as superscript digits: −3 → "⁻³" (exponents in labels: 10⁻⁶, mm⁻³)."""
    return str(n).translate(_SUPERSCRIPT)


def format_length(v_mm: float, digits: int = 3) -> str:
    """``v_mm`` (mm) with ``digits`` significant digits in its own unit: 4.39e-5 → '43.9 nm'."""
    v = float(v_mm)
    if not math.isfinite(v):
        return f"{v} mm"
    # the unit of the value as rounded: 9.9996e-4 mm reads "1 µm", not "1e+03 nm"
    scale, unit = length_unit(float(f"{v:.{digits}g}"))
    w = v / scale
    if 10 ** digits <= abs(w) < 1e9:  # 1300 mm reads "1300 mm" (a drawing's figure), never "1.3e+03 mm"
        return f"{w:.0f} {unit}"  # (and 1e300 mm not as 298 digits of metres)
    return f"{w:.{digits}g} {unit}"


# --- units stated in files (headers like ``x [µm]``) -----------------------------------------------
# A length in a file's unit becomes mm in ONE IEEE operation, so it is correctly rounded: units below
# the mm are divided by an exact power of ten (1234 µm / 1000 is the float64 nearest 1.234, the same
# value as "1.234" written in mm — multiplying by 1e-3, itself inexact, can be one ulp off), units
# above it are multiplied (m × 1000, cm × 10, in × 25.4). mm itself is left untouched (no operation),
# so a file written in mm reads back bit for bit.
_DIVIDE_TO_MM = {"um": 1e3, "µm": 1e3, "μm": 1e3, "micron": 1e3, "microns": 1e3, "nm": 1e6, "pm": 1e9}
_MULTIPLY_TO_MM = {"mm": 1.0, "cm": 10.0, "dm": 100.0, "m": 1e3, "in": 25.4, "inch": 25.4}
LENGTH_UNITS = tuple(sorted({*_DIVIDE_TO_MM, *_MULTIPLY_TO_MM}))

#: channels PointsPro's steps make that hold lengths in mm (written ``name [mm]``): the residual and
#: what the steps remove or add (docs/formats.md, Units in headers)
LENGTH_CHANNELS = frozenset({"residual", "probe_residual", "kinematic_error", "dynamic_error", "z_raw",
                             "u_x", "u_y", "u_z", "omega", "xd", "xc"})
#: channels that are counts, labels or flags: never converted, written without a unit
UNITLESS_CHANNELS = frozenset({"index", "row", "col", "line", "fiducial", "sensor", "flags", "flag",
                               "outside_workspace", "classification", "point", "point_source_id",
                               "return_number", "number_of_returns"})


def _unit_key(unit: str) -> str:
    u = unit.strip()
    return u if u in ("µm", "μm") else u.lower()


def is_length_unit(unit: str | None) -> bool:
    """Whether ``unit`` (as a file writes it: ``µm``, ``um``, ``nm``, ``mm``, ``m``, ``in`` …) is a
    length PointsPro converts to mm."""
    if not unit:
        return False
    k = _unit_key(unit)
    return k in _DIVIDE_TO_MM or k in _MULTIPLY_TO_MM


def length_to_mm(values, unit: str):
    """``values`` (float64 array) stated in ``unit`` as mm: one correctly rounded division (units
    below the mm) or multiplication (above), none for mm. KeyError for a unit that is no length."""
    import numpy as np

    k = _unit_key(unit)
    a = np.asarray(values, dtype=np.float64)
    if k in _DIVIDE_TO_MM:
        return a / _DIVIDE_TO_MM[k]
    factor = _MULTIPLY_TO_MM[k]
    return a if factor == 1.0 else a * factor


def channel_unit(name: str, stated: str | None = None) -> str | None:
    """The unit a written file states for channel ``name`` as PointsPro holds it: ``mm`` for x, y, z,
    the steps' length channels and any channel read with a length unit (converted on reading); a
    non-length unit the input stated (``s``, ``°C``) as it was; None for counts, labels, flags and
    channels of unknown unit."""
    if name in ("x", "y", "z") or name in LENGTH_CHANNELS:
        return "mm"
    if name in UNITLESS_CHANNELS or not stated:
        return None
    return "mm" if is_length_unit(stated) else stated


#: a figure's unit from its key's suffix (report.json's convention: rms_um, slope_rms_urad, alpha_deg)
KEY_UNITS = (("_um", "µm"), ("_nm", "nm"), ("_mm", "mm"), ("_urad", "µrad"), ("_deg", "°"),
             ("_arcsec", "″"), ("_s", "s"))


#: report keys with no unit suffix that are lengths in mm by the rule of docs/conventions.md, Units
#: (a pose's translation, a step's window or spacing, an aperture's diameter, a surface's radius; and
#: the measurement model's effect parameters in mm, explain.json's ``found[].params``: a vibration's
#: ``amplitude``, spindle_axial's harmonics ``a1``…``b32``, straightness ``s2``…``s4``, thermal_drift
#: ``d1``, ``d2`` — docs/formats.md, Measurement models; core/simulate/effects.py). No other report
#: uses these names (spindle_tilt's harmonics carry their unit: ``a2_arcsec``).
BARE_LENGTH_KEYS = frozenset({"dx", "dy", "dz", "tx", "ty", "tz", "diameter", "aperture", "knot_spacing",
                              "spacing", "window", "norm_radius", "r_max", "radius", "probe_radius",
                              "amplitude", "s2", "s3", "s4", "d1", "d2",
                              *(f"{ab}{k}" for k in range(1, 33) for ab in "ab")})


def unit_of_key(name: str) -> str:
    """The unit a report key names ("" for none): its suffix's (``rms_um`` µm, ``alpha_deg`` °), or mm
    for a bare length (``BARE_LENGTH_KEYS``; "pose.dz" is the pose's dz) and its uncertainty
    (``u_dz``). The report's tables, the window's step tables and the Monte Carlo's histograms label
    figures by it."""
    unit = next((u for suffix, u in KEY_UNITS if name.endswith(suffix)), "")
    last = name.rsplit(".", 1)[-1]
    if not unit and (last in BARE_LENGTH_KEYS or last.startswith("u_") and last[2:] in BARE_LENGTH_KEYS):
        return "mm"  # a bare length, or its uncertainty (``u_dz`` read "1.58193e-06" without a unit)
    return unit


#: the length units numbers are shown in, and their size in mm (report keys, the window's views)
SHOWN_LENGTH_MM = {"mm": 1.0, "µm": 1e-3, "nm": 1e-6}


def column_unit(values_mm, default: str = "mm") -> str:
    """The one unit ("mm", "µm" or "nm") a table column of lengths (mm) is shown in: that of its
    largest finite magnitude, so a 50.7 µm piston reads "50.7318" under "coefficient (µm)" and the
    column's rows compare at a glance (its smaller rows keep 6 significant digits). ``default`` when
    no value is finite and non-zero."""
    big = max((abs(float(v)) for v in values_mm
               if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)), default=0.0)
    if big == 0.0:
        return default
    unit = length_unit(float(f"{big:.6g}"))[1]
    return unit if unit in SHOWN_LENGTH_MM else ("mm" if unit == "m" else "nm")


def format_keyed(name: str, v: float, digits: int = 6) -> str:
    """A report number for people, with the unit its key names: a length in the unit its size asks
    for (``robust_sigma_um`` 0.2976 → "297.6 nm", ``dx`` 0.7975361802 → "797.536 µm"), another unit
    appended ("0.168275°", "3.8695 µrad"); a key with no unit, the number alone (counts, ratios)."""
    unit = unit_of_key(name)
    if unit in SHOWN_LENGTH_MM:
        if v == 0:  # a zero in its key's own unit ("0 µm"), not "0 mm" (a review)
            return f"0 {unit}"
        return format_length(float(v) * SHOWN_LENGTH_MM[unit], digits)
    text = f"{v:.{digits}g}" if isinstance(v, float) else str(v)
    return text + ("" if not unit else unit if unit in ("°", "″") else f" {unit}")


# --- the on-machine clock and spindle angle (channels t and c, docs/formats.md) ---------------------
# The steps read a time in s and the spindle angle in degrees; a unit a file states is converted like a
# length (an exact division for a power of ten below the unit, none for the unit itself). Only units
# that mean one thing: "grad" (gon in English, degree in German) or "sec" of arc are not guessed.
_TIME_DIVIDE = {"ms": 1e3, "us": 1e6, "µs": 1e6, "μs": 1e6}
_TIME_MULTIPLY = {"s": 1.0, "sec": 1.0, "min": 60.0, "h": 3600.0}
_ANGLE_DIVIDE = {"mrad": 1e3}
_ANGLE_MULTIPLY = {"deg": 1.0, "°": 1.0, "degree": 1.0, "degrees": 1.0, "rad": 180.0 / math.pi,
                   "mrad": 180.0 / math.pi, "gon": 0.9}
#: the units a step may read a column in: name → (what it is, divisors, multipliers)
READ_UNITS = {"s": ("time", _TIME_DIVIDE, _TIME_MULTIPLY), "deg": ("angle", _ANGLE_DIVIDE, _ANGLE_MULTIPLY)}


def _in_unit(values, stated: str | None, unit: str):
    """``values`` stated in ``stated`` as ``unit`` ("s" or "deg"); as they are with no stated unit or
    the unit itself. KeyError for a stated unit that is not a ``unit`` of READ_UNITS."""
    import numpy as np

    a = np.asarray(values, dtype=np.float64)
    if not stated or not str(stated).strip():
        return a
    _, divide, multiply = READ_UNITS[unit]
    k = _unit_key(str(stated))
    if k not in divide and k not in multiply:
        raise KeyError(k)
    a = a / divide[k] if k in divide else a
    mul = multiply.get(k, 1.0)
    return a if mul == 1.0 else a * mul


def unit_problem(stated: str, unit: str, reader: str = "it", quote: bool = True) -> str:
    """Why a column stated in ``stated`` cannot be read in ``unit`` ("s" or "deg"): the message's tail,
    naming the units accepted. ``quote=False``: the stated unit is named only when it is one PointsPro
    knows (a parameter file's messages quote none of its content)."""
    what, divide, multiply = READ_UNITS[unit]
    known = ", ".join(dict.fromkeys([*multiply, *divide]))
    k = _unit_key(str(stated))
    if is_length_unit(stated):
        kind = f"a length ({k})"
    elif k in _TIME_MULTIPLY or k in _TIME_DIVIDE:
        kind = f"a time ({k})"
    elif k in _ANGLE_MULTIPLY:
        kind = f"an angle ({k})"
    else:
        kind = f"'{stated}', a unit PointsPro does not know" if quote else "a unit PointsPro does not know"
    return (f"the unit stated is {kind}; {reader} reads this column as {'an' if what == 'angle' else 'a'} "
            f"{what} in {unit}: state one of {known}, or no unit for {unit}")


def read_in(values, stated: str | None, unit: str, where: str, column: str, reader: str = "it",
            quote: bool = True):
    """``values`` of ``column`` as ``unit`` ("s" or "deg") from the unit the file stated (None: in
    ``unit`` already); InputError naming ``where`` (the file), the column, ``reader`` (the step) and
    the units accepted otherwise — a stated unit is never ignored."""
    try:
        return _in_unit(values, stated, unit)
    except KeyError:
        from .errors import InputError

        name = f"{column} [{stated}]" if quote else column
        raise InputError(f"{where}: column '{name}': {unit_problem(stated, unit, reader, quote)}") from None


def channel_in(cloud, name: str, unit: str, step: str):
    """Channel ``name`` of ``cloud`` as ``unit`` ("s" or "deg"), converted from the unit its file
    stated (``meta["channel_units"]``: ``t [ms]``, ``c [rad]``); InputError naming the file, the column
    and the step otherwise."""
    stated = cloud.meta.get("channel_units") or {}
    stated = stated.get(name) if isinstance(stated, dict) else None
    return read_in(cloud[name], stated, unit, cloud.meta.get("source") or "the input", name,
                   f"the {step} step")

"""The recipe's ``tolerance:`` block: the drawing's surface form tolerance (ISO 10110-5:2015), its
quantities (ISO 14999-4:2015) and the verdict (ISO 14253-1:2017). docs/tolerance.md says it all.

    tolerance: "3/2(0.5/0.2) RMSi < 0.05"            # fringes at λ = 546.07 nm (1 fringe = λ/2)
    tolerance:
      form: "3/2(0.5/0.2) RMSi < 0.05"
      unit: fringes            # fringes (default), um or nm: the unit of the form's numbers
      wavelength_nm: 632.8     # the test wavelength of a fringe (default 546.07); or "λ = 632.8 nm"
      rule: guarded            # guarded (ISO 14253-1 guard band U95, default) or simple
      rms_um: 0.25             # plain limits, in the unit of their name (µm, µrad)
      pv_um: 1.0

Errors are one line naming the recipe's line and, for the form, the character:
"recipe.yaml, line 12: tolerance: cannot read '3/2(0.5/0.2) RMSq < 0.05' at character 17 'q':
expected t, i or a after RMS (RMSt, RMSi, RMSa)".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import RecipeError
from . import decision as dec
from .notation import Form, NotationError, parse_form
from .quantities import AREAL, ISO_KEYS, KINDS, SUMMARY_KEYS, compute

__all__ = ["ToleranceSpec", "Limit", "parse_tolerance", "Form", "parse_form", "NotationError"]

#: ISO 10110-5:2015: fringes are counted at the e-line of mercury unless the drawing says otherwise
DEFAULT_WAVELENGTH_NM = 546.07
UNITS = {"fringes": "fringes", "fringe": "fringes", "fr": "fringes", "um": "um", "µm": "um",
         "μm": "um", "nm": "nm"}
RULE_ALIASES = {"guarded": "guarded", "iso14253": "guarded", "iso 14253-1": "guarded", "simple": "simple"}
#: plain limit keys and their unit
PLAIN = {**{k: "um" for k in ISO_KEYS}, **{k: "um" for k in SUMMARY_KEYS}, "slope_rms_urad": "urad"}
KEYS = ("form", "unit", "wavelength_nm", "rule", *PLAIN)
#: the form's letters → the quantity key
FORM_KEYS = (("sag", "sag_um"), ("irr", "irr_um"), ("rsi", "rsi_um"))
RMS_KEYS = {"t": "rmst_um", "i": "rmsi_um", "a": "rmsa_um"}
#: Zernike terms (n, m) whose removal by a zernike step leaves each ISO quantity wrong
_ALLOWED_REMOVED = {"sag_um": {(0, 0), (1, 1), (1, -1)}, "rmst_um": {(0, 0), (1, 1), (1, -1)}}
_IRREGULAR_ALLOWED = {(0, 0), (1, 1), (1, -1), (2, 0)}
#: the steps that make a ``residual`` channel (the form deviation)
RESIDUAL_STEPS = ("misalignment", "register", "zernike")


#: the pose's degrees of freedom (core/params/pose.py FIVE_DOF); any other name in a step's `dof` is
#: a shape parameter of the nominal (radius, conic, A_n)
POSE_NAMES = ("alpha", "beta", "dx", "dy", "dz")
#: a stylus profile's pose (core/profiles/fit.py PROFILE_POSE)
_PROFILE_POSE = ("tilt", "decentre", "dz")

@dataclass(frozen=True)
class Limit:
    """One toleranced quantity: ``key`` (µm or µrad), its name, the limit in ``unit`` (fringes, um,
    nm, urad) and in the key's own unit."""

    key: str
    name: str
    limit: float
    unit: str
    limit_native: float


@dataclass(frozen=True)
class ToleranceSpec:
    limits: tuple[Limit, ...]
    form: Form | None = None
    unit: str = "fringes"
    wavelength_nm: float = DEFAULT_WAVELENGTH_NM
    rule: str = "guarded"
    plain: dict = field(default_factory=dict)  # plain limits as written (key → number)

    # -- what the recipe records --------------------------------------------------------------------
    def to_dict(self) -> dict:
        d: dict = {}
        if self.form is not None:
            d["form"] = self.form.text
            d["unit"] = self.unit
            if self.unit == "fringes":
                d["wavelength_nm"] = self.wavelength_nm
        d["rule"] = self.rule
        d.update(self.plain)
        return d

    @property
    def keys(self) -> list[str]:
        return [lim.key for lim in self.limits]

    @property
    def fringe_um(self) -> float:
        """One fringe in µm of surface height: λ/2."""
        return self.wavelength_nm / 2000.0

    def to_unit(self, v_native: float, unit: str) -> float:
        """A value in its key's unit (µm, µrad) → ``unit`` (fringes, um, nm, urad)."""
        return {"fringes": v_native / self.fringe_um, "nm": v_native * 1e3}.get(unit, v_native)

    # -- checks at load --------------------------------------------------------------------------
    def check_computable(self, steps, surface_spec, at: str) -> None:
        """RecipeError (one line) when this recipe cannot compute a named quantity (docs/tolerance.md)."""
        enabled = [s for s in steps if getattr(s, "enabled", True)]
        ids = [s.id for s in enabled]
        if not any(i in RESIDUAL_STEPS for i in ids) and not _flat_spec(surface_spec):
            raise RecipeError(
                f"{at}: tolerance: {_names(self.keys)} need the form deviation, but no step makes a residual "
                f"({', '.join(RESIDUAL_STEPS)}) and the nominal surface "
                f"({(surface_spec or {}).get('type', '?')}) is not a flat: add a misalignment step")
        for s in enabled:
            where = f"{at.rsplit(', line', 1)[0]}, line {s.line}" if s.line else at
            shape = [n for n in (getattr(s.params, "dof", None) or [])
                     if n not in POSE_NAMES and n not in _PROFILE_POSE]
            iso = [lim for lim in self.limits if lim.key in ISO_KEYS]
            if shape and iso:
                # a fitted radius takes the power out of the residual (A = 0 whatever the part), a
                # conic or A_n the rotationally symmetric terms (B, C, RMSx): all judged too small
                raise RecipeError(
                    f"{where}: tolerance: the {s.id} step fits the surface's {', '.join(shape)} to the "
                    f"points, which takes part of the form deviation out of the residual, so "
                    f"{_names([lim.key for lim in iso])} would be judged without it (too small): fit "
                    f"the pose only (dof: [{', '.join(POSE_NAMES)}]) or drop those limits")
            if s.id != "zernike":
                continue
            removed = _removed_pairs(s.params)
            for lim in self.limits:
                if lim.key not in ISO_KEYS:
                    continue
                allowed = _ALLOWED_REMOVED.get(lim.key, _IRREGULAR_ALLOWED)
                bad = sorted(p for p in removed if p not in allowed)
                if bad:
                    from ..metrics.zernike import name_of

                    terms = ", ".join(dict.fromkeys(name_of(*p) for p in bad))
                    raise RecipeError(
                        f"{where}: tolerance: the zernike step removes {terms} from the residual, so "
                        f"{lim.name} would be judged without it (too small): keep it — e.g. remove: "
                        f"[piston, tilt] — or drop that limit")

    # -- after the run ---------------------------------------------------------------------------
    def quantities(self, cloud, surface, centre=None) -> dict[str, float]:
        """The named quantities of the final cloud (µm; slope µrad); cheap, deterministic — the
        Monte Carlo calls it on every sample (core.uncertainty, ``kinds`` says each one's bias).
        ``centre``: the pupil centre the recipe gives (core.metrics.pupil.recipe_centre)."""
        return compute(cloud, surface, self.keys, centre)

    quantities.kinds = KINDS  # read by core.uncertainty through the bound method

    def decide(self, values: dict, uncertainty: dict | None = None) -> dict:
        """``summary["tolerance"]``: the verdict per item and overall (core.tolerance.decision)."""
        items = []
        unc = uncertainty or {}
        for lim in self.limits:
            e = unc.get(lim.key) if isinstance(unc, dict) else None
            value = values.get(lim.key)
            U = interval = None
            if isinstance(e, dict) and e.get("value") is not None and e.get("U95") is not None:
                value, U = float(e["value"]), float(e["U95"])
                if e.get("interval95") is not None:
                    interval = tuple(map(float, e["interval95"]))
            signed = value
            if value is not None and lim.key == "sag_um":
                value = abs(value)  # −L ≤ A ≤ L: the magnitude and its interval are compared
                if interval is not None:
                    lo, hi = interval
                    interval = (lo, hi) if lo >= 0 else (-hi, -lo) if hi <= 0 else (0.0, max(-lo, hi))
            v_u = None if value is None else self.to_unit(value, lim.unit)
            U_u = None if U is None else self.to_unit(U, lim.unit)
            i_u = None if interval is None else tuple(self.to_unit(b, lim.unit) for b in interval)
            verdict, note = dec.item_verdict(v_u, U_u, lim.limit, self.rule, i_u)
            native = "urad" if lim.key == "slope_rms_urad" else "um"
            item = {"name": lim.name, "quantity": lim.key, "value": v_u, "U95": U_u, "limit": lim.limit,
                    "unit": dec.UNIT_LABELS.get(lim.unit, lim.unit), "verdict": verdict,
                    f"value_{native}": value, f"U95_{native}": U, f"limit_{native}": lim.limit_native}
            if i_u is not None:
                item["interval95"] = list(i_u)
            if lim.key == "sag_um" and signed is not None:
                item["signed_value_um"] = signed
            if note:
                item["note"] = note
            items.append(item)
        verdict = dec.overall(i["verdict"] for i in items)
        out = {"verdict": verdict, "rule": self.rule, "rule_text": dec.RULES[self.rule],
               "unit": self.unit, "items": items,
               "uncertainty": "summary.uncertainty (Monte Carlo)" if uncertainty else None}
        if self.form is not None:
            out["form"] = self.form.text
        if self.unit == "fringes":
            out["wavelength_nm"] = self.wavelength_nm
            out["fringe_um"] = self.fringe_um
        out["text"] = dec.summary_text(verdict, items)
        return out


def _names(keys) -> str:
    return ", ".join(ISO_KEYS.get(k) or SUMMARY_KEYS.get(k, k) for k in keys)


def _flat_spec(surface_spec) -> bool:
    """No nominal, or one that is a plane (the heights themselves are then the form)."""
    if surface_spec is None:
        return True
    if not isinstance(surface_spec, dict) or surface_spec.get("type") == "mesh":
        return False
    try:
        from ..surfaces import parse_surface_spec

        return bool(parse_surface_spec(dict(surface_spec)).build(None).is_flat())
    except Exception:  # noqa: BLE001 — the surface's own check reports a bad spec
        return False


def _removed_pairs(params) -> set:
    from ..metrics import zernike as zk

    remove = getattr(params, "remove", None) or []
    ordering = getattr(params, "ordering", "fringe")
    out = set()
    for t in remove:
        if isinstance(t, str):
            out.update(zk.TERM_NAMES.get(t, ()))
        else:
            try:
                out.add(zk.nm_of(int(t), ordering))
            except ValueError:
                pass  # the step itself refuses an index out of range
    return out


def _loc(data, key, at: str, where: str) -> str:
    ln = getattr(data, "key_lines", {}).get(key) if isinstance(data, dict) else None
    return f"{where}, line {ln}" if ln else at


def _positive(value, key: str, loc: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RecipeError(f"{loc}: tolerance: key '{key}': a number is needed (got {value!r})")
    v = float(value)
    if not (math.isfinite(v) and v >= 0):
        what = "a wavelength is a finite number > 0" if key == "wavelength_nm" else "a limit is a finite number ≥ 0"
        raise RecipeError(f"{loc}: tolerance: key '{key}': {what} (got {value!r})")
    return v


def parse_tolerance(data, at: str, where: str = "recipe") -> ToleranceSpec:
    """The validated block (``at``: "recipe.yaml, line 12" of the key; ``where``: the file)."""
    if isinstance(data, str):
        data = {"form": data}
    if not isinstance(data, dict) or not data:
        raise RecipeError(f"{at}: tolerance: write the drawing's form tolerance, e.g. "
                          f"\"3/2(0.5/0.2) RMSi < 0.05\", or a mapping such as {{form: \"3/…\", unit: um}} "
                          f"or {{rms_um: 0.25, pv_um: 1.0}} (got {data!r})")
    for key in data:
        if key not in KEYS:
            raise RecipeError(f"{_loc(data, key, at, where)}: tolerance: unknown key '{key}' (it has "
                              f"{', '.join(KEYS)})")
    loc = lambda k: _loc(data, k, at, where)  # noqa: E731

    rule = data.get("rule", "guarded")
    if not isinstance(rule, str) or rule.strip().lower() not in RULE_ALIASES:
        raise RecipeError(f"{loc('rule')}: tolerance: key 'rule': {rule!r} is not guarded (ISO 14253-1 guard "
                          f"band U95, the default) or simple (simple acceptance)")
    rule = RULE_ALIASES[rule.strip().lower()]

    form = None
    text = data.get("form")
    if text is not None:
        if isinstance(text, (int, float)) and not isinstance(text, bool):
            text = str(text)
        if not isinstance(text, str):
            raise RecipeError(f"{loc('form')}: tolerance: key 'form': the drawing's text, e.g. "
                              f"\"3/2(0.5/0.2) RMSi < 0.05\" (got {text!r})")
        try:
            form = parse_form(text)
        except NotationError as e:
            raise RecipeError(f"{loc('form')}: tolerance: {e}") from None

    unit_raw = data.get("unit")
    unit = "fringes"
    if unit_raw is not None:
        if not isinstance(unit_raw, str) or unit_raw.strip() not in UNITS:
            raise RecipeError(f"{loc('unit')}: tolerance: key 'unit': {unit_raw!r} is not fringes, um or nm")
        unit = UNITS[unit_raw.strip()]
        if form is None:
            raise RecipeError(f"{loc('unit')}: tolerance: key 'unit' is the unit of the form's numbers, and "
                              f"there is no form (plain limits carry their unit in their name: rms_um)")

    wl = DEFAULT_WAVELENGTH_NM
    wl_given = data.get("wavelength_nm")
    if wl_given is not None:
        wl = _positive(wl_given, "wavelength_nm", loc("wavelength_nm"))
        if not 100.0 <= wl <= 20000.0:
            raise RecipeError(f"{loc('wavelength_nm')}: tolerance: key 'wavelength_nm': {wl_given!r} nm is not "
                              f"a test wavelength (100…20000 nm)")
    if form is not None and form.wavelength_nm is not None:
        if wl_given is not None and abs(wl - form.wavelength_nm) > 1e-9:
            raise RecipeError(f"{loc('wavelength_nm')}: tolerance: the form says λ = {form.wavelength_nm:g} nm "
                              f"and wavelength_nm {wl:g}: give it once")
        wl = form.wavelength_nm
        wl_given = wl
        if not 100.0 <= wl <= 20000.0:
            raise RecipeError(f"{loc('form')}: tolerance: λ = {wl:g} nm is not a test wavelength (100…20000 nm)")
    if wl_given is not None and (form is None or unit != "fringes"):
        raise RecipeError(f"{loc('wavelength_nm')}: tolerance: a wavelength counts fringes, and the limits "
                          f"here are lengths (unit: {unit if form is not None else 'in the keys'}): drop it")

    spec_unit = unit
    fringe_um = wl / 2000.0
    limits: list[Limit] = []
    if form is not None:
        def native(v):
            return v * fringe_um if unit == "fringes" else (v * 1e-3 if unit == "nm" else v)
        for attr, key in FORM_KEYS:
            v = getattr(form, attr)
            if v is not None:
                limits.append(Limit(key, ISO_KEYS[key], v, unit, native(v)))
        for kind in ("t", "i", "a"):
            if kind in form.rms:
                key = RMS_KEYS[kind]
                limits.append(Limit(key, ISO_KEYS[key], form.rms[kind], unit, native(form.rms[kind])))
    plain = {}
    for key, u in PLAIN.items():
        if key not in data:
            continue
        v = _positive(data[key], key, loc(key))
        if any(lim.key == key for lim in limits):
            raise RecipeError(f"{loc(key)}: tolerance: key '{key}': {ISO_KEYS[key]} is already limited by the "
                              f"form {form.text!r}: give it once")
        plain[key] = data[key]
        name = ISO_KEYS.get(key) or SUMMARY_KEYS[key]
        limits.append(Limit(key, name, v, u, v))
    if not limits:
        raise RecipeError(f"{at}: tolerance: no limit given: write form: \"3/A(B/C)\" or a plain limit "
                          f"({', '.join(PLAIN)})")
    return ToleranceSpec(tuple(limits), form, spec_unit, wl, rule, plain)


__all__ += ["AREAL", "KINDS", "DEFAULT_WAVELENGTH_NM"]

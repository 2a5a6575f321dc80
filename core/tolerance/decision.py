"""Decisions of conformity with the drawing's limits (docs/tolerance.md, "Verdicts").

Every limit of ISO 10110-5 is an upper limit (a PV or an RMS; for the sagitta deviation a bound on
|A|, i.e. −L ≤ A ≤ L, which for an interval symmetric about A is the same comparison on |A|).

- ``guarded`` (the default; ISO 14253-1:2017, guard band = U95 on both sides):
  ``conforms`` only when value + U95 ≤ limit, ``does not conform`` only when value − U95 > limit,
  else ``undecided``. An item with no uncertainty (the recipe has no ``uncertainty:`` block) cannot be
  proved either way: ``undecided``, with the note NO_UNCERTAINTY — an accredited laboratory states
  conformity with its uncertainty or says which rule it used (ISO/IEC 17025:2017 §7.8.6).
- ``simple`` (simple acceptance, ILAC-G8:09/2019 §4.2.1, "binary statement, w = 0"): the value alone
  against the limit — conforms when value ≤ limit, else does not conform. U95 is still reported.

Overall: ``does not conform`` if any item does not, ``conforms`` if every item does, else ``undecided``.
"""
from __future__ import annotations

import math

CONFORMS, NOT, UNDECIDED = "conforms", "does not conform", "undecided"
RULES = {
    "guarded": "ISO 14253-1:2017 decision rule with guard band U95: conforms when value + U95 ≤ limit, "
               "does not conform when value − U95 > limit, else undecided",
    "simple": "simple acceptance (ILAC-G8:09/2019 §4.2.1): the value alone against the limit; the "
              "measurement uncertainty is not taken into account",
}
NO_UNCERTAINTY = "no uncertainty: add an uncertainty: block, or rule: simple"
#: relative slack of the comparisons, for the rounding of a unit conversion (fringes ↔ µm) only
_EPS = 1e-12

UNIT_LABELS = {"fringes": "fr", "um": "µm", "nm": "nm", "urad": "µrad"}


def item_verdict(value: float | None, U: float | None, limit: float, rule: str,
                 interval: tuple[float, float] | None = None) -> tuple[str, str | None]:
    """(verdict, note) of one upper limit; ``value`` is the compared magnitude. ``interval``: the 95 %
    interval of that magnitude when the uncertainty gives one — the guard band is its ends, not
    value ± U95 (the interval of an RMS, a PV or PVr is not centred on its value: ± U95 passed a
    limit the interval held, and failed another)."""
    if value is None or not math.isfinite(value):
        return UNDECIDED, "not computed on these points"
    slack = _EPS * max(abs(limit), abs(value), 1e-300)
    if rule == "simple":
        return (CONFORMS if value <= limit + slack else NOT), None
    if U is None or not math.isfinite(U):
        return UNDECIDED, NO_UNCERTAINTY + ("; the value alone exceeds the limit" if value > limit + slack
                                            else "")
    lo, hi = interval if interval is not None else (value - U, value + U)
    if hi <= limit + slack:
        return CONFORMS, None
    if lo > limit + slack:
        return NOT, None
    return UNDECIDED, "the 95 % interval holds the limit"


def overall(verdicts) -> str:
    verdicts = list(verdicts)
    if any(v == NOT for v in verdicts):
        return NOT
    if verdicts and all(v == CONFORMS for v in verdicts):
        return CONFORMS
    return UNDECIDED


def _g(v: float, digits: int = 3) -> str:
    return f"{v:.{digits}g}"


def item_text(item: dict) -> str:
    """"irregularity B 0.62 ± 0.05 fr > 0.5 fr"."""
    unit = UNIT_LABELS.get(item["unit"], item["unit"])
    if item.get("value") is None:
        return f"{item['name']} not computed (limit {_g(item['limit'])} {unit})"
    val = _g(item["value"]) + (f" ± {_g(item['U95'], 2)}" if item.get("U95") is not None else "")
    rel = {CONFORMS: "≤", NOT: ">"}.get(item["verdict"], "vs")
    return f"{item['name']} {val} {unit} {rel} {_g(item['limit'])} {unit}"


def summary_text(verdict: str, items: list[dict]) -> str:
    """One line for a terminal or a status bar: the verdict and the items that decided it."""
    if verdict == CONFORMS:
        # the item nearest its limit says how much room there is
        def share(i):
            return (i["value"] + (i.get("U95") or 0.0)) / i["limit"] if i["limit"] > 0 else math.inf
        worst = max(items, key=share)
        return f"conforms: {len(items)} of {len(items)} items, nearest its limit {item_text(worst)}"
    deciding = [i for i in items if i["verdict"] == verdict]
    text = "; ".join(item_text(i) for i in deciding[:3])
    if len(deciding) > 3:
        text += f"; and {len(deciding) - 3} more"
    notes = sorted({i["note"] for i in deciding if i.get("note")})
    if verdict == UNDECIDED and notes:
        text += " (" + "; ".join(notes) + ")"
    return f"{verdict}: {text}"

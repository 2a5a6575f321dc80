"""Decisions of conformity with the drawing's limits (docs/tolerance.md, "Verdicts").

Every limit of ISO 10110-5 is an upper limit (a PV or an RMS; for the sagitta deviation a bound on
|A|, i.e. −L ≤ A ≤ L, which for an interval symmetric about A is the same comparison on |A|).

- ``guarded`` (the default; ISO 14253-1:2017, guard band = the expanded uncertainty): ``conforms``
  only when the upper end of the value's 95 % coverage interval ≤ limit, ``does not conform`` only
  when its lower end > limit, else ``undecided``. The interval is the Monte Carlo's (not centred on
  the value for an RMS, a PV or PVr); value ± U95 where no interval is given. An item with no uncertainty (the recipe has no ``uncertainty:`` block) cannot be
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
    "guarded": "ISO 14253-1:2017 decision rule with the expanded uncertainty as guard band: conforms "
               "when the upper end of the value's 95 % coverage interval ≤ limit, does not conform when "
               "its lower end > limit, else undecided (the interval is value ± U95 when symmetric)",
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


def _limit(v: float) -> str:
    """A drawing's limit as it was written (0.17225 µm, 172.25 nm, 0.1234566 µm), not rounded to 3
    digits — "0.172 µm > 0.172 µm" read as a contradiction (a review): 6 significant digits, or the
    shortest text that reads back to it where that is no longer (up to 10 digits: a limit converted
    from fringes keeps its 10)."""
    short = f"{v:.6g}"
    if float(short) == v:
        return short
    exact = repr(float(v))
    return exact if len(exact.lstrip("-").replace(".", "").lstrip("0")) <= 10 else f"{v:.10g}"


def _value_beside(v: float, limit: float) -> str:
    """A value with 3 significant digits, or as many more as it takes to stand on its own side of
    ``limit`` ("0.1723 µm > 0.17225 µm", not "0.172 µm > 0.17225 µm")."""
    lim = float(_limit(limit))
    for digits in range(3, 18):
        shown = float(_g(v, digits))
        if (shown > lim) == (v > limit) and (shown < lim) == (v < limit):
            return _g(v, digits)
    return repr(v)


def item_text(item: dict) -> str:
    """"irregularity B 0.620 ± 0.050 fr > 0.5 fr": U95 with two significant digits and the value to
    the same decimal place (GUM §7.2.6, as core.statement.with_uncertainty); the 95 % interval too
    when it is not value ± U95 to that rounding — it is what the verdict compares (module doc)."""
    from ..statement import _decimals

    unit = UNIT_LABELS.get(item["unit"], item["unit"])
    if item.get("value") is None:
        return f"{item['name']} not computed (limit {_limit(item['limit'])} {unit})"
    U = item.get("U95")
    if U is not None and math.isfinite(U):
        d = _decimals(U)
        val = f"{item['value']:.{d}f} ± {U:.{d}f}"
        iv = item.get("interval95")
        if iv is not None and all(math.isfinite(b) for b in iv):
            lo, hi = (f"{b:.{d}f}" for b in iv)
            if (lo, hi) != (f"{item['value'] - U:.{d}f}", f"{item['value'] + U:.{d}f}"):
                val += f" (95 % interval {lo} … {hi})"
    else:
        val = _value_beside(item["value"], item["limit"])
    rel = {CONFORMS: "≤", NOT: ">"}.get(item["verdict"], "vs")
    return f"{item['name']} {val} {unit} {rel} {_limit(item['limit'])} {unit}"


def summary_text(verdict: str, items: list[dict]) -> str:
    """One line for a terminal or a status bar: the verdict and the items that decided it."""
    if verdict == CONFORMS:
        # the item nearest its limit says how much room there is
        def share(i):  # the interval's upper end (what the guarded rule compares) over the limit
            top = i["interval95"][1] if i.get("interval95") else i["value"] + (i.get("U95") or 0.0)
            return top / i["limit"] if i["limit"] > 0 else math.inf
        worst = max(items, key=share)
        return f"conforms: {len(items)} of {len(items)} items, nearest its limit {item_text(worst)}"
    deciding = [i for i in items if i["verdict"] == verdict]
    text = "; ".join(item_text(i) for i in deciding[:3])
    if len(deciding) > 3:
        text += f"; and {len(deciding) - 3} more"
    # each clause of the items' notes once: "no uncertainty: …" stood twice beside "…; the value
    # alone exceeds the limit" (a review)
    clauses = []
    for note in sorted({i["note"] for i in deciding if i.get("note")}):
        for clause in note.split("; "):
            if clause not in clauses:
                clauses.append(clause)
    if verdict == UNDECIDED and clauses:
        text += " (" + "; ".join(clauses) + ")"
    return f"{verdict}: {text}"

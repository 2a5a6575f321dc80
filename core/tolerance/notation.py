"""The surface form tolerance as written on a drawing, ISO 10110-5:2015 (docs/tolerance.md):

    3/A(B/C)                        A sagitta deviation, B irregularity, C rotationally symmetric
    3/A(B)   3/-(B/C)   3/A(-/C)    irregularity (each a maximum PV); '-' = not toleranced
    3/A(B/C) RMSi < D               RMSt, RMSi, RMSa: maximum RMS values (several, separated by ';')
    3/2(0.5/0.2) RMSi < 0.05; λ = 632.8 nm     the test wavelength (``lambda =`` also reads)

A hand-written reader (not a regular expression) so that a string it cannot read is refused with the
1-based position of the first character it could not take and what it expected there.
"""
from __future__ import annotations

from dataclasses import dataclass, field

#: the RMS kinds of ISO 10110-5:2015 (t: total, i: irregularity, a: non-rotationally symmetric)
RMS_KINDS = ("t", "i", "a")


#: ASCII digits only: str.isdigit takes "²" too, which float() refuses (a review: an internal error)
_DIGITS = frozenset("0123456789")


@dataclass(frozen=True)
class Form:
    """A parsed ``3/A(B/C) RMSx < D`` string: the limits in the string's unit (None: not toleranced)."""

    text: str
    sag: float | None = None
    irr: float | None = None
    rsi: float | None = None
    rms: dict = field(default_factory=dict)  # "t"/"i"/"a" → limit
    wavelength_nm: float | None = None


class NotationError(ValueError):
    """The string's 1-based ``position``, the character there (None at the end) and what was expected."""

    def __init__(self, text: str, position: int, expected: str):
        self.text, self.position, self.expected = text, position, expected
        ch = text[position - 1] if position <= len(text) else None
        self.char = ch
        where = (f"at character {position} {ch!r}" if ch is not None
                 else f"at its end (character {position})")
        super().__init__(f"cannot read {text!r} {where}: expected {expected}")


class _Reader:
    def __init__(self, text: str):
        self.t = text
        self.i = 0

    # -- primitives ------------------------------------------------------------------------------
    def ws(self) -> None:
        while self.i < len(self.t) and self.t[self.i].isspace():
            self.i += 1

    def peek(self, s: str, fold: bool = False) -> bool:
        got = self.t[self.i:self.i + len(s)]
        return (got.lower() == s.lower()) if fold else got == s

    def take(self, s: str, fold: bool = False) -> bool:
        if self.peek(s, fold):
            self.i += len(s)
            return True
        return False

    def fail(self, expected: str, at: int | None = None):
        raise NotationError(self.t, (self.i if at is None else at) + 1, expected)

    def number(self) -> float | None:
        """A number written 2, 0.5, .5 or 2. ; None (nothing taken) when none starts here."""
        t, j = self.t, self.i
        while j < len(t) and t[j] in _DIGITS:
            j += 1
        whole = j > self.i
        if j < len(t) and t[j] in ".,":
            if t[j] == ",":  # a decimal comma (written on many drawings) is refused with its place
                if whole and j + 1 < len(t) and t[j + 1] in _DIGITS:
                    self.i = j
                    self.fail("a decimal point '.' (not a comma)")
                j_end = j
            else:
                k = j + 1
                while k < len(t) and t[k] in _DIGITS:
                    k += 1
                if k == j + 1 and not whole:
                    return None
                j_end = k
        else:
            j_end = j
        if j_end == self.i:
            return None
        v = float(t[self.i:j_end])
        self.i = j_end
        return v

    def limit(self, what: str) -> float | None:
        """A number or '-' (not toleranced)."""
        self.ws()
        if self.take("-"):
            return None
        v = self.number()
        if v is None:
            self.fail(f"{what}: a number (e.g. 0.5) or '-' (not toleranced)")
        return v


def parse_form(text: str) -> Form:
    """The Form of ``text``; NotationError naming the first character that cannot be read."""
    r = _Reader(text)
    r.ws()
    if not r.take("3"):
        r.fail("the code number 3 (ISO 10110-5 surface form tolerance: 3/A(B/C))")
    r.ws()
    if not r.take("/"):
        r.fail("'/' after the code number 3")
    sag = irr = rsi = None
    sag_only = False  # an A with no (B/C) group yet: '(' may still come
    r.ws()
    if not (r.peek("RMS", fold=True)):
        sag = r.limit("the sagitta deviation A")
        r.ws()
        if r.take("("):
            irr = r.limit("the irregularity B")
            r.ws()
            if r.take("/"):
                rsi = r.limit("the rotationally symmetric irregularity C")
                r.ws()
                if not r.take(")"):
                    r.fail("')' after C")
            elif not r.take(")"):
                r.fail("'/' or ')' after B")
        else:
            sag_only = True
    rms: dict[str, float] = {}
    wavelength = None
    first = True
    while True:
        r.ws()
        if r.i >= len(r.t):
            break
        if not first or r.peek(";"):
            if not r.take(";") and not first:
                r.fail("';' between items, or the end")
            r.ws()
        first, group_may, sag_only = False, sag_only, False
        start = r.i
        if r.take("RMS", fold=True):
            if r.i >= len(r.t) or r.t[r.i].lower() not in RMS_KINDS:
                r.fail("t, i or a after RMS (RMSt, RMSi, RMSa)")
            kind = r.t[r.i].lower()
            r.i += 1
            if kind in rms:
                r.fail(f"RMS{kind} once only (it is given twice)", at=start)
            r.ws()
            if not (r.take("<=") or r.take("<") or r.take("≤")):
                r.fail(f"'<' after RMS{kind}")
            r.ws()
            v = r.number()
            if v is None:
                r.fail(f"the limit of RMS{kind} (a number, e.g. 0.05)")
            rms[kind] = v
        elif r.take("λ") or r.take("lambda", fold=True):
            if wavelength is not None:
                r.fail("the wavelength once only (it is given twice)", at=start)
            r.ws()
            if not r.take("="):
                r.fail("'=' after λ")
            r.ws()
            v = r.number()
            if v is None:
                r.fail("the wavelength in nm (a number, e.g. 632.8)")
            r.ws()
            if not r.take("nm"):
                r.fail("'nm' after the wavelength")
            if not v > 0:
                r.fail("a wavelength > 0 nm", at=start)
            wavelength = v
        else:
            r.fail(("'(' B/C ')', " if group_may else "") + "RMSt, RMSi or RMSa < D, λ = … nm, or the end")
    if sag is None and irr is None and rsi is None and not rms:
        raise NotationError(text, len(text) + 1, "a limit: every quantity is '-' (none is toleranced)")
    return Form(text, sag, irr, rsi, rms, wavelength)

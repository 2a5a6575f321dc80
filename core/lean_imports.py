"""What a batch process leaves out as it imports its libraries: text that only ``help()`` shows.

scipy ≥ 1.15 decorates each function of its array-API table with ``xp_capabilities``
(``scipy/_lib/_array_api.py``), which parses the function's whole docstring with numpydoc's
``FunctionDoc`` *as the module is imported*, to append a "supported backends" table to its Notes.
Here that is 0.35–0.45 s of the 0.75–1.05 s it takes to import scipy.spatial, linalg, ndimage,
interpolate, optimize, special, signal and fft — paid by every batch process and pool worker for text
nobody reads there (issue 17; benchmarks/README.md "scipy's docstring tables").

``skip_scipy_capability_notes`` has the decorator keep each docstring as it is written instead. The
functions themselves, their signatures and every result are unchanged (the decorator returns the
function it was given either way; tests/test_speed_imports.py compares a batch's outputs with and
without). Only batch processes call it (core/cli.py, core/executors.py); the window, notebooks and
the Python API import scipy untouched, so ``help()`` there shows scipy's tables.

Defensive by design: on a scipy without the hook this does nothing, and anything the decorator asks
of the parsed docstring beyond the two uses it makes today (``doc["Notes"]``, ``str(doc)``) is
answered by a real parse, so a future scipy can only lose the saving, not fail to import.
"""
from __future__ import annotations

import sys


class _UnparsedDoc:
    """Stands in for numpydoc's ``FunctionDoc(f)`` inside scipy's ``xp_capabilities``: any section is
    an empty list to append to (the note appended is dropped) and ``str()`` gives a signature line
    (which the decorator cuts off) followed by the docstring as written."""

    _real = None  # the FunctionDoc class replaced, for anything else asked (set by the patch)

    def __init__(self, func, *args, **kwargs):
        self._func, self._args, self._kwargs = func, args, kwargs

    def __getitem__(self, section):
        return []

    def __str__(self):
        return "\n" + (getattr(self._func, "__doc__", None) or "")

    def __getattr__(self, name):  # a use the decorator did not make when this was written
        return getattr(type(self)._real(self._func, *self._args, **self._kwargs), name)


def skip_scipy_capability_notes() -> bool:
    """Have scipy's ``xp_capabilities`` decorator leave docstrings unparsed in this process (modules
    imported afterwards). True when the hook was found and set; False on a scipy without it (older or
    newer than this was written for) — then nothing is changed."""
    import importlib

    try:
        xp = importlib.import_module("scipy._lib._array_api")
    except Exception:  # noqa: BLE001 — no scipy, or its layout changed: nothing to save
        return False
    real = getattr(xp, "FunctionDoc", None)
    if real is None or not callable(getattr(xp, "xp_capabilities", None)):
        return False
    if real is _UnparsedDoc:
        return True
    _UnparsedDoc._real = real
    xp.FunctionDoc = _UnparsedDoc
    return True


def scipy_notes_skipped() -> bool:
    """Whether this process's scipy docstrings are left unparsed (for tests and ``--debug`` readers)."""
    xp = sys.modules.get("scipy._lib._array_api")
    return xp is not None and getattr(xp, "FunctionDoc", None) is _UnparsedDoc

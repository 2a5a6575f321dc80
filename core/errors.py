"""The errors a user sees. Each carries one line that names the file, line, step or key at fault.

The CLI prints ``str(error)`` on one line (no traceback unless ``--debug``) and exits 2.
"""


class PointsProError(Exception):
    """Base of every error that is the user's input's fault (file, recipe, parameter, data)."""


class InputError(PointsProError):
    """A data file that cannot be read: missing, empty, non-numeric, wrong column count, NaN..."""


class RecipeError(PointsProError):
    """A recipe that cannot be run: unknown step, unknown/mistyped key, out-of-range value."""


class DomainError(PointsProError):
    """Points outside a nominal surface's domain (e.g. the conic's square root turns negative)."""


class StepError(PointsProError):
    """A step that cannot process this cloud (too few points, ill-posed fit...)."""


class InternalError(PointsProError):
    """A bug — in a step (ours or a third party's) or a library under it — met while processing one
    input. It fails that input alone, with one line naming the input and the step and "please
    report"; the traceback is kept (``summary.json``, ``--debug``). Not the user's fault, but the
    batch goes on exactly as for one."""


class Cancelled(Exception):
    """Raised by ``ctx.progress.check()`` when the user cancelled. Not an error of the input."""

"""Atomic writes: write under a temporary name in the same folder, then rename into place.

A crash or kill never leaves a half-written file that looks complete (README "Batch"; docs/conventions.md "Errors").

The temporary file or folder is created with the modes any other tool's output gets — 0o666 for a
file, 0o777 for a folder, less the process umask (``-rw-r--r--`` and ``drwxr-xr-x`` under the usual
umask 022) — and keeps them through the rename. ``tempfile.mkstemp``/``mkdtemp`` would give 0600 and
0700, private to the user, which a colleague or a results share cannot read. The kernel applies the
umask itself (``os.open(..., 0o666)``, ``os.mkdir(..., 0o777)``), so it is never read nor changed
here: no ``os.umask`` round trip, which is process-wide and races with other threads.
"""
from __future__ import annotations

import contextlib
import os
import secrets
import shutil
from pathlib import Path

from ..pathnames import resolved

_TRIES = 100


def _temp_name(path: Path, suffix: str) -> Path:
    return path.parent / f".{path.name}.{secrets.token_hex(4)}{suffix}"


def make_temp_file(path: Path, suffix: str = ".partial") -> Path:
    """Create an empty, new file beside ``path`` (mode 0o666 less the umask) and return its path."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(_TRIES):
        tmp = _temp_name(path, suffix)
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(f"{path.parent}: no free temporary name for {path.name}")  # pragma: no cover


def make_temp_dir(path: Path, suffix: str = ".partial") -> Path:
    """Create a new, empty folder beside ``path`` (mode 0o777 less the umask) and return its path."""
    for _ in range(_TRIES):
        tmp = _temp_name(path, suffix)
        try:
            os.mkdir(tmp, 0o777)
        except FileExistsError:
            continue
        return tmp
    raise FileExistsError(f"{path.parent}: no free temporary name for {path.name}")  # pragma: no cover


class InputPlaces:
    """Where the inputs are: each input's resolved path and every folder above it, mapped to the
    input (the first one given, where several share a folder). A batch asks "is this output folder
    an input, or does it hold one?" once per input; resolving every input for each of them was
    N² path resolutions — 200 inputs took 0.65 s here (1.6 s on a 16-core machine's slower cores)
    before the first input started, a 1,000-input night ~16 s (benchmarks/README.md, issue 17)."""

    def __init__(self, inputs=()):
        self._where: dict[Path, Path] = {}
        for p in inputs:
            pr = resolved(p)
            for place in (pr, *pr.parents):
                self._where.setdefault(place, Path(p))

    def held_by(self, resolved: Path) -> Path | None:
        """The input that is ``resolved`` (a resolved path) or lies inside it; None when none does."""
        return self._where.get(resolved)


def why_not_replace(target: Path, marker: str, inputs=()) -> tuple[str, Path | None] | None:
    """Why ``atomic_dir`` must not replace the folder ``target`` as a whole (it swaps the old one out
    and deletes it): ("input", p) when it is or holds the input ``p``; ("file", None) when it is a
    file or a link; ("foreign", None) when it is a folder with something in it but no ``marker``
    (report.json, explain.json: not an earlier output of ours); ("extra", name) when it is an earlier
    output that holds an entry its marker's ``files`` list does not name. None when it may be
    replaced. The
    callers (the batch's folders, explain's --out) word the refusal."""
    places = inputs if isinstance(inputs, InputPlaces) else InputPlaces(inputs)
    held = places.held_by(resolved(target))
    if held is not None:
        return "input", held
    target = Path(target)
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        return "file", None
    if target.is_dir() and not (target / marker).is_file() and any(target.iterdir()):
        return "foreign", None
    if target.is_dir() and (target / marker).is_file() and not _is_ours(target / marker):
        return "foreign", None  # a file of that name that is no output of ours (a review: a user's
        # folder holding "report.json" with any text in it was replaced, notes and all)
    if target.is_dir():
        extra = _not_written_by_it(target, marker)
        if extra:
            return "extra", Path(extra)
    return None


#: keys a marker written by PointsPro always holds (report.json: core/report.py; explain.json:
#: core/explain/workflow.py), by the marker's name
_MARKER_KEYS = {"report.json": ("pointspro", "steps"), "explain.json": ("verdict", "gap_before")}


def _is_ours(marker: Path) -> bool:
    """Whether the marker file is one PointsPro wrote: JSON, an object, with the keys it always
    writes (_MARKER_KEYS)."""
    import json

    try:
        data = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and all(k in data for k in _MARKER_KEYS.get(marker.name, ()))


def _not_written_by_it(folder: Path, marker: str) -> str | None:
    """The first entry of ``folder`` that its marker (an earlier output's report.json, which lists
    the ``files`` it wrote) does not list — a user's notes put beside the results were deleted with
    the folder when the batch ran again (a review). None when all are listed, or when the marker
    lists nothing (an output from before it did)."""
    import json

    try:
        files = json.loads((folder / marker).read_text(encoding="utf-8")).get("files")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(files, list):
        return None
    listed = {str(f) for f in files} | {marker}
    return next((p.name for p in sorted(folder.iterdir()) if p.name not in listed), None)


def naming(e: BaseException, path) -> OSError | None:
    """A copy of the OSError ``e`` naming ``path``, where ``e`` names no file (a write's error: a full
    disk's "File too large" says which file it was writing — a review: "writing the outputs: File too
    large"); None otherwise (not an OSError, or it names its file)."""
    if not isinstance(e, OSError) or e.filename is not None:
        return None
    return OSError(e.errno, e.strerror or str(e), str(path))


@contextlib.contextmanager
def naming_errors(path):
    """Context: an OSError raised inside that names no file names ``path`` (``naming``)."""
    try:
        yield
    except OSError as e:
        renamed = naming(e, path)
        if renamed is None:
            raise
        raise renamed from e


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; on success rename it to ``path``, else remove it."""
    path = Path(path)
    tmp = make_temp_file(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as e:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        renamed = naming(e, path)  # Arrow's CSV writer on a full disk names no file
        if renamed is not None:
            raise renamed from e
        raise


@contextlib.contextmanager
def atomic_dir(path):
    """Yield a temporary folder beside ``path``; on success it replaces ``path`` as a whole.

    The output folder of an input is therefore either complete or absent (an older complete one is
    kept until the new one is ready): on Linux the new folder and the old one swap names in one step
    (``_exchange``), so no moment is without a complete folder — with two renames a process killed
    between them left none (a review).
    """
    path = Path(path)
    tmp = make_temp_dir(path)
    try:
        yield tmp
        if path.is_dir() and not path.is_symlink() and _exchange(tmp, path):
            shutil.rmtree(tmp, ignore_errors=True)  # the old folder, now under the temporary name
        elif path.exists():
            # two renames where the system cannot swap: a kill between them leaves the old folder as
            # .<name>.<hex>.old and no <name> — the batch's clean-up puts it back (batch.remove_leftovers)
            old = make_temp_dir(path, ".old")  # reserves a free name; the old folder moves there
            os.rmdir(old)
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        name = getattr(e, "filename", None) if isinstance(e, OSError) else None
        if name and str(name).startswith(str(tmp) + os.sep):
            # the file named where it was going, not in the temporary folder that is gone now
            raise OSError(e.errno, e.strerror or str(e), str(path) + str(name)[len(str(tmp)):]) from e
        raise


_RENAME_EXCHANGE = 2  # linux/fs.h
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap the names of ``a`` and ``b`` atomically (Linux ``renameat2(…, RENAME_EXCHANGE)``, glibc ≥
    2.28). False where the system or the file system cannot (another OS, an old kernel or libc, a
    file system without it): the caller renames twice instead."""
    import sys

    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    renameat2.restype = ctypes.c_int
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    import errno

    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.EXDEV):
        return False
    raise OSError(err, os.strerror(err), str(b))

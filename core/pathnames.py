"""Paths as the user named them: resolved without failing on a loop of symbolic links, and why one is
no regular file to read (core/io/formats.py read_cloud, core/recipe.py load_recipe)."""
from __future__ import annotations

import os
from pathlib import Path


def resolved(path) -> Path:
    """``Path(path).resolve()``; where a loop of symbolic links stops the resolution (Python before
    3.13 raises RuntimeError "Symlink loop from …", 3.13 an OSError) the absolute path as named. The
    file is then refused by whatever opens it ("…: a loop of symbolic links"), never as an internal
    error — an input that was a link to itself ended the batch with "internal error … please report
    it" (a review)."""
    p = Path(path)
    try:
        return p.resolve()
    except (RuntimeError, OSError):
        return Path(os.path.abspath(p))


def why_not_a_file(path, what: str = "data file") -> str | None:
    """Why ``path`` cannot be read as a ``what``, or None when it is a regular file: not found, a
    symbolic link to nothing or a loop of them, a folder, or not a regular file — a pipe or a device
    (/dev/null as a recipe read "recipe file not found", /dev/zero as data "empty file": a review)."""
    import errno
    import stat

    p = Path(path)
    try:
        mode = os.stat(p).st_mode
    except OSError as e:
        if e.errno == errno.ELOOP:
            return "a loop of symbolic links, no file at its end"
        if e.errno not in (errno.ENOENT, errno.ENOTDIR):  # a folder on the way that may not be entered
            return f"cannot be read ({e.strerror or e})"
        try:
            link = os.readlink(p) if p.is_symlink() else None
        except OSError:
            link = None
        if link is not None:  # the link is there; what it names (or a link further on) is not
            return f"a symbolic link to {link}, which leads to no file"
        return f"{what} not found" if what == "recipe file" else "file not found"
    if stat.S_ISDIR(mode):
        return f"is a folder, not a {what}"
    if not stat.S_ISREG(mode):
        kind = ("a pipe" if stat.S_ISFIFO(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
                else "a socket" if stat.S_ISSOCK(mode) else "not a file")
        return f"{kind}, not a regular file — give the {what} itself"
    return None

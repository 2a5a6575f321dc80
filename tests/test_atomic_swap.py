"""An output folder that replaces an earlier one never leaves a moment without a complete folder
(core/io/atomic.py atomic_dir; a review: with two renames, a worker killed between them left the
earlier output only as ``.<name>.<hex>.old``, which the batch's clean-up then deleted)."""
import os
import sys

import pytest

import pointspro.core.io.atomic as atomic
from pointspro.core.batch import cleanup_partials


def _earlier_output(out):
    folder = out / "part"
    folder.mkdir()
    (folder / "report.json").write_text('{"files": ["old.txt"]}', encoding="utf-8")
    (folder / "old.txt").write_text("earlier", encoding="utf-8")
    return folder


def _killed_after_first_rename(monkeypatch):
    real = os.replace
    calls = []

    def replace(a, b):
        real(a, b)
        calls.append((a, b))
        if len(calls) == 1:
            raise KeyboardInterrupt  # the process stopped right after this rename

    monkeypatch.setattr(atomic.os, "replace", replace)
    return calls


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="renameat2 is Linux's")
def test_the_new_folder_takes_the_old_ones_name_in_one_step(tmp_path, monkeypatch):
    folder = _earlier_output(tmp_path)
    calls = _killed_after_first_rename(monkeypatch)
    with atomic.atomic_dir(folder) as tmp:
        (tmp / "new.txt").write_text("new", encoding="utf-8")
    assert calls == []  # no rename pair: one exchange
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part"]
    assert (folder / "new.txt").read_text(encoding="utf-8") == "new"
    assert not (folder / "old.txt").exists()


def test_where_the_system_cannot_swap_the_cleanup_puts_the_earlier_output_back(tmp_path, monkeypatch):
    folder = _earlier_output(tmp_path)
    monkeypatch.setattr(atomic, "_exchange", lambda a, b: False)
    _killed_after_first_rename(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        with atomic.atomic_dir(folder) as tmp:
            (tmp / "new.txt").write_text("new", encoding="utf-8")
    monkeypatch.undo()
    left = sorted(p.name for p in tmp_path.iterdir())
    assert len(left) == 1 and left[0].startswith(".part.") and left[0].endswith(".old")  # the gap
    cleanup_partials(tmp_path, ["part"])  # as an interrupted batch or --resume runs it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part"]
    assert (folder / "old.txt").read_text(encoding="utf-8") == "earlier"


def test_a_set_aside_folder_whose_replacement_arrived_is_removed(tmp_path):
    folder = _earlier_output(tmp_path)
    stale = tmp_path / ".part.0123abcd.old"
    stale.mkdir()
    (stale / "old.txt").write_text("older", encoding="utf-8")
    assert cleanup_partials(tmp_path, ["part"]) == [stale.name]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part"]
    assert (folder / "old.txt").read_text(encoding="utf-8") == "earlier"


def test_of_two_set_aside_folders_the_complete_one_is_put_back(tmp_path):
    """An old folder whose deletion failed half-way (atomic_dir's fallback removes it with
    ignore_errors) beside a complete one: the one that still holds its report.json is put back, the
    other removed (a review: the first in the order of their random names was restored)."""
    half = tmp_path / ".part.00000000.old"
    half.mkdir()
    (half / "figure.png").write_bytes(b"x")
    whole = tmp_path / ".part.ffffffff.old"
    whole.mkdir()
    (whole / "report.json").write_text('{"files": []}', encoding="utf-8")
    cleanup_partials(tmp_path, ["part"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part"]
    assert (tmp_path / "part" / "report.json").is_file()

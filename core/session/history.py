"""Undo and redo for the window's model: snapshots of (recipe, displayed cloud), kept by reference.

Cheap: a Recipe is immutable (every edit returns a new one that shares the unchanged steps) and so
is a PointCloud, so a snapshot is two references, never a copy; the points the window's deletions
hide are one bit per point (``keep``, numpy.packbits: 1.6 MB at 12.6 million points).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..cloud import PointCloud
from ..recipe import Recipe

LIMIT = 100  # undo steps kept


@dataclass(frozen=True)
class Snapshot:
    recipe: Recipe
    shown: PointCloud | None
    #: np.packbits of the mask of ``shown``'s points displayed (None: all of them)
    keep: Any = None


class History:
    """Two stacks of snapshots. ``push`` before a change records the state it changes; ``undo`` and
    ``redo`` take the current state and return the one to go back (or forward) to."""

    def __init__(self, limit: int = LIMIT):
        self.limit = limit
        self._undo: list[Snapshot] = []
        self._redo: list[Snapshot] = []

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    def push(self, current: Snapshot) -> None:
        """A new change: ``current`` becomes undoable, what was undone cannot be redone any more."""
        self._undo.append(current)
        del self._undo[:-self.limit]
        self._redo.clear()

    def undo(self, current: Snapshot) -> Snapshot | None:
        if not self._undo:
            return None
        self._redo.append(current)
        return self._undo.pop()

    def redo(self, current: Snapshot) -> Snapshot | None:
        if not self._redo:
            return None
        self._undo.append(current)
        return self._redo.pop()

    def clear(self) -> None:
        self._undo.clear()
        self._redo.clear()

    def __len__(self) -> int:
        return len(self._undo)

    def __repr__(self) -> Any:
        return f"<History {len(self._undo)} undo, {len(self._redo)} redo>"

"""The window's model: a measurement, its recipe and the optician's edits, with undo and redo.

Qt-free (napari's rule: the model never imports Qt; the window subscribes to its events), so every
interaction is tested headless. Each deletion the optician makes is recorded as a `manual_edit` step
(indices of the input rows), so the saved recipe replays the same cleanup in `pointspro --batch`.

The recipe is a typed, immutable `Recipe`: each edit validates only what it changes (with the one
Registry of the session) and returns a new Recipe, so the undo history (session.history) keeps old
recipes and clouds by reference. Selections are core.session.selection's, files core.session.project's.

Events (``session.events``, core.events): opened, recipe, steps, ran, deleted, restored, undo, redo —
the model changed (``event.type`` says how) — and warning: something the optician must read although
no action failed (``event.value``, one line), e.g. a project that opened but whose recipe did not run.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..cloud import PointCloud
from ..errors import InputError, PointsProError, RecipeError
from ..events import EmitterGroup
from ..recipe import Recipe, load_yaml, make_step, parse_recipe
from ..registry import Registry
from . import project, selection
from .history import History, Snapshot

log = logging.getLogger(__name__)

#: events that say the model changed (the window redraws on each)
#: the note of the manual_edit steps the window's deletions make (Restore all drops those alone)
WINDOW_NOTE = "deleted in the window"
CHANGES = ("opened", "recipe", "steps", "ran", "deleted", "restored", "undo", "redo")
EVENTS = CHANGES + ("warning",)


class Session:
    def __init__(self, registry: Registry | None = None):
        self.input_path: Path | None = None
        self.input_cloud: PointCloud | None = None
        self.recipe: Recipe = Recipe([])
        # what the views display: ``_base`` less the points ``_keep`` drops (None: none dropped).
        # A deletion makes a new mask, never a copy of the cloud (the undo history keeps masks)
        self._base: PointCloud | None = None
        self._keep: np.ndarray | None = None
        self._shown: PointCloud | None = None  # _base.select(_keep), made when asked for
        self.last_result = None
        self.events = EmitterGroup(self, *EVENTS)
        self.history = History()
        self._registry = registry

    @property
    def registry(self) -> Registry:
        """The installed steps, read once per session (reading the entry points costs ~0.2 s)."""
        if self._registry is None:
            self._registry = Registry()
        return self._registry

    # -- what is shown ------------------------------------------------------------------------------
    @property
    def shown(self) -> PointCloud | None:
        """The displayed cloud (after the window's deletions), made on first use after a change:
        the views draw and select from ``view`` instead, without a copy per deletion."""
        if self._keep is None:
            return self._base
        if self._shown is None:
            self._shown = self._base.select(self._keep)
        return self._shown

    @shown.setter
    def shown(self, cloud: PointCloud | None) -> None:
        self._set_view(cloud, None)

    def _set_view(self, base: PointCloud | None, keep: np.ndarray | None) -> None:
        self._base, self._keep, self._shown = base, keep, None

    @property
    def view(self) -> tuple[PointCloud | None, np.ndarray | None]:
        """(cloud, keep): what is shown is ``cloud.select(keep)``; keep is a boolean mask over the
        cloud, or None when nothing of it is hidden. Both are never changed in place."""
        return self._base, self._keep

    @property
    def n_shown(self) -> int:
        if self._base is None:
            return 0
        return self._base.n if self._keep is None else int(np.count_nonzero(self._keep))

    # -- changes and undo -----------------------------------------------------------------------------
    def _snapshot(self) -> Snapshot:
        return Snapshot(self.recipe, self._base, None if self._keep is None else np.packbits(self._keep))

    def _restore(self, s: Snapshot) -> None:
        self.recipe = s.recipe
        keep = None
        if s.keep is not None:
            keep = np.unpackbits(s.keep, count=s.shown.n).view(bool)
        self._set_view(s.shown, keep)

    def _change(self, what: str, recipe: Recipe, value=None) -> None:
        """An undoable change of the recipe."""
        self.history.push(self._snapshot())
        self.recipe = recipe
        self.events[what](value)

    @property
    def can_undo(self) -> bool:
        return self.history.can_undo

    @property
    def can_redo(self) -> bool:
        return self.history.can_redo

    def undo(self) -> None:
        s = self.history.undo(self._snapshot())
        if s is not None:
            self._restore(s)
            self.events.undo()

    def redo(self) -> None:
        s = self.history.redo(self._snapshot())
        if s is not None:
            self._restore(s)
            self.events.redo()

    # -- data -----------------------------------------------------------------------------------------
    def open(self, path) -> int:
        """Read a measurement; on error nothing changes and the InputError says why. Returns how many
        of the window's deletions were dropped: they name rows of the measurement open before, and
        another file's same rows are other points (a review: a second part lost 96 points at the
        first part's row numbers, without a word). The recipe's own manual_edit steps (another
        note) stay; opening the same file again keeps the deletions."""
        from ..io import read_cloud

        cloud = read_cloud(Path(path), **self.recipe.input)  # the recipe's reader options
        other = self.input_path is not None and Path(path).resolve() != self.input_path.resolve()
        window_edits = [s for s in self.recipe.steps if s.id == "manual_edit"
                        and getattr(s.params, "note", None) == WINDOW_NOTE]
        if other and window_edits:
            self.recipe = self.recipe.with_steps([s for s in self.recipe.steps
                                                  if not any(s is w for w in window_edits)])
        self.input_path, self.input_cloud = Path(path), cloud
        # the same file again: shown less the deletions its recipe keeps, as Restore all shows it
        self._set_view(self.input_less_edits() if window_edits and not other else cloud, None)
        self.history.clear()
        self.events.opened(self.input_path)
        return len(window_edits) if other else 0

    def set_recipe(self, data: Recipe | dict, where: str = "recipe") -> None:
        """Replace the recipe (a Recipe, or a mapping validated whole first: on error nothing
        changes)."""
        recipe = data if isinstance(data, Recipe) else parse_recipe(data, where, self.registry)
        self._change("recipe", recipe)

    def load_recipe(self, path) -> None:
        from ..pathnames import why_not_a_file

        p = Path(path)
        why = why_not_a_file(p, "recipe file")
        if why is not None:
            raise RecipeError(f"{p}: {why}")
        self.set_recipe(load_yaml(p.read_text(encoding="utf-8"), str(p)), str(p))

    # -- pipeline editing ---------------------------------------------------------------------------
    @property
    def steps(self) -> list[dict]:
        """The steps as the recipe file writes them (``{id: non-default params}``, ``enabled: false``
        when disabled): a fresh list each time — editing it changes nothing; edit through the methods
        below (or read ``recipe.steps``, the typed steps)."""
        return [s.to_yaml_entry() for s in self.recipe.steps]

    def add_step(self, step_id: str, params: dict | None = None, at: int | None = None) -> None:
        """RecipeError naming the step (unknown) or the key (invalid value); nothing changes then."""
        position = (len(self.recipe.steps) if at is None else at) + 1
        step = make_step(step_id, params, self.registry, position)
        self._change("steps", self.recipe.inserted(step, at))

    def remove_step(self, i: int) -> None:
        self._change("steps", self.recipe.removed(i))

    def move_step(self, i: int, j: int) -> None:
        self._change("steps", self.recipe.moved(i, j))

    def set_params(self, i: int, params: dict) -> None:
        """New parameters for step i; RecipeError naming the key when a value is invalid."""
        self._change("steps", self.recipe.with_params(i, params, self.registry))

    def set_enabled(self, i: int, enabled: bool) -> None:
        self._change("steps", self.recipe.with_enabled(i, enabled))

    # -- running ------------------------------------------------------------------------------------
    def compute(self, upto: int | None = None, progress=None):
        """Run the recipe (steps before ``upto``) on the input and return the result without changing
        the session — safe in a worker thread (it reads one snapshot of the recipe and the input,
        both immutable)."""
        from ..pipeline import run_pipeline

        recipe, cloud = self.recipe, self.input_cloud
        if cloud is None:
            raise InputError("open a measurement first")
        return run_pipeline(cloud, recipe, progress=progress, upto=upto)

    def accept(self, result) -> None:
        """Show a computed result. Not an undo step: Ctrl+Z right after a run undid the run — nothing
        on screen changed but the Report turned stale, and the deletion it was meant to undo took a
        second Ctrl+Z (a review). Undo goes back to the edit before it; the run's result then is stale
        and says so, as after any edit."""
        self.last_result = result
        self._set_view(result.cloud, None)
        self.events.ran(result)

    def run(self, upto: int | None = None, progress=None):
        """Run the recipe on the input; the result becomes what is shown."""
        result = self.compute(upto, progress)
        self.accept(result)
        return result

    # -- selection and cleanup ----------------------------------------------------------------------
    def select_rectangle(self, x0, x1, y0, y1) -> np.ndarray:
        return selection.rectangle(self.shown, x0, x1, y0, y1)

    def select_lasso(self, polygon) -> np.ndarray:
        return selection.lasso(self.shown, polygon)

    def select_threshold(self, channel: str, value: float, above: bool = True) -> np.ndarray:
        return selection.threshold(self.shown, channel, value, above)

    def delete(self, mask, note: str = WINDOW_NOTE) -> int:
        """Remove the selected points; recorded as a manual_edit step (their input rows).

        ``mask`` is over the shown cloud, or over ``view``'s cloud (what the views select in): the
        change is a new keep mask, not a copy of the cloud."""
        base, keep = self._base, self._keep
        if base is None:
            return 0
        mask = np.asarray(mask, dtype=bool)
        if mask.shape == (base.n,):  # over the view's cloud
            pos = np.flatnonzero(mask if keep is None else mask & keep)
        elif keep is not None and mask.shape == (self.n_shown,):  # over the shown cloud
            pos = np.flatnonzero(keep)[mask]
        else:
            raise InputError(f"the selection holds {mask.size:,} points, the shown cloud {self.n_shown:,}")
        n = int(pos.size)
        if n == 0:
            return 0
        rows = np.sort(base.index[pos])
        new_keep = np.ones(base.n, dtype=bool) if keep is None else keep.copy()
        new_keep[pos] = False
        step = self._manual_edit(rows, note)
        self.history.push(self._snapshot())
        # first, after the recipe's own leading manual edits: the step removes input rows, so every
        # step — the pose, the Zernike fit, the map — must run without them (put last, as it was, the
        # exported map.csv of a review's run still held four deleted spikes: map PV 16.9 µm for 3.9).
        # The views show the deletion at once; the steps' numbers change at the next run
        self.recipe = self.recipe.inserted(step, self._edit_position())
        self._set_view(base, new_keep)
        self.events.deleted(n)
        return n

    def _edit_position(self) -> int:
        """Where a deletion's manual_edit goes: after the leading manual_edit steps (0 when none)."""
        i = 0
        while i < len(self.recipe.steps) and self.recipe.steps[i].id == "manual_edit":
            i += 1
        return i

    def _manual_edit(self, rows: np.ndarray, note: str):
        """The manual_edit step removing ``rows`` (sorted, distinct input rows), in its compact form:
        runs of consecutive rows as ``remove_ranges`` pairs [first, last], the isolated rows in
        ``remove`` (a lasso over a map is whole stretches of raster rows: 10⁶ rows, a few thousand
        pairs; the autosave's YAML of 10⁶ numbers took 9–28 s). Its parameters are checked on a short
        stand-in and the rows set after: input rows are non-negative integers by construction
        (checked here), and validating 10⁶ integers one by one in Python cost 0.4 s a deletion."""
        import dataclasses

        if rows.size == 0 or rows[0] < 0:  # not input rows: the step's own validation says why
            return make_step("manual_edit", {"remove": rows.tolist(), "note": note}, self.registry,
                             len(self.recipe.steps) + 1)
        single, ranges = rows_to_ranges(rows)
        step = make_step("manual_edit", {"remove": [], "note": note}, self.registry,
                         len(self.recipe.steps) + 1)
        update = {"remove": single.tolist(), "remove_ranges": [tuple(r) for r in ranges.tolist()]}
        return dataclasses.replace(step, params=step.params.model_copy(update=update))

    def restore_all(self) -> None:
        """Drop the manual_edit steps deletions in the window made (undoable); a recipe's own edit with
        another note (the example's "probe slipped off the edge") stays — a review found Restore all
        dropping it with the window's deletions."""
        recipe = self.recipe.with_steps([s for s in self.recipe.steps if not (
            s.id == "manual_edit" and getattr(s.params, "note", None) == WINDOW_NOTE)])
        self.history.push(self._snapshot())
        self.recipe = recipe
        self._set_view(self.input_less_edits(), None)  # less the rows the recipe's own edits remove
        self.events.restored()

    def input_less_edits(self):
        """The measurement as read, less the rows the recipe's enabled manual_edit steps remove (the
        window's deletions and the recipe's own): the points as measured that the user keeps — what
        explain compares (a review: it read the file again, spikes deleted in the window and all).
        None when nothing is open."""
        view = self.input_cloud
        if view is None:
            return None
        from ..step import Context

        for st in self.recipe.steps:
            if st.id == "manual_edit" and st.enabled:
                view = self.registry.load("manual_edit")().run(view, st.params, Context()).cloud
        return view

    # -- projects -----------------------------------------------------------------------------------
    def project_text(self, project_path: Path) -> str:
        return project.project_text(self.recipe, self.input_path, project_path)

    def save_project(self, path) -> None:
        project.write_project(Path(path), self.recipe, self.input_path)

    def save_recipe(self, path) -> None:
        """The recipe alone (what `pointspro --batch` replays), written atomically."""
        project.write_recipe(Path(path), self.recipe)

    def open_project(self, path, run: bool = True) -> None:
        """Open a project; a moved data file or a broken recipe is an error and nothing changes.

        A project with manual edits is run at once so the view shows the cleaned cloud. When that
        run fails the project stays open (its data and recipe are valid: the optician fixes the
        step in the window) and the reason is the ``warning`` event — it never passes silently.
        ``run=False`` (the window, which runs the recipe in its worker thread: a review measured a
        1 s freeze on the 4,680-point example, longer on larger clouds) shows the measurement less
        the manual edits' rows instead."""
        from ..io import read_cloud

        path = Path(path)
        data = project.load_project(path)
        recipe = parse_recipe(project.project_recipe(data), str(path), self.registry)
        data_path = project.project_data_file(path, data)
        cloud = read_cloud(data_path, **recipe.input)  # the recipe's reader options
        self.input_path, self.input_cloud = data_path, cloud
        self.recipe = recipe
        self.history.clear()
        self.shown = cloud
        if not run:
            self._set_view(self.input_less_edits(), None)
        self.events.opened(data_path)
        if run and any(s.id == "manual_edit" for s in recipe.steps):
            try:
                self.run()
            except PointsProError as e:
                msg = (f"{path}: the project opened, but its recipe did not run, so its deleted points "
                       f"are still shown — {e}")
                log.warning("%s", msg)
                self.events.warning(msg)

    def export_cloud(self, path) -> None:
        from ..io import write_cloud

        if self.shown is None:
            raise InputError("nothing to export")
        write_cloud(self.shown, Path(path))


def rows_to_ranges(rows) -> tuple[np.ndarray, np.ndarray]:
    """(single rows, [first, last] pairs) of sorted, distinct input rows, as manual_edit's ``remove``
    and ``remove_ranges``: each run of two or more consecutive rows is one pair, both ends included,
    the other rows stay single — by np.diff, no Python loop per row."""
    rows = np.asarray(rows, dtype=np.int64).ravel()
    if rows.size == 0:
        return rows, np.empty((0, 2), dtype=np.int64)
    brk = np.flatnonzero(np.diff(rows) != 1) + 1
    first = np.concatenate(([0], brk))
    last = np.concatenate((brk, [rows.size])) - 1
    run = last > first
    return rows[first[~run]], np.column_stack([rows[first[run]], rows[last[run]]])

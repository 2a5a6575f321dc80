"""The window's model: a measurement, its recipe and the optician's edits, with undo and redo.

Qt-free (napari's rule: the model never imports Qt; the window subscribes to its events), so every
interaction is tested headless. Each deletion the optician makes is recorded as a `manual_edit` step
(indices of the input rows), so the saved recipe replays the same cleanup in `pointspro --batch`.
Undo/redo keep snapshots of (recipe, displayed cloud) by reference — cheap: every edit builds a new
recipe mapping instead of changing the old one in place, and clouds are immutable.

Project file (YAML text): {pointspro_project: 1, input: <data file, relative to the project>,
recipe: <the recipe mapping>}.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .cloud import PointCloud
from .errors import InputError, PointsProError, RecipeError

PROJECT_VERSION = 1


@dataclass
class _State:
    recipe: dict
    shown: PointCloud | None


@dataclass
class Session:
    input_path: Path | None = None
    input_cloud: PointCloud | None = None
    recipe: dict = field(default_factory=lambda: {"pointspro": 1, "steps": []})
    shown: PointCloud | None = None          # what the views display
    last_result: object = None
    listeners: list[Callable[[str], None]] = field(default_factory=list)
    _undo: list[_State] = field(default_factory=list)
    _redo: list[_State] = field(default_factory=list)

    # -- events -------------------------------------------------------------------------------------
    def _emit(self, what: str) -> None:
        for f in list(self.listeners):
            f(what)

    def _push(self) -> None:
        self._undo.append(_State(self.recipe, self.shown))
        del self._undo[:-100]
        self._redo.clear()

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    def undo(self) -> None:
        if self._undo:
            self._redo.append(_State(self.recipe, self.shown))
            s = self._undo.pop()
            self.recipe, self.shown = s.recipe, s.shown
            self._emit("undo")

    def redo(self) -> None:
        if self._redo:
            self._undo.append(_State(self.recipe, self.shown))
            s = self._redo.pop()
            self.recipe, self.shown = s.recipe, s.shown
            self._emit("redo")

    # -- data -----------------------------------------------------------------------------------------
    def open(self, path) -> None:
        """Read a measurement; on error nothing changes and the InputError says why."""
        from .io import read_cloud

        cloud = read_cloud(Path(path))
        self.input_path, self.input_cloud, self.shown = Path(path), cloud, cloud
        self._undo.clear()
        self._redo.clear()
        self._emit("opened")

    def set_recipe(self, data: dict, where: str = "recipe") -> None:
        """Replace the recipe (validated whole first: on error nothing changes)."""
        from .recipe import _plain

        data = _plain(data)  # the YAML loader's line-numbered mappings → plain dicts (savable)
        self._validate(data, where)
        self._push()
        self.recipe = data
        self._emit("recipe")

    def load_recipe(self, path) -> None:
        from .recipe import load_yaml

        p = Path(path)
        if not p.is_file():
            raise RecipeError(f"{p}: recipe file not found")
        self.set_recipe(load_yaml(p.read_text(encoding="utf-8"), str(p)), str(p))

    def _validate(self, data, where="recipe"):
        from .recipe import parse_recipe

        return parse_recipe(data, where)

    # -- pipeline editing ---------------------------------------------------------------------------
    @property
    def steps(self) -> list[dict]:
        return self.recipe.setdefault("steps", [])

    def _edit(self, new_steps: list, what: str) -> None:
        data = {**self.recipe, "steps": new_steps}
        self._validate(data)
        self._push()
        self.recipe = data
        self._emit(what)

    def add_step(self, step_id: str, params: dict | None = None, at: int | None = None) -> None:
        steps = list(self.steps)
        steps.insert(len(steps) if at is None else at, {step_id: dict(params or {})})
        self._edit(steps, "steps")

    def remove_step(self, i: int) -> None:
        steps = list(self.steps)
        del steps[i]
        self._edit(steps, "steps")

    def move_step(self, i: int, j: int) -> None:
        steps = list(self.steps)
        steps.insert(j, steps.pop(i))
        self._edit(steps, "steps")

    def set_params(self, i: int, params: dict) -> None:
        """New parameters for step i; RecipeError naming the key when a value is invalid."""
        steps = list(self.steps)
        entry = dict(steps[i])
        sid = next(k for k in entry if k != "enabled")
        entry[sid] = dict(params)
        steps[i] = entry
        self._edit(steps, "steps")

    def set_enabled(self, i: int, enabled: bool) -> None:
        steps = list(self.steps)
        entry = dict(steps[i])
        if enabled:
            entry.pop("enabled", None)
        else:
            entry["enabled"] = False
        steps[i] = entry
        self._edit(steps, "steps")

    # -- running ------------------------------------------------------------------------------------
    def compute(self, upto: int | None = None, progress=None):
        """Run the recipe (steps before ``upto``) on the input and return the result without changing
        the session — safe in a worker thread (it reads one snapshot of the recipe and the input)."""
        from .pipeline import run_pipeline

        recipe_data, cloud = self.recipe, self.input_cloud
        if cloud is None:
            raise InputError("open a measurement first")
        recipe = self._validate(recipe_data)
        return run_pipeline(cloud, recipe, progress=progress, upto=upto)

    def accept(self, result) -> None:
        """Show a computed result (undoable)."""
        self._push()
        self.last_result = result
        self.shown = result.cloud
        self._emit("ran")

    def run(self, upto: int | None = None, progress=None):
        """Run the recipe on the input; the result becomes what is shown."""
        result = self.compute(upto, progress)
        self.accept(result)
        return result

    # -- selection and cleanup ----------------------------------------------------------------------
    def select_rectangle(self, x0, x1, y0, y1) -> np.ndarray:
        return in_rectangle(self.shown.x, self.shown.y, x0, x1, y0, y1)

    def select_lasso(self, polygon) -> np.ndarray:
        from pointspro.plugins.aperture import points_in_polygon

        return points_in_polygon(self.shown.x, self.shown.y, np.asarray(polygon, dtype=np.float64))

    def select_threshold(self, channel: str, value: float, above: bool = True) -> np.ndarray:
        c = self.shown
        v = c.z if channel == "z" else c[channel]
        return v > value if above else v < value

    def delete(self, mask, note: str = "deleted in the window") -> int:
        """Remove the selected points; recorded as a manual_edit step (their input rows)."""
        mask = np.asarray(mask, dtype=bool)
        n = int(mask.sum())
        if n == 0:
            return 0
        rows = np.sort(self.shown.index[mask]).tolist()
        steps = list(self.steps) + [{"manual_edit": {"remove": rows, "note": note}}]
        data = {**self.recipe, "steps": steps}
        self._validate(data)
        self._push()
        self.recipe = data
        self.shown = self.shown.select(~mask)
        self._emit("deleted")
        return n

    def restore_all(self) -> None:
        """Drop every manual_edit step (undoable)."""
        steps = [s for s in self.steps if "manual_edit" not in s]
        data = {**self.recipe, "steps": steps}
        self._validate(data)
        self._push()
        self.recipe, self.shown = data, self.input_cloud
        self._emit("restored")

    # -- projects -----------------------------------------------------------------------------------
    def project_text(self, project_path: Path) -> str:
        return project_text(self.recipe, self.input_path, project_path)

    def save_project(self, path) -> None:
        write_project(Path(path), self.recipe, self.input_path)

    def save_recipe(self, path) -> None:
        """The recipe alone (what `pointspro --batch` replays), written atomically."""
        import yaml

        from .io.atomic import atomic_path

        with atomic_path(Path(path)) as tmp:
            Path(tmp).write_text(yaml.dump(self.recipe, Dumper=_dumper(), sort_keys=False), encoding="utf-8")

    def open_project(self, path) -> None:
        """Open a project; a moved data file or a broken recipe is an error and nothing changes."""
        import yaml

        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: project file not found")
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except yaml.YAMLError as e:
            raise InputError(f"{path}: not a PointsPro project ({str(e).splitlines()[0]})") from None
        if not isinstance(data, dict) or data.get("pointspro_project") != PROJECT_VERSION:
            raise InputError(f"{path}: not a PointsPro project (no 'pointspro_project: 1')")
        recipe = data.get("recipe") or {"pointspro": 1, "steps": []}
        self._validate(recipe, str(path))
        inp = data.get("input")
        if inp is None:
            raise InputError(f"{path}: the project names no data file")
        data_path = (path.parent / inp) if not Path(inp).is_absolute() else Path(inp)
        if not data_path.is_file():
            raise InputError(f"{path}: its data file {data_path} was moved or deleted — put it back or "
                             "open the data and the recipe separately")
        from .io import read_cloud

        cloud = read_cloud(data_path)
        self.input_path, self.input_cloud = data_path, cloud
        self.recipe = recipe
        self._undo.clear()
        self._redo.clear()
        self.shown = cloud
        self._emit("opened")
        if any("manual_edit" in s for s in recipe.get("steps", [])):
            try:
                self.run()
            except PointsProError:
                pass

    def export_cloud(self, path) -> None:
        from .io import write_cloud

        if self.shown is None:
            raise InputError("nothing to export")
        write_cloud(self.shown, Path(path))


def in_rectangle(x, y, x0, x1, y0, y1) -> np.ndarray:
    """Mask of the points inside the axis-aligned rectangle (corners in any order, edges included):
    the map's rectangle in mm and the 3D view's in screen pixels."""
    lo_x, hi_x = sorted((x0, x1))
    lo_y, hi_y = sorted((y0, y1))
    return (x >= lo_x) & (x <= hi_x) & (y >= lo_y) & (y <= hi_y)


def _dumper():
    import yaml

    return getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml: 20× faster on long edit lists


def project_text(recipe: dict, input_path: Path | None, project_path: Path) -> str:
    """The project file's text: the data file relative to the project (absolute on another drive)."""
    import yaml

    inp = None
    if input_path is not None:
        try:
            inp = os.path.relpath(Path(input_path).resolve(), Path(project_path).resolve().parent)
        except ValueError:  # another drive
            inp = str(Path(input_path).resolve())
    return yaml.dump({"pointspro_project": PROJECT_VERSION, "input": inp, "recipe": recipe},
                     Dumper=_dumper(), sort_keys=False)


def write_project(path: Path, recipe: dict, input_path: Path | None) -> None:
    """Write a project atomically (a crash mid-write never leaves half a file). Used by save and by the
    window's autosave thread."""
    from .io.atomic import atomic_path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = project_text(recipe, input_path, path)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")

"""Project files: a measurement and its recipe saved together, and the recipe saved alone.

Project file (YAML text, read by the YAML 1.2 core schema as recipes are: core.yamlio):
{pointspro_project: 1, input: <data file, relative to the project>, recipe: <the recipe mapping>}.
Every file is written atomically (a crash mid-write never leaves half a file).
"""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError
from ..recipe import Recipe
from ..yamlio import dump_yaml, read_yaml_mapping

PROJECT_VERSION = 1


def _mapping(recipe: Recipe | dict) -> dict:
    return recipe.to_dict() if isinstance(recipe, Recipe) else recipe


def project_text(recipe: Recipe | dict, input_path: Path | None, project_path: Path) -> str:
    """The project file's text: the data file relative to the project (absolute on another drive)."""
    inp = None
    if input_path is not None:
        try:
            inp = os.path.relpath(Path(input_path).resolve(), Path(project_path).resolve().parent)
        except ValueError:  # another drive
            inp = str(Path(input_path).resolve())
    # libyaml's emitter (fast = True): 20× faster on long edit lists
    return dump_yaml({"pointspro_project": PROJECT_VERSION, "input": inp, "recipe": _mapping(recipe)},
                     fast=True, sort_keys=False)


def _write(path: Path, text: str) -> None:
    from ..io.atomic import atomic_path

    with atomic_path(Path(path)) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")


def write_project(path: Path, recipe: Recipe | dict, input_path: Path | None) -> None:
    """Write a project atomically. Used by save and by the window's autosave thread (a Recipe is
    immutable: the thread's snapshot cannot change under it)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write(path, project_text(recipe, input_path, path))


def write_recipe(path: Path, recipe: Recipe | dict) -> None:
    """The recipe alone (what `pointspro --batch` replays), written atomically."""
    _write(Path(path), dump_yaml(_mapping(recipe), fast=True, sort_keys=False))


def load_project(path: Path) -> dict:
    """A project file's mapping (YAML 1.2, lines remembered: core.yamlio); InputError saying why the
    file is not a project."""
    return read_yaml_mapping(path, "project", "pointspro_project", PROJECT_VERSION, InputError)


def project_recipe(data: dict) -> dict:
    """The recipe mapping of a loaded project (an empty recipe when it has none); not validated."""
    return data.get("recipe") or {"pointspro": 1, "steps": []}


def project_data_file(path: Path, data: dict) -> Path:
    """The measurement a loaded project names (relative to the project); InputError when it names
    none or the file is gone."""
    path = Path(path)
    inp = data.get("input")
    if inp is None:
        raise InputError(f"{path}: the project names no data file")
    data_path = (path.parent / inp) if not Path(inp).is_absolute() else Path(inp)
    if not data_path.is_file():
        raise InputError(f"{path}: its data file {data_path} was moved or deleted — put it back or "
                         "open the data and the recipe separately")
    return data_path

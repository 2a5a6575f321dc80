"""Discovery of steps through the entry-point group ``pointspro.steps``.

Built-in steps register exactly like third-party ones (pyproject.toml). Listing reads only the entry
points' names; a step's module is imported when the step is used (`load`), so `pointspro --batch`
imports just the steps its recipe names.
"""
from __future__ import annotations

from importlib.metadata import entry_points

from .errors import RecipeError

GROUP = "pointspro.steps"


class Registry:
    """The installed steps. Built fresh where needed (no global state); cheap to build."""

    def __init__(self, extra: dict | None = None):
        self._eps = {ep.name: ep for ep in entry_points(group=GROUP)}
        self._loaded: dict[str, type] = {}
        for cls in (extra or {}).values():  # steps registered in code, e.g. by tests
            self._loaded[cls.id] = cls

    def ids(self) -> list[str]:
        return sorted(set(self._eps) | set(self._loaded))

    def __contains__(self, step_id: str) -> bool:
        return step_id in self._eps or step_id in self._loaded

    def load(self, step_id: str):
        if step_id in self._loaded:
            return self._loaded[step_id]
        ep = self._eps.get(step_id)
        if ep is None:
            raise RecipeError(f"unknown step '{step_id}'; installed steps: {', '.join(self.ids())}")
        cls = ep.load()
        if getattr(cls, "id", None) != step_id:
            raise RecipeError(f"entry point '{step_id}' loads {cls!r} whose id is {getattr(cls, 'id', None)!r}")
        self._loaded[step_id] = cls
        return cls

    def all(self) -> list[type]:
        return [self.load(i) for i in self.ids()]

"""The window's model, Qt-free, in four parts: the model (Session, model.py), its undo history
(history.py), what the optician selects (selection.py) and project files (project.py)."""
from ..geometry.polygon import in_rectangle, points_in_polygon
from .history import History, Snapshot
from .model import CHANGES, EVENTS, Session
from .project import PROJECT_VERSION, project_text, write_project, write_recipe

__all__ = ["Session", "History", "Snapshot", "CHANGES", "EVENTS", "PROJECT_VERSION", "project_text",
           "write_project", "write_recipe", "in_rectangle", "points_in_polygon"]

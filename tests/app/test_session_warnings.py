"""The window shows what the session reports without failing: a project whose recipe does not run
opens, and the log says why (it used to be swallowed)."""
from __future__ import annotations

import pytest
import yaml

from ..conftest import EXAMPLE

pytest.importorskip("pytestqt")


def test_project_whose_recipe_fails_opens_and_the_log_says_why(qtbot, tmp_path):
    from pointspro.app.main import build_window

    recipe = {"pointspro": 1, "steps": [{"manual_edit": {"remove": [0]}},
                                        {"aperture": {"diameter": 1.0, "center_x": 1.0e6}}]}
    proj = tmp_path / "p.pointspro.yaml"
    proj.write_text(yaml.safe_dump({"pointspro_project": 1, "input": str(EXAMPLE / "asphere_cmm.csv"),
                                    "recipe": recipe}), encoding="utf-8")
    win = build_window([])
    qtbot.addWidget(win)
    win.open_any(str(proj))  # the recipe runs in the worker thread, as Run all
    qtbot.waitUntil(lambda: not win.runner.busy, timeout=60_000)
    log = win.log_widget.toPlainText()
    assert "run: " in log and "no point lies inside the aperture" in log
    assert win.pipeline.bar.format() == "failed"
    # the project is open, shown less its manual edit's row, the steps there to fix
    assert win.session.shown.n == win.session.input_cloud.n - 1 and win.pipeline.list.count() == 2

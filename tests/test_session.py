"""The window's model (core/session.py), headless: open, edit the pipeline, run, select, delete,
undo/redo, projects, and the batch replaying the saved recipe identically."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from pointspro.core.errors import InputError, RecipeError
from pointspro.core.io import read_cloud
from pointspro.core.session import Session

from .conftest import EXAMPLE


@pytest.fixture
def session():
    s = Session()
    s.open(EXAMPLE / "asphere_cmm.csv")
    s.load_recipe(EXAMPLE / "recipe.yaml")
    # keep the test fast: the steps up to the aperture
    s.set_recipe({**s.recipe, "steps": s.recipe["steps"][:5]})
    return s


def test_edit_run_select_delete_undo_redo(session):
    events = []
    session.listeners.append(events.append)
    session.run()
    n0 = session.shown.n
    assert "residual" in session.shown.channels and n0 == 4640
    mask = session.select_rectangle(-100, 100, -100, 100)
    k = int(mask.sum())
    assert 0 < k < n0
    assert session.delete(mask, "centre") == k
    assert session.shown.n == n0 - k
    assert session.steps[-1]["manual_edit"]["note"] == "centre"
    session.undo()
    assert session.shown.n == n0 and "manual_edit" not in session.steps[-1]
    session.redo()
    assert session.shown.n == n0 - k
    # threshold on ω: how many go
    sel = session.select_threshold("omega", 0.001)
    assert sel.sum() < 50
    lasso = session.select_lasso([[0, 0], [300, 0], [300, 300]])
    assert lasso.any()
    assert events[:3] == ["ran", "deleted", "undo"]


def test_pipeline_editing_is_validated_and_undoable(session):
    n = len(session.steps)
    session.add_step("zernike", {"remove": ["piston"]})
    assert len(session.steps) == n + 1
    with pytest.raises(RecipeError, match="key 'terms'"):
        session.set_params(n, {"terms": 0})
    assert session.steps[n] == {"zernike": {"remove": ["piston"]}}  # unchanged
    session.move_step(n, 0)
    assert "zernike" in session.steps[0]
    session.set_enabled(0, False)
    assert session.steps[0]["enabled"] is False
    session.undo()
    session.undo()
    session.remove_step(n)
    assert len(session.steps) == n
    with pytest.raises(RecipeError, match="unknown step 'nope'"):
        session.add_step("nope")


def test_project_round_trip_and_batch_replays_the_cleanup(session, tmp_path, run_cli):
    session.run()
    session.delete(session.select_rectangle(200, 400, -50, 50), "probe slipped")
    shown = session.shown
    session.save_project(tmp_path / "p.pointspro.yaml")
    s2 = Session()
    s2.open_project(tmp_path / "p.pointspro.yaml")
    assert s2.shown.equals(shown)
    # the recipe of the project replays identically in the batch
    proj = yaml.safe_load((tmp_path / "p.pointspro.yaml").read_text())
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(proj["recipe"], sort_keys=False))
    code, _, err = run_cli("--batch", tmp_path / "r.yaml", EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o")
    assert code == 0, err
    out = read_cloud(tmp_path / "o" / "asphere_cmm" / "cloud.csv")
    assert np.array_equal(out.index, shown.index)
    assert np.allclose(out["residual"], shown["residual"], rtol=0, atol=1e-15)


def test_bad_input_leaves_the_session_usable(session, tmp_path):
    before = session.shown
    (tmp_path / "bad.csv").write_text("x,y,z\n1,2,oops\n")
    with pytest.raises(InputError, match="bad.csv"):
        session.open(tmp_path / "bad.csv")
    assert session.shown is before
    session.save_project(tmp_path / "p.yaml")
    moved = tmp_path / "sub"
    moved.mkdir()
    (tmp_path / "p.yaml").rename(moved / "p.yaml")
    with pytest.raises(InputError, match="was moved or deleted"):
        Session().open_project(moved / "p.yaml")
    (tmp_path / "r.yaml").write_text("pointspro: 1\nsteps:\n  - wobble: {}\n")
    with pytest.raises(RecipeError, match="unknown step 'wobble'"):
        session.load_recipe(tmp_path / "r.yaml")
    assert session.shown is before

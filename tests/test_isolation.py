"""Issue 18: one bug must not sink the night. A third-party step that raises anything (here a
ZeroDivisionError on one input) fails that input alone — sequentially, in the process pool and on
Dask — with one line naming the input and the step, the traceback in summary.json; the others are
complete; exit 1. Repeated steps keep their artifacts apart."""
from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest

from .conftest import EXAMPLE, write

BUGGY = '''
from pointspro.core.step import Params, Step, StepResult


class BuggyParams(Params):
    pass


class BuggyStep(Step):
    id = "buggy"
    title = "A third party's step with a bug"
    summary = "divides by zero on inputs whose name holds 'bad'"
    Params = BuggyParams

    def run(self, cloud, params, ctx):
        if "bad" in str(cloud.meta.get("source", "")):
            1 / 0
        return StepResult(cloud.replace(), {"ok": True}, {"buggy.txt": "fine"})
'''


WARNS = '''
import numpy as np

from pointspro.core.step import Params, Step, StepResult


class WarnsParams(Params):
    pass


class WarnsStep(Step):
    id = "warns"
    title = "A third party's step that meets a numpy warning"
    summary = "divides by zero in numpy (a RuntimeWarning, no error)"
    Params = WarnsParams

    def run(self, cloud, params, ctx):
        ratio = np.ones(3) / np.zeros(3)
        return StepResult(cloud.replace(), {"ratio_finite": bool(np.isfinite(ratio).all())})
'''


def _install_step(tmp_path, monkeypatch, module: str, step_id: str, cls: str, source: str):
    """An installed third-party package with a `pointspro.steps` entry point (a real dist-info on
    sys.path and PYTHONPATH, so spawned workers and Dask's see it too)."""
    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / f"{module}.py").write_text(source, encoding="utf-8")
    dist = site / f"{module}-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module.replace('_', '-')}\nVersion: 0.1\n",
                                   encoding="utf-8")
    (dist / "entry_points.txt").write_text(f"[pointspro.steps]\n{step_id} = {module}:{cls}\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(site))
    import os

    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(site),
                                                                    os.environ.get("PYTHONPATH")])))
    return site


@pytest.fixture
def buggy_package(tmp_path, monkeypatch):
    return _install_step(tmp_path, monkeypatch, "buggy_step", "buggy", "BuggyStep", BUGGY)


def test_a_library_warning_is_one_log_line_naming_the_input(tmp_path, monkeypatch, run_cli):
    """numpy's RuntimeWarnings reached stderr as two lines each — a file path with a line number and
    the source text — naming no input; now one log line of `pointspro.warnings` naming the input."""
    _install_step(tmp_path, monkeypatch, "warns_step", "warns", "WarnsStep", WARNS)
    r = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - warns: {}\n")
    data = write(tmp_path / "part.csv", (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8"))
    code, _, err = run_cli("--batch", r, data, "--out", tmp_path / "o", "--quiet", "--figures", "none")
    lines = err.strip().splitlines()
    assert code == 0 and lines, err
    assert all(ln.startswith("pointspro.warnings: part.csv: RuntimeWarning: ") for ln in lines), err
    assert "divide by zero" in err and "np.ones(3)" not in err  # not the source line


def _inputs(tmp_path):
    src = (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8")
    return [write(tmp_path / name, src) for name in ("bad_first.csv", "good2.csv", "good3.csv")]


@pytest.mark.parametrize("mode", [["--workers", "1"], ["--workers", "2"],
                                  ["--scheduler", "local", "--workers", "2"]],
                         ids=["sequential", "processes", "dask"])
def test_a_bug_in_a_step_fails_one_input_and_the_batch_goes_on(buggy_package, run_cli, tmp_path, mode):
    recipe = write(tmp_path / "r.yaml", textwrap.dedent("""\
        pointspro: 1
        surface: {type: even_asphere, c: 3.3333333e-4, k: -0.98, A: {4: 7.0e-13, 6: 1.0e-19}}
        steps:
          - misalignment: {}
          - buggy: {}
        """))
    files = _inputs(tmp_path)
    code, out, err = run_cli("--batch", recipe, *files, "--out", tmp_path / "o", "--quiet", *mode)
    assert code == 1, err
    line = f"{files[0]}: step 2 'buggy': internal error ZeroDivisionError: division by zero — please report"
    assert line in err
    assert "Traceback" not in err  # only with --debug
    s = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    assert [e["status"] for e in s["inputs"]] == ["failed", "ok", "ok"]
    assert "ZeroDivisionError" in s["inputs"][0]["traceback"] and "buggy_step.py" in s["inputs"][0]["traceback"]
    assert s["inputs"][1]["traceback"] is None
    for f in files[1:]:
        assert (tmp_path / "o" / f.stem / "buggy.txt").read_text(encoding="utf-8") == "fine"
    assert not (tmp_path / "o" / files[0].stem).exists()
    code, out, err = run_cli("--batch", recipe, files[0], "--out", tmp_path / "d", "--debug", *mode)
    assert "Traceback" in err and "ZeroDivisionError" in err


def test_run_pipeline_turns_a_bug_into_an_internal_error_naming_the_step(buggy_package):
    from pointspro.core.cloud import PointCloud
    from pointspro.core.errors import InternalError
    from pointspro.core.pipeline import run_pipeline
    from pointspro.core.recipe import parse_recipe

    cloud = PointCloud(np.zeros((3, 3)) + np.arange(3.0)[:, None], {}, {"source": "x/bad.csv"})
    with pytest.raises(InternalError, match=r"^step 1 'buggy': internal error ZeroDivisionError"):
        run_pipeline(cloud, parse_recipe({"pointspro": 1, "steps": [{"buggy": {}}]}))


def test_repeated_steps_keep_their_artifacts_apart(tmp_path, run_cli):
    recipe = write(tmp_path / "r.yaml", textwrap.dedent("""\
        pointspro: 1
        surface: {type: even_asphere, c: 3.3333333e-4, k: -0.98, A: {4: 7.0e-13, 6: 1.0e-19}}
        steps:
          - misalignment: {}
          - knn_denoise: {window: 15.0, remove: auto}
          - knn_denoise: {window: 30.0, remove: 0}
        """))
    code, out, err = run_cli("--batch", recipe, EXAMPLE / "asphere_cmm.csv", "--out", tmp_path / "o",
                             "--quiet")
    assert code == 0, err
    folder = tmp_path / "o" / "asphere_cmm"
    names = {p.name for p in folder.iterdir()}
    firsts = {n[2:] for n in names if n.startswith("2_")}
    seconds = {n[2:] for n in names if n.startswith("3_")}
    assert firsts and firsts == seconds  # both steps' files, under their positions
    assert "misalignment.png" in names  # a step that runs once keeps the plain name
    rep = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    arts = [st["artifacts"] for st in rep["steps"]]
    assert all(a.startswith("2_") for a in arts[1]) and all(a.startswith("3_") for a in arts[2])
    for a in arts[1] + arts[2]:
        assert (folder / a).is_file()
    png = sorted(n for n in firsts if n.endswith(".png"))[0]
    assert (folder / f"2_{png}").read_bytes() != (folder / f"3_{png}").read_bytes()


EXITS = '''
from pointspro.core.step import Params, Step, StepResult


class ExitsParams(Params):
    pass


class ExitsStep(Step):
    id = "exits"
    title = "A third party's step that leaves by the back door"
    summary = "sys.exit(0) on inputs named 'exit…', a bare BaseException on 'base…'"
    Params = ExitsParams

    def run(self, cloud, params, ctx):
        import os

        source = os.path.basename(str(cloud.meta.get("source", "")))
        if "exit" in source:
            raise SystemExit(0)
        if "base" in source:
            raise BaseException("a bare one")
        return StepResult(cloud.replace(), {"ok": True})
'''


@pytest.mark.parametrize("mode", [["--workers", "1"], ["--workers", "2"]], ids=["sequential", "processes"])
def test_a_step_calling_sys_exit_or_raising_a_bare_base_exception_fails_its_input_alone(
        tmp_path, monkeypatch, run_cli, mode):
    """A review: sys.exit(0) in a step ended the whole batch with exit 0, no summary.json and a
    half-written folder; a bare BaseException ended it with a traceback."""
    _install_step(tmp_path, monkeypatch, "exits_step", "exits", "ExitsStep", EXITS)
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - exits: {}\n")
    src = (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8")
    files = [write(tmp_path / name, src) for name in ("good1.csv", "exit2.csv", "base3.csv", "good4.csv")]
    code, _, err = run_cli("--batch", recipe, *files, "--out", tmp_path / "o", "--quiet", "--figures", "none",
                           *mode)
    assert code == 1, err
    assert f"{files[1]}: step 1 'exits': internal error: the step called sys.exit(0) — please report" in err
    assert f"{files[2]}: step 1 'exits': internal error: the step raised BaseException: a bare one" in err
    assert "Traceback" not in err
    s = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    assert [e["status"] for e in s["inputs"]] == ["ok", "failed", "failed", "ok"]
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["good1", "good4", "summary.json"]


def test_a_folder_with_a_report_json_that_pointspro_did_not_write_is_not_replaced(tmp_path, run_cli):
    """A review: a user's folder holding a file named report.json (any text, `{}`, `[]`) was taken for
    an earlier output and replaced, notes and subfolders with it."""
    data = write(tmp_path / "a.csv", (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8"))
    recipe = EXAMPLE / "recipe.yaml"
    for text in ("not json at all", "{}", "[]", '{"files": ["notes.txt"]}'):
        out = tmp_path / "o"
        import shutil

        shutil.rmtree(out, ignore_errors=True)
        (out / "a" / "sub").mkdir(parents=True)
        (out / "a" / "notes.txt").write_text("mine", encoding="utf-8")
        (out / "a" / "report.json").write_text(text, encoding="utf-8")
        code, _, err = run_cli("--batch", recipe, data, "--out", out, "--figures", "none", "--quiet")
        assert code == 2 and "is not a PointsPro output folder" in err, (text, err)
        assert (out / "a" / "notes.txt").read_text(encoding="utf-8") == "mine"
    # an earlier output of ours is still replaced
    shutil.rmtree(tmp_path / "o")
    assert run_cli("--batch", recipe, data, "--out", tmp_path / "o", "--figures", "none", "--quiet")[0] == 0
    assert run_cli("--batch", recipe, data, "--out", tmp_path / "o", "--figures", "none", "--quiet")[0] == 0


def test_an_input_whose_output_folder_name_cannot_be_written_is_refused_before_any(tmp_path, run_cli):
    """A 240-byte name ran the whole pipeline, then failed "File name too long" on the temporary
    folder ".<name>.<8 hex>.partial" (a review)."""
    src = (EXAMPLE / "asphere_cmm.csv").read_text(encoding="utf-8")
    long_one = write(tmp_path / ("y" * 240 + ".csv"), src)
    fine = write(tmp_path / ("z" * 237 + ".csv"), src)
    code, _, err = run_cli("--batch", EXAMPLE / "recipe.yaml", long_one, "--out", tmp_path / "o", "--figures",
                           "none", "--quiet")
    assert code == 2 and "its name is 240 bytes long" in err and "at most 237 bytes" in err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
    code, _, err = run_cli("--batch", EXAMPLE / "recipe.yaml", fine, "--out", tmp_path / "o2", "--figures",
                           "none", "--quiet")
    assert code == 0, err

"""probe_radius names a flipped curvature sign (the mirrored fit, core/geometry/nominal_check.py).

The example recipe runs probe_radius before misalignment. With its nominal's c and A negated (the
concave/convex mix-up misalignment now names) it stopped in probe_radius's own pose fit: "the fit
cannot separate its parameters … on a nearly spherical part a tilt is a decenter — fit fewer DOF";
with c alone negated "the fit did not converge … check the data's units". Both sent the user the
wrong way. probe_radius now fits the probe-ball centres mirrored in z to the nominal (the ball's side
turns with them: offset −s·ρ) when its fit fails or leaves a distance residual the size of the
nominal's own sag, and names `surface.c` when that fits far better; the DOF advice stays where it
is right (a near-sphere, the tilts not separable from the decenters).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from pointspro.core import PointCloud
from pointspro.core.errors import StepError
from pointspro.core.geometry import Pose
from pointspro.core.step import Context
from pointspro.core.surfaces import EvenAsphere
from pointspro.plugins.probe_radius import ProbeRadiusStep

from .conftest import EXAMPLE, write
from .paper002 import raster

RECIPE = EXAMPLE / "recipe.yaml"
DATA = EXAMPLE / "asphere_cmm.csv"


def _example_surface() -> dict:
    return yaml.safe_load(RECIPE.read_text(encoding="utf-8"))["surface"]


def _negated_c() -> str:
    return f"surface.c={-_example_surface()['c']!r}"


def _negated_a() -> str:
    return "surface.A={" + ", ".join(f"{n}: {-v!r}" for n, v in _example_surface()["A"].items()) + "}"


def _run(run_cli, tmp_path, recipe, *overrides):
    out = tmp_path / "o"
    sets = [a for o in overrides for a in ("--set", o)]
    code, stdout, err = run_cli("--batch", recipe, DATA, "--out", out, "--figures", "none", "--quiet", *sets)
    return code, stdout, err, out


CASES = {  # --set overrides of the example recipe
    # its 5-DOF fit "cannot separate its parameters … fit fewer DOF"
    "c_and_A_negated": lambda: [_negated_c(), _negated_a()],
    # its fit "did not converge … check the data's units (mm) and frame"
    "c_negated": lambda: [_negated_c()],
    # the advice followed (tilts held): the fit converges to 41 mm of distance residual; misalignment
    # named the sign one step later, after probe_radius had "compensated" along the wrong normals
    "c_and_A_negated_three_dof": lambda: [_negated_c(), _negated_a(), "probe_radius.dof=[dx, dy, dz]"],
    # a flipped sphere-like conic: the 5-DOF fit converges (ill-posed) to 41.6 mm
    "c_negated_no_asphere": lambda: [_negated_c(), "surface.k=0", "surface.A={}"],
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_example_recipe_with_a_flipped_nominal_is_refused_naming_the_sign(run_cli, tmp_path, case):
    code, _, err, out = _run(run_cli, tmp_path, RECIPE, *CASES[case]())
    assert code != 0, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pointspro: "), err
    assert "Traceback" not in err
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert [e["status"] for e in summary["inputs"]] == ["failed"]
    line = lines[0]
    assert "'probe_radius'" in line, line  # the first step that meets the nominal says it
    assert "opposite curvature" in line and "`surface.c` (or `R`)" in line and "concave vs convex" in line
    # the failed fit is named (c negated: "the pose fit to the nominal failed (the fit did not converge)"),
    # its advice is not
    assert "fewer DOF" not in line and "units" not in line and "initial values" not in line


def test_a_probe_radius_only_recipe_with_a_flipped_nominal_is_refused(run_cli, tmp_path):
    """Without misalignment after it, the fit that converged (tilts held) ended with exit 0 and
    "contact points" moved 4 mm along the normals of the wrong surface."""
    recipe = write(tmp_path / "r.yaml", RECIPE.read_text(encoding="utf-8").split("steps:")[0]
                   + "steps:\n  - probe_radius: {radius: 4.0, side: +1, dof: [dx, dy, dz]}\n")
    code, _, err, out = _run(run_cli, tmp_path, recipe, _negated_c(), _negated_a())
    assert code != 0, err
    assert "'probe_radius'" in err and "`surface.c` (or `R`)" in err
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]


def test_the_example_recipe_still_passes(run_cli, tmp_path):
    code, _, err, out = _run(run_cli, tmp_path, RECIPE)
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert [e["status"] for e in summary["inputs"]] == ["ok"]
    rep = json.loads((out / "asphere_cmm" / "report.json").read_text(encoding="utf-8"))
    pr = next(s["report"] for s in rep["steps"] if s["id"] == "probe_radius")
    assert pr["distance_residual_rms_um"] < 2.0  # 0.84 µm


def _centres(surface, pose, x, y, radius, form=None):
    z = surface.sag(x, y) + (0.0 if form is None else form)
    p = np.column_stack([x, y, z])
    return pose.to_measuring(p + radius * surface.normal(x, y))


def _step(q, surface, radius, **params):
    return ProbeRadiusStep().run(PointCloud(q), ProbeRadiusStep.Params(radius=radius, **params),
                                 Context(surface=surface))


POSE = Pose(0.3, -0.2, 0.5, -0.7, 2.0)


@pytest.mark.parametrize("R,diameter,ball", [(10.0, 12.0, 2.5), (20.0, 30.0, 6.0), (-20.0, 30.0, 4.0)])
def test_a_flipped_lens_probed_with_a_large_ball_is_named(R, diameter, ball):
    """Small lenses, balls a quarter to a third of the radius: the mirrored centres fitted by their
    vertical residual (as misalignment does on contact points) leave 0.27–0.58 of the sag variation —
    not decisive; fitted by the normal distance at −s·ρ they are exact. The fit to the flipped nominal
    converged (ill-posed) and the step passed."""
    true = EvenAsphere(1 / R, 0.0, {}, diameter)
    x, y = raster(diameter, diameter / 40)
    q = _centres(true, POSE, x, y, ball, 1e-4 * np.sin(x))
    assert _step(q, true, ball).report["distance_residual_rms_um"] < 0.2
    with pytest.raises(StepError, match=r"opposite curvature.*`surface\.c` \(or `R`\)"):
        _step(q, EvenAsphere(-1 / R, 0.0, {}, diameter), ball)


def test_a_near_sphere_keeps_the_dof_advice():
    """R 50 mm, k −0.01: tilt and decenter trade off and the 5-DOF fit wanders — the advice is right
    there (the mirrored fit leaves twice the sag variation), and following it gives the compensation."""
    s = EvenAsphere(1 / 50, -0.01, {}, 40)
    x, y = raster(40, 1.0)
    q = _centres(s, POSE, x, y, 2.0)
    with pytest.raises(StepError, match=r"cannot separate alpha/dy, beta/dx .*fewer DOF.*dof: \[dx, dy, dz\]") as e:
        _step(q, s, 2.0)
    assert "surface.c" not in str(e.value) and "opposite curvature" not in str(e.value)
    res = _step(q, s, 2.0, dof=["dx", "dy", "dz"], initial={"alpha_deg": 0.3, "beta_deg": -0.2})
    assert res.report["distance_residual_rms_um"] < 1e-3

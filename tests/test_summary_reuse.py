"""The run summary takes PVr's 36-term fit and the slope-RMS spline from the `zernike` and
`bspline_map` steps when they fitted exactly those on exactly the final data (core.pipeline
._reusable; issues 17, 26) — the same figures as fitting again (1e-9 relative), the refit skipped —
and fits again whenever anything differs: other terms or ordering, a step after them that changes
the points or the residual, another centre, a spline with a diameter or other knots."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.metrics import form
from pointspro.core.pipeline import run_pipeline, summarize
from pointspro.core.recipe import parse_recipe

FIGURES = ("rms_um", "pv_um", "pvr_um", "slope_rms_urad")


def _map(seed: int, n: int = 60, shape: str = "disk") -> PointCloud:
    """An interferometer-like map: pixels of an n × n grid (mm), heights of a few Zernike-like terms
    plus a mid-spatial ripple and noise (mm)."""
    rng = np.random.default_rng(seed)
    g = np.linspace(-20, 20, n) + rng.uniform(-5, 5)
    x, y = (a.ravel() for a in np.meshgrid(g, g + rng.uniform(-5, 5)))
    cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
    if shape == "disk":
        keep = np.hypot(x - cx, y - cy) <= 20
        x, y = x[keep], y[keep]
    u, v = (x - cx) / 20, (y - cy) / 20
    z = (rng.normal(0, 2e-4) * (2 * (u * u + v * v) - 1) + rng.normal(0, 1e-4) * (u * u - v * v)
         + rng.normal(0, 1e-4) * (3 * (u * u + v * v) - 2) * u + 2e-5 * np.sin(2 * np.pi * x / 3.7)
         + rng.normal(0, 3e-6, x.size))
    return PointCloud.from_xyz(x, y, z)


def _run(cloud, steps, surface=None):
    data = {"pointspro": 1, "steps": steps}
    if surface is not None:
        data["surface"] = surface
    return run_pipeline(cloud, parse_recipe(data), assess=False)


def _refit(res) -> dict:
    """The summary fitted afresh: no fit reused, about the pupil centre the recipe gives."""
    return summarize(res.input_cloud, res.cloud, res.surface, centre=res.pupil_centre)


def _close(a: dict, b: dict):
    for k in FIGURES:
        assert (a[k] is None) == (b[k] is None), k
        if a[k] is not None:
            assert a[k] == pytest.approx(b[k], rel=1e-9, abs=1e-12), k


def _count_calls(monkeypatch):
    calls = {"pvr": 0, "spline": 0}
    real_pvr, real_slope = form.pvr, form.slope_rms_urad

    def pvr(*a, **k):
        calls["pvr"] += 1
        return real_pvr(*a, **k)

    def slope(x, y, r, spline=None, weights=None):
        calls["spline"] += spline is None  # fitted here, not taken from the step
        return real_slope(x, y, r, spline, weights)
    monkeypatch.setattr(form, "pvr", pvr)
    monkeypatch.setattr(form, "slope_rms_urad", slope)
    return calls


@pytest.mark.parametrize("seed,shape", [(0, "disk"), (1, "disk"), (2, "square"), (3, "disk")])
def test_a_map_recipe_takes_both_fits_from_its_steps(monkeypatch, seed, shape):
    res = _run(_map(seed, shape=shape), [{"zernike": {"terms": 36, "remove": ["piston", "tilt", "power"]}},
                                         {"bspline_map": {}}])
    calls = _count_calls(monkeypatch)
    got = res.summary()
    assert calls == {"pvr": 0, "spline": 0}
    _close(got, _refit(res))


def test_a_cmm_recipe_with_a_surface_takes_pvr_from_zernike(monkeypatch):
    """Part frame, the surface's axis as centre, a norm radius other than the summary's (the span of
    Fringe Z1…Z36 does not depend on it)."""
    c = _map(4)
    xyz = c.xyz - [0.5 * (c.x.min() + c.x.max()), 0.5 * (c.y.min() + c.y.max()), 0.0]  # on the axis
    c = PointCloud.from_xyz(xyz[:, 0], xyz[:, 1], xyz[:, 2], residual=c.z)
    res = _run(c, [{"zernike": {"terms": 36, "norm_radius": 31.0, "remove": ["piston", "tilt"]}}],
               surface={"type": "even_asphere", "c": 0.002, "k": 0.0, "aperture": 45.0})
    calls = _count_calls(monkeypatch)
    got = res.summary()
    assert calls["pvr"] == 0
    _close(got, _refit(res))


@pytest.mark.parametrize("steps,pvr_refit,spline_refit", [
    ([{"zernike": {"terms": 15}}, {"bspline_map": {"knot_spacing": 4.0}}], 1, 1),  # other terms, knots
    ([{"zernike": {"terms": 36, "ordering": "noll"}}], 1, 1),  # another span; no spline at all
    ([{"zernike": {"terms": 36, "centre": [1.0, -0.5], "remove": []}}], 0, 1),  # its centre is the summary's
    ([{"zernike": {"terms": 36, "centre": [1.0, -0.5], "remove": []}},
      {"bspline_map": {"centre": [0.0, 0.0]}}], 1, 0),  # the summary's centre is the last one given
    ([{"zernike": {"terms": 36}}, {"aperture": {"diameter": 30.0}}], 1, 1),  # points removed after it
    ([{"zernike": {"terms": 36}}, {"zernike": {"terms": 4, "remove": ["piston", "tilt"]}}], 1, 1),
    ([{"zernike": {"terms": 36}}, {"bspline_map": {"diameter": 36.0}}], 0, 1),  # a spline over a disk
    ([{"zernike": {"terms": 36}}, {"bspline_map": {"smoothing": 0.01}}], 0, 1),  # another penalty
    ([{"bspline_map": {}}, {"zernike": {"terms": 36}}], 0, 1),  # the residual changed after the spline
])
def test_anything_different_is_fitted_again(monkeypatch, steps, pvr_refit, spline_refit):
    res = _run(_map(5), steps)
    calls = _count_calls(monkeypatch)
    got = res.summary()
    assert calls == {"pvr": pvr_refit, "spline": spline_refit}
    _close(got, _refit(res))


def test_the_reused_arrays_are_not_written():
    res = _run(_map(6), [{"zernike": {"terms": 36}}, {"bspline_map": {}}])
    assert set(res.steps[0].reuse) == {"pvr"} and set(res.steps[1].reuse) == {"slope_spline"}
    assert all("reuse" not in rec.to_json() for rec in res.steps)


@pytest.mark.parametrize("step", ["zernike", "bspline_map"])
def test_summary_pvr_is_about_the_centre_given_in_the_recipe(step):
    """An off-axis clear aperture (centre (300, 0), radius 50 mm, of a 1300 mm part): the centre given
    on a zernike or bspline_map step is the summary's pupil too (docs/conventions.md, Pupil). About
    the part's axis the 36-term fit was singular (condition 4e15) and PVr 4 % low."""
    import pointspro.core as pp
    from pointspro.core.metrics import form_metrics

    rng = np.random.default_rng(11)
    g = np.arange(-50, 50.001, 1.0)
    X, Y = np.meshgrid(g, g)
    m = X**2 + Y**2 <= 50.0**2
    u, v = X[m], Y[m]
    x, y = u + 300.0, v
    e = (3e-5 * (2 * (u**2 + v**2) / 2500 - 1) + 2e-5 * u * v / 2500
         + 2e-5 * np.exp(-((u - 20) ** 2 + (v + 10) ** 2) / 18.0) + 2e-6 * rng.standard_normal(len(u)))
    surface = {"type": "even_asphere", "c": 1 / 2000, "k": -1, "aperture": 1300}
    cloud = pp.PointCloud.from_numpy(np.column_stack([x, y, (x**2 + y**2) / 4000 + e]), residual=e,
                                     meta={"frame": "part"})
    params = {"centre": [300, 0]} | ({"remove": ["piston", "tilt"]} if step == "zernike" else {})
    recipe = {"surface": surface, "steps": [{step: params}]}
    if step == "zernike":  # a step that makes the residual: the drawing can be judged
        recipe["tolerance"] = {"form": "3/-(1/0.5)", "pvr_um": 1.0}
    res = pp.run(recipe, cloud)
    s = res.summary
    assert s["pupil"]["centre_mm"] == [300.0, 0.0]
    assert s["pupil"]["centre_from"] == "given in the recipe"
    r = res.cloud["residual"]
    own = form_metrics(res.cloud.x, res.cloud.y, r, 50.0, center=(300.0, 0.0))
    assert s["pvr_um"] == pytest.approx(own["pvr_um"], rel=1e-9)
    if step == "zernike":  # the tolerance judges the same PVr
        judged = {it["quantity"]: it["value"] for it in s["tolerance"]["items"]}
        assert judged["pvr_um"] == pytest.approx(own["pvr_um"], rel=1e-9)
    axis = form_metrics(res.cloud.x, res.cloud.y, r, 650.0, center=(0.0, 0.0))
    assert abs(axis["pvr_um"] - own["pvr_um"]) > 1e-3 * own["pvr_um"]  # the case tells them apart

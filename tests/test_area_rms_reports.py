"""The RMS figures the steps and tools report beside the summary's are over the area too
(docs/conventions.md, Summary figures; core/metrics/area_weights.py): zernike's rms_before_um and
rms_after_um, the titles of zernike_removed.png, misalignment.png and explain's gap_map.png, a
notebook's "RMS / PV" line, `pointspro info`'s z_plane_removed, explain's gap_before, gap_after and
unexplained.rms_um, kinematic's removed_rms_nm.

A star scan of 12 diameters (R = 50 mm, a point every 0.5 mm) crowds its centre: the plain mean over
its points reads astigmatism √6ρ²cos2θ ~21 % low and spherical aberration √5(6ρ⁴ − 6ρ² + 1) ~20 %
high, a central bump 2.2× its RMS. Each figure is checked against the area RMS of the same field over
the star's convex hull (quadrature on a fine grid) and the plain mean is checked to be far off, so each
test fails without the weights. On a raster (an even sampling: no weights) each figure is the plain
mean to the last bit, as before. Fixed seeds throughout."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from pointspro.core import PointCloud
from pointspro.core.metrics.area_weights import area_weights, weighted_rms
from pointspro.core.step import Context
from pointspro.core.units import format_length

R = 50.0


def star(diameters=12, step=0.5):
    """x, y (mm) and the spindle angle c (deg) that brings each point under the probe at
    X·(cos c, −sin c) (plugins/kinematic: X = s along the line, through the centre)."""
    s = np.arange(-R, R + 1e-9, step)
    th = np.pi * np.arange(diameters) / diameters
    x = np.concatenate([s * np.cos(t) for t in th])
    y = np.concatenate([s * np.sin(t) for t in th])
    c = np.concatenate([np.full(s.size, -np.degrees(t) % 360.0) for t in th])
    return x, y, c


def raster(pitch=1.0):
    g = np.arange(-R, R + 1e-9, pitch)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    keep = np.hypot(x, y) <= R
    return x[keep], y[keep]


def astigmatism(x, y):  # 1 µm RMS over the disk (mm)
    return 1e-3 * np.sqrt(6) * (x * x - y * y) / R ** 2


def spherical(x, y):  # 1 µm RMS over the disk (mm)
    rho2 = (x * x + y * y) / R ** 2
    return 1e-3 * np.sqrt(5) * (6 * rho2 * rho2 - 6 * rho2 + 1)


def bump(x, y):  # a central bump, σ 10 mm, 1 µm high (mm)
    return 1e-3 * np.exp(-(x * x + y * y) / 100.0)


def area_truth(x, y, f) -> float:
    """RMS of f about its mean over the points' convex hull, by quadrature (0.125 mm cells)."""
    eq = ConvexHull(np.column_stack([x, y])).equations
    g = np.linspace(-R, R, 801)
    X, Y = (a.ravel() for a in np.meshgrid(g, g))
    inside = np.all(eq[:, :2] @ np.vstack([X, Y]) + eq[:, 2:3] <= 1e-9, axis=0)
    return float(np.std(f(X[inside], Y[inside])))


def plain(v) -> float:
    return weighted_rms(v, None)


def close_to_area_far_from_points(got, v, truth, rel=0.03):
    """``got`` within ``rel`` of the area truth, where the points' plain RMS of ``v`` is > 10 % off."""
    assert got == pytest.approx(truth, rel=rel), (got / truth, plain(v) / truth)
    assert abs(plain(v) / truth - 1) > 0.10, plain(v) / truth


def _titles_rms(fig) -> list[str]:
    return [re.search(r"RMS (.*)$", ax.get_title()).group(1) for ax in fig.axes if "RMS" in ax.get_title()]


@pytest.fixture
def spy_before_after(monkeypatch):
    """The weights each caller hands core.figures.before_after (the callers import it when they draw)."""
    import pointspro.core.figures as figures

    calls, real = [], figures.before_after

    def spy(*args, **kwargs):
        calls.append(kwargs.get("weights"))
        return real(*args, **kwargs)

    monkeypatch.setattr(figures, "before_after", spy)
    return calls


# ---------------------------------------------------------------- zernike and its figure

def _zernike(x, y, v):
    from pointspro.plugins.zernike import ZernikeStep

    cloud = PointCloud.from_xyz(x, y, np.zeros_like(x), residual=v)
    return ZernikeStep().run(cloud, ZernikeStep.Params(), Context())  # removes piston, tilt, power


def before_field(x, y):
    """Astigmatism with piston, a tilt and power for zernike to remove."""
    return astigmatism(x, y) + 0.2e-3 + 0.3e-3 * x / R + 0.3e-3 * (2 * (x * x + y * y) / R ** 2 - 1)


def test_zernike_rms_before_and_after_are_over_the_area_on_a_star(tmp_path, spy_before_after):
    x, y, _ = star()
    v = before_field(x, y)
    res = _zernike(x, y, v)
    after = res.cloud["residual"]
    close_to_area_far_from_points(res.report["rms_before_um"] * 1e-3, v, area_truth(x, y, before_field))
    close_to_area_far_from_points(res.report["rms_after_um"] * 1e-3, after, area_truth(x, y, astigmatism))
    # the fit diagnostic stays the fit's, over the points (the field is in the fitted span: ~0)
    assert res.report["fit_residual_rms_um"] < 1e-9
    # the figure's titles say the report's RMS
    res.artifacts["zernike_removed.png"](tmp_path / "z.png")
    w = area_weights(x, y)
    assert len(spy_before_after) == 1 and np.array_equal(spy_before_after[0], w)


def test_zernike_on_a_raster_is_the_plain_mean_to_the_last_bit(tmp_path, spy_before_after):
    x, y = raster()
    v = before_field(x, y)
    res = _zernike(x, y, v)
    after = res.cloud["residual"]

    def old_std(a):  # the step's _std before the weights
        d = a - float(np.sum(a)) / len(a)
        return float(np.sqrt(float(d @ d) / len(a)))

    assert res.report["rms_before_um"] == old_std(v) * 1e3
    assert res.report["rms_after_um"] == old_std(after) * 1e3
    res.artifacts["zernike_removed.png"](tmp_path / "z.png")
    assert spy_before_after == [None]


def test_before_after_titles_give_the_rms_over_the_area():
    from pointspro.core.figures import before_after

    x, y, _ = star()
    v, a = spherical(x, y), astigmatism(x, y)
    w = area_weights(x, y)
    fig = before_after(x, y, v, a, what="test", weights=w)
    assert _titles_rms(fig) == [format_length(weighted_rms(v, w), 4), format_length(weighted_rms(a, w), 4)]
    assert _titles_rms(before_after(x, y, v, a, what="test")) == [format_length(np.std(v), 4),
                                                                  format_length(np.std(a), 4)]


def test_misalignment_figure_is_drawn_with_the_part_frame_areas(tmp_path, spy_before_after):
    from pointspro.core.surfaces import EvenAsphere
    from pointspro.plugins.misalignment import MisalignmentStep

    x, y, _ = star(step=1.0)
    surface = EvenAsphere(1 / 500.0, 0.0, {}, 2 * R)
    q = np.column_stack([x, y, surface.sag(x, y) + astigmatism(x, y)])
    res = MisalignmentStep().run(PointCloud(q), MisalignmentStep.Params(), Context(surface=surface))
    res.artifacts["misalignment.png"](tmp_path / "m.png")
    part = res.cloud
    assert len(spy_before_after) == 1 and spy_before_after[0] is not None
    assert np.array_equal(spy_before_after[0], area_weights(part.x, part.y))


def test_misalignment_residual_rms_is_over_the_area_on_a_star_plain_on_a_raster():
    """misalignment's own residual_rms_um (beside the summary's) on a star: within 3 % of the area
    truth where the points' plain RMS is > 10 % off; on a raster the plain formula, bit for bit."""
    from pointspro.core.surfaces import EvenAsphere
    from pointspro.plugins.misalignment import MisalignmentStep

    surface = EvenAsphere(1 / 500.0, 0.0, {}, 2 * R)
    x, y, _ = star()
    q = np.column_stack([x, y, surface.sag(x, y) + astigmatism(x, y)])
    rep = MisalignmentStep().run(PointCloud(q), MisalignmentStep.Params(), Context(surface=surface)).report
    close_to_area_far_from_points(rep["residual_rms_um"] * 1e-3, astigmatism(x, y), area_truth(x, y, astigmatism))
    assert rep["residual_rms_over"].startswith("area")
    x, y = raster(2.0)
    q = np.column_stack([x, y, surface.sag(x, y) + astigmatism(x, y)])
    res = MisalignmentStep().run(PointCloud(q), MisalignmentStep.Params(), Context(surface=surface))
    r = res.cloud["residual"]
    assert res.report["residual_rms_um"] == float(np.sqrt(np.mean(r ** 2))) * 1e3
    assert res.report["residual_rms_over"].startswith("points")


def test_misalignment_residual_rms_keeps_a_held_piston_on_every_sampling():
    """residual_rms_um is about zero on a raster and on a star alike (a review: the star's weighted
    figure was about the mean and dropped a piston the raster's kept): with dz held and the part
    2 µm high, both read √(2² + 1²) µm over the area (astigmatism 1 µm RMS)."""
    from pointspro.core.surfaces import EvenAsphere
    from pointspro.plugins.misalignment import MisalignmentStep

    surface = EvenAsphere(1 / 500.0, 0.0, {}, 2 * R)
    params = MisalignmentStep.Params(dof=["alpha", "beta", "dx", "dy"])
    got = {}
    for name, (x, y) in (("star", star()[:2]), ("raster", raster(2.0))):
        q = np.column_stack([x, y, surface.sag(x, y) + astigmatism(x, y) + 2e-3])
        rep = MisalignmentStep().run(PointCloud(q), params, Context(surface=surface)).report
        got[name] = rep["residual_rms_um"]
    truth = float(np.hypot(2.0, area_truth(*star()[:2], astigmatism) * 1e3))
    assert got["star"] == pytest.approx(truth, rel=0.03), got
    assert got["raster"] == pytest.approx(truth, rel=0.03), got


def test_probe_radius_distance_residual_rms_is_over_the_area_on_a_star():
    """probe_radius's distance_residual_rms_um: the foot points' areas, as the summary's."""
    from pointspro.core.surfaces import EvenAsphere
    from pointspro.plugins.probe_radius import ProbeRadiusStep

    surface = EvenAsphere(1 / 500.0, 0.0, {}, 2 * R)
    x, y, _ = star()
    rho = 1.0
    # probe-centre points: the contact points (nominal + astigmatism along z, ~ the normal here)
    # moved out by the ball's radius along the nominal's normal
    z = surface.sag(x, y) + astigmatism(x, y)
    n = surface.normal(x, y)
    q = np.column_stack([x, y, z]) + rho * n
    rep = ProbeRadiusStep().run(PointCloud(q), ProbeRadiusStep.Params(radius=rho, normals="design"),
                                Context(surface=surface)).report
    assert rep["distance_residual_rms_over"].startswith("area")
    close_to_area_far_from_points(rep["distance_residual_rms_um"] * 1e-3, astigmatism(x, y),
                                  area_truth(x, y, astigmatism), rel=0.04)


# ---------------------------------------------------------------- notebook and info

def _notebook_rms(cloud) -> str:
    from pointspro.core.notebook import cloud_html

    return re.search(r"RMS / PV of the [^<]*</th><td[^>]*>([^<]*) / ", cloud_html(cloud)).group(1)


def test_notebook_rms_is_over_the_area_residual_and_heights():
    x, y, _ = star()
    v = spherical(x, y)
    truth = area_truth(x, y, spherical)
    w = area_weights(x, y)
    close_to_area_far_from_points(weighted_rms(v, w), v, truth)
    # the residual, and the heights less their least-squares plane (a tilt added)
    assert _notebook_rms(PointCloud.from_xyz(x, y, np.zeros_like(x), residual=v)) == format_length(weighted_rms(v, w))
    from pointspro.core.pipeline import remove_piston_tilt

    z = v + 2e-3 * x / R + 0.01
    h = remove_piston_tilt(x, y, z)
    close_to_area_far_from_points(weighted_rms(h, w), h, truth)
    assert _notebook_rms(PointCloud.from_xyz(x, y, z)) == format_length(weighted_rms(h, w))


def test_notebook_rms_on_a_raster_is_the_plain_mean():
    x, y = raster()
    v = spherical(x, y)
    d = v - v.mean()  # the line's formula before the weights
    assert _notebook_rms(PointCloud.from_xyz(x, y, np.zeros_like(x), residual=v)) == \
        format_length(float(np.sqrt(np.mean(d * d))))


def _info(tmp_path, x, y, z):
    from pointspro.core.info import describe
    from pointspro.core.io import read_cloud, write_csv

    p = tmp_path / "scan.csv"
    write_csv(PointCloud.from_xyz(x, y, z), p)
    return describe(p)["z_plane_removed"], read_cloud(p)


def test_info_plane_removed_rms_is_over_the_area_on_a_star(tmp_path):
    from pointspro.core.pipeline import remove_piston_tilt

    x, y, _ = star()
    got, cloud = _info(tmp_path, x, y, astigmatism(x, y) + 0.05 + 1e-3 * y / R)
    r = remove_piston_tilt(cloud.x, cloud.y, cloud.z)
    close_to_area_far_from_points(got["rms_mm"], r, area_truth(x, y, astigmatism))
    assert got["rms"] == format_length(got["rms_mm"])
    assert got["pv_mm"] == float(np.ptp(r))  # the PV and the plane as before


def test_info_plane_removed_rms_on_a_raster_is_the_plain_mean_to_the_last_bit(tmp_path):
    from pointspro.core.pipeline import remove_piston_tilt

    x, y = raster()
    got, cloud = _info(tmp_path, x, y, astigmatism(x, y) + 0.05 + 1e-3 * y / R)
    r = remove_piston_tilt(cloud.x, cloud.y, cloud.z)
    assert got["rms_mm"] == float(np.sqrt(np.mean((r - r.mean()) ** 2)))


# ---------------------------------------------------------------- kinematic

def _kinematic(tmp_path, x, y, c, field):
    from pointspro.core.kinematics.errormap import KinematicMap
    from pointspro.plugins.kinematic import KinematicStep

    r = np.arange(-R, R + 1e-9, 0.25)  # across the centre: a star's probe reaches X < 0
    cg = np.arange(0.0, 360.0, 30.0)
    e = np.outer(field(r, np.zeros_like(r)), np.ones(cg.size))  # a slide's error, the same at every c
    (tmp_path / "map.json").write_text(KinematicMap(r, cg, e).to_json(), encoding="utf-8")
    e_pts = field(x, y)
    cloud = PointCloud.from_xyz(x, y, e_pts, c=c)  # heights = the machine's error: flat after
    res = KinematicStep().run(cloud, KinematicStep.Params(map="map.json"), Context(base_dir=tmp_path))
    return res.report, res.cloud["kinematic_error"]


def test_kinematic_removed_rms_is_over_the_area_on_a_star(tmp_path):
    x, y, c = star()
    rep, e = _kinematic(tmp_path, x, y, c, spherical)
    assert rep["points_at_negative_x"] > 0 and not rep["warnings"]
    close_to_area_far_from_points(rep["removed_rms_nm"] * 1e-6, e, area_truth(x, y, spherical))
    assert rep["removed_pv_nm"] == float(np.ptp(e) * 1e6)


def test_kinematic_removed_rms_on_a_raster_is_np_std(tmp_path):
    x, y = raster()
    c = np.degrees(-np.arctan2(y, x)) % 360.0  # each point under the probe at X = √(x² + y²)
    rep, e = _kinematic(tmp_path, x, y, c, spherical)
    assert rep["removed_rms_nm"] == float(np.std(e) * 1e6)


# ---------------------------------------------------------------- explain

def test_explain_gap_rms_is_over_the_area_on_a_star(tmp_path, monkeypatch, spy_before_after):
    """A central bump no effect of the library explains whole: gap_before over the area (the points'
    RMS read 2.2×), and gap_after, unexplained.rms_um and the last found effect's gap_after the area
    RMS of the selection's residual. The selection itself (its F tests, BIC, σ) is the points'."""
    import pointspro.core.explain.workflow as wf
    from pointspro.core.io import write_csv

    x, y, c = star(step=1.0)  # 1,212 points: the correlated-noise test's Cholesky is O(N³)
    t = np.arange(x.size) * 0.01
    rng = np.random.default_rng(0)
    write_csv(PointCloud.from_xyz(x, y, bump(x, y) + rng.normal(0, 2e-6, x.size), t=t, c=c), tmp_path / "m.csv")
    write_csv(PointCloud.from_xyz(x, y, np.zeros_like(x), t=t, c=c), tmp_path / "s.csv")
    seen, real = {}, wf.select

    def spy(*args, **kwargs):
        seen["res"] = real(*args, **kwargs)
        return seen["res"]

    monkeypatch.setattr(wf, "select", spy)
    rep = wf.explain(tmp_path / "m.csv", tmp_path / "o", simulated=tmp_path / "s.csv", bootstrap=0)
    saved = json.loads((tmp_path / "o" / "explain.json").read_text(encoding="utf-8"))
    assert saved["gap_before"] == rep["gap_before"]
    w = area_weights(x, y)
    gap = rep_gap(tmp_path)  # the bump and 2 nm of noise (< 0.1 % of its RMS in quadrature)
    close_to_area_far_from_points(rep["gap_before"]["rms_um"] * 1e-3, gap, area_truth(x, y, bump), rel=0.05)
    after = seen["res"]["residual"]
    assert rep["verdict"] == "unexplained" and rep["found"]
    assert rep["gap_after"]["rms_um"] == pytest.approx(weighted_rms(after, w) * 1e3, rel=1e-12)
    assert abs(plain(after) / weighted_rms(after, w) - 1) > 0.10
    assert rep["unexplained"]["rms_um"] == rep["gap_after"]["rms_um"]
    assert rep["found"][-1]["gap_after"]["rms_um"] == pytest.approx(rep["gap_after"]["rms_um"], rel=1e-12)
    assert rep["gap_before"]["pv_um"] == float(np.ptp(gap) * 1e3)  # the PV as before
    # the selection's own figures are the points': its σ and residual RMS against σ as without weights
    assert rep["checks"]["residual_rms_over_noise"] == seen["res"]["rms"] / max(seen["res"]["sigma"], 1e-300)
    assert len(spy_before_after) == 1 and np.array_equal(spy_before_after[0], w)


def rep_gap(tmp_path):
    from pointspro.core.io import read_cloud

    return read_cloud(tmp_path / "m.csv").z - read_cloud(tmp_path / "s.csv").z


def test_explain_stats_on_an_even_sampling_are_the_plain_mean_to_the_last_bit():
    from pointspro.core.explain.workflow import _stats

    x, y = raster()
    assert area_weights(x, y) is None  # what explain() hands _stats on a raster
    v = spherical(x, y) + np.random.default_rng(1).normal(0, 1e-5, x.size)
    assert _stats(v, area_weights(x, y)) == {"rms_um": float(np.sqrt(np.mean((v - v.mean()) ** 2)) * 1e3),
                                             "pv_um": float(np.ptp(v) * 1e3)}

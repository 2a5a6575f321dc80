"""`correction` after an independent review (E): an off-axis part's radial program, the removal
map's material side, an annular or off-centre `aperture`, a near-hemisphere's extension, the radial
table's number format, a flat on a lathe, and the depth limit inside the clear aperture."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.correction.files import read_comment_csv
from pointspro.core.errors import StepError
from pointspro.core.surfaces import EvenAsphere, surface_from_spec

from .test_correction import _grid_of, _run, _write_all


def _cloud(fn, centre=(0.0, 0.0), radius=10.0, h=0.25, inner=0.0):
    """A regular-grid error map fn(x, y) (mm) over the disk (ring) about ``centre``, as a cloud with a
    residual."""
    g = np.arange(-radius, radius + h / 2, h)
    X, Y = np.meshgrid(g + centre[0], g + centre[1])
    R = np.hypot(X - centre[0], Y - centre[1])
    keep = (R <= radius) & (R >= inner)
    x, y = X[keep], Y[keep]
    return PointCloud.from_xyz(x, y, np.zeros_like(x), residual=fn(x, y))


def _with(cloud, step, **params):
    return cloud.with_provenance({"id": step, "params": params})


def _aperture(cloud, diameter, center_x=0.0, center_y=0.0, inner_diameter=0.0):
    shape = "annulus" if inner_diameter > 0 else "circle"
    return _with(cloud, "aperture", shape=shape, diameter=diameter, inner_diameter=inner_diameter,
                 center_x=center_x, center_y=center_y, vertices=[])


PARENT = EvenAsphere(0.02, -1.0, {4: 1e-6}, aperture=60.0)


def _zone_error(x, y):
    return 1e-4 * np.cos((x - 15.0) / 3.0) * np.exp(-(y / 7.0) ** 2) + 5e-5 * ((x - 15) / 10) ** 3


def _arc_means(xs, ys, dz, r, centre, radius):
    """The mean of dz (bilinear on the written grid) over the arc of each ring about the axis that
    lies on the part, 20 000 samples per ring."""
    from scipy.interpolate import RegularGridInterpolator

    it = RegularGridInterpolator((ys, xs), dz, bounds_error=False, fill_value=np.nan)
    th = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    out = []
    for ri in r:
        px, py = ri * np.cos(th), ri * np.sin(th)
        on = np.hypot(px - centre[0], py - centre[1]) <= radius
        out.append(np.nanmean(it((py[on], px[on]))) if on.any() else np.nan)
    return np.array(out)


def test_off_axis_part_radial_program_is_the_arc_mean_over_the_part(tmp_path):
    """A Ø20 zone at x = 15 of the parent: the radial program covers r = 5…25 about the parent's axis
    (not 0…12, edge-clamped off the map), each row the mean of dz over the ring's arc on the part,
    no row at r = 0; the corrected surface is fitted to those rows."""
    cloud = _cloud(_zone_error, centre=(15.0, 0.0))
    res = _run(cloud, PARENT, cutoff_mm=2.0, diameter=20.0, centre=[15.0, 0.0],
               outputs=["cutting", "radial"])
    out = _write_all(res, tmp_path / "o")
    comments, header, d = read_comment_csv(out / "correction_radial.csv")
    r, mean = d[:, 0], d[:, 1]
    # the rings that only touch the part (r = 5, 25: one rim point) are no arc on it
    assert r[0] == pytest.approx(5.25) and r[-1] == pytest.approx(24.75)
    assert np.any(np.isclose(r, 15.0)) and np.any(np.isclose(r, 20.0)) and not np.any(r < 5.0)
    assert any("off-axis part" in c for c in comments)
    xs, ys, dz, _, _ = _grid_of(out / "correction.csv")
    mine = _arc_means(xs, ys, dz, r, (15.0, 0.0), 10.0)
    assert np.max(np.abs(mean - mine)) < 2e-7  # mm: 0.2 nm of a ~100 nm correction
    rad = res.report["radial"]
    assert rad["r_range_mm"] == [pytest.approx(5.25), pytest.approx(24.75)] and rad["off_axis_mm"] == 15.0
    info = res.report["corrected_surface"]
    assert info["fit_rms_nm"] <= 1.0
    surf = surface_from_spec(info["surface"])
    err = surf.sag_r(r) + info["vertex_offset_um"] * 1e-3 - PARENT.sag_r(r) - mean
    assert np.max(np.abs(err)) < 3e-6  # every row, the shortest arcs too


def test_an_off_centre_aperture_step_gives_the_correction_its_centre():
    """`aperture {diameter: 20, center_x: 15}` and no `centre` on the correction: its diameter was
    taken about the axis and the step refused "covers 15.7 % … no data from r = 0"."""
    cloud = _aperture(_cloud(_zone_error, centre=(15.0, 0.0)), 20.0, center_x=15.0)
    rep = _run(cloud, PARENT, cutoff_mm=2.0, outputs=["cutting", "radial"]).report
    assert rep["centre_mm"] == [15.0, 0.0] and "aperture" in rep["centre_from"]
    assert rep["diameter_mm"] == 20.0 and rep["coverage"] >= 0.99
    assert rep["radial"]["r_range_mm"][0] == pytest.approx(5.25)


def test_a_coverage_refusal_advises_only_what_can_help():
    """Data off the centre: no smaller diameter is covered, so the message says to give the centre;
    data over the inner Ø30 of a Ø40 aperture: a diameter the map covers is named; a ring of data:
    an annulus, never a smaller diameter."""
    off = _cloud(_zone_error, centre=(15.0, 0.0))
    with pytest.raises(StepError) as e:
        _run(off, PARENT, cutoff_mm=2.0, diameter=20.0)
    msg = str(e.value)
    assert "\n" not in msg and "smaller diameter" not in msg and "diameter ≤" not in msg
    assert "centre" in msg
    part = _cloud(lambda x, y: 1e-5 * np.cos(x / 5), radius=15.0)
    with pytest.raises(StepError) as e:
        _run(part, PARENT, cutoff_mm=2.0, diameter=40.0)
    assert "give diameter ≤ 30" in str(e.value) and "annulus" not in str(e.value)
    ring = _cloud(lambda x, y: 1e-5 * np.cos(x / 5), radius=20.0, inner=5.0)  # no `aperture` annulus
    with pytest.raises(StepError) as e:
        _run(ring, PARENT, cutoff_mm=2.0, diameter=40.0)
    assert "annulus with inner_diameter ≥" in str(e.value) and "diameter ≤" not in str(e.value)


def test_an_annular_aperture_is_covered_over_its_ring():
    """`aperture {shape: annulus, diameter: 40, inner_diameter: 8}`: refused "covers 96.1 % … give a
    smaller diameter" (the hole counted as missing data)."""
    cloud = _aperture(_cloud(lambda x, y: 1e-4 * np.cos(x / 6) * np.sin(y / 9), radius=20.0, h=0.5,
                             inner=4.0), 40.0, inner_diameter=8.0)
    res = _run(cloud, PARENT, cutoff_mm=2.0)
    rep = res.report
    assert rep["inner_diameter_mm"] == 8.0 and rep["coverage"] >= 0.99
    assert "cutting" in rep["outputs"] and "radial" in rep["outputs"]


def _bump(x, y):
    return 3e-4 * np.exp(-((x - 4.0) ** 2 + y ** 2) / (2 * 3.0 ** 2))


@pytest.mark.parametrize("side", [None, 1, -1])
def test_the_removal_map_takes_material_from_the_side_that_has_too_much(side, tmp_path):
    """Probe centres measured from below (probe_radius side −1): the part's material lies above the
    surface, so a high spot (z − sag > 0) lacks material and a low one has too much. The map said to
    remove the most where the part lacked it. dz stays geometric."""
    cloud = _cloud(_bump, radius=20.0, h=0.5)
    if side is not None:
        cloud = _with(cloud, "probe_radius", radius=1.0, side=side)
    res = _run(cloud, None, diameter=40.0, cutoff_mm=2.0, outputs=["cutting", "polishing"])
    out = _write_all(res, tmp_path / "o")
    xs, ys, rem, comments, _ = _grid_of(out / "removal.csv")
    _, _, dz, _, _ = _grid_of(out / "correction.csv")
    X, Y = np.meshgrid(xs, ys)
    spot = np.argmin(np.hypot(X - 4.0, Y))  # the high spot
    inside = np.hypot(X, Y) <= 20.0
    assert dz.flat[spot] < -2e-4  # geometric: cut lower, whatever the side
    rep = res.report["removal"]
    if side == -1:
        assert rem.flat[spot] < 0.05 * np.nanmax(rem[inside])  # nothing to remove where material lacks
        assert rep["probe_side"] == -1 and "below" in rep["material"]
        assert any("seen from below" in c for c in comments)
    else:
        assert rem.flat[spot] == pytest.approx(np.nanmax(rem[inside]), rel=1e-6)
        assert rep["probe_side"] == 1
        assert ("instrument" in rep["material"]) == (side is None)
    assert np.nanmin(rem) == pytest.approx(0.0, abs=1e-9)


def test_the_depth_limit_is_judged_inside_the_clear_aperture():
    """max_depth_um reported and limited over the clear aperture; the run-out ring beyond it (no part)
    is reported apart (a review: 0.442 µm with the ring against 0.422 µm inside, and a limit between
    them refused)."""
    cloud = _cloud(lambda x, y: 2e-4 * (x / 20.0) ** 3 + 5e-5 * np.cos(y / 4), radius=20.0, h=0.5)
    rep = _run(cloud, None, diameter=40.0, cutoff_mm=2.0, outputs=["polishing"]).report["removal"]
    inside, written = rep["max_depth_um"], rep["max_depth_written_um"]
    assert written > inside * 1.01
    limit = 0.5 * (inside + written)
    ok = _run(cloud, None, diameter=40.0, cutoff_mm=2.0, outputs=["polishing"], max_depth_um=limit)
    assert ok.report["removal"]["max_depth_um"] == pytest.approx(inside)
    with pytest.raises(StepError, match="inside the clear aperture.*max_depth_um"):
        _run(cloud, None, diameter=40.0, cutoff_mm=2.0, outputs=["polishing"], max_depth_um=0.99 * inside)


SPHERE = EvenAsphere(0.04, 0.0, aperture=46.0)  # R 25 mm: exists to r = 25 mm


def test_a_near_hemisphere_clamps_its_default_extension_to_the_surface():
    """Ø46 of a sphere R 25: the default extension (one cutoff, 3 mm) took the program to r = 26 mm,
    beyond the sphere, and the whole step failed; now clamped with a warning. An explicit extend_mm
    beyond it is refused naming the largest that works, and that one works."""
    cloud = _cloud(lambda x, y: 1e-4 * np.cos(x / 6), radius=23.5, h=0.5)
    res = _run(cloud, SPHERE, cutoff_mm=3.0)
    rep = res.report
    assert set(rep["outputs"]) == {"cutting", "radial", "freeform", "polishing"}
    assert rep["extend_mm"] == pytest.approx(1.999)
    assert any("extend_mm defaults to one cutoff" in w and "25 mm" in w for w in rep["warnings"])
    assert rep["radial"]["r_range_mm"][1] <= 25.0 and "corrected_surface" in rep
    with pytest.raises(StepError) as e:
        _run(cloud, SPHERE, cutoff_mm=3.0, extend_mm=3.0)
    msg = str(e.value)
    assert "extend_mm 3 mm" in msg and "extend_mm ≤ 1.999" in msg and "\n" not in msg
    assert _run(cloud, SPHERE, cutoff_mm=3.0, extend_mm=1.999).report["extend_mm"] == 1.999


def test_the_radial_table_is_fixed_point_as_documented(tmp_path):
    """correction_radial.csv was written with repr (-9.263000727204912e-05, r 1.2000000000000002);
    docs/conventions.md promises fixed point, 12 decimals in mm, like the grid files."""
    res = _run(_cloud(lambda x, y: 1e-4 * (np.hypot(x, y) / 20) ** 4 + 3e-9 * x, radius=20.0, h=0.2),
               PARENT, cutoff_mm=2.0, diameter=40.0, outputs=["radial"])
    out = _write_all(res, tmp_path / "o")
    rows = [ln for ln in (out / "correction_radial.csv").read_text(encoding="utf-8").splitlines()
            if not ln.startswith("#")][1:]
    assert rows and not any("e" in ln.lower() for ln in rows)
    r_txt = [ln.split(",")[0] for ln in rows]
    assert r_txt[:7] == ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0", "1.2"]
    assert all(len(ln.split(",")[1].split(".")[1]) <= 12 for ln in rows)


def test_a_flat_faced_on_a_lathe_gets_a_radial_program(tmp_path):
    """A flat nominal with outputs [radial] was refused "needs a rotationally symmetric nominal
    (even_asphere…); this one is even_asphere". A faced flat's program is sag 0 + dz(r) about the
    part's centre on the spindle."""
    flat = EvenAsphere(0.0, 0.0, aperture=40.0)
    centre = (100.0, 50.0)
    cloud = _cloud(lambda x, y: 1e-4 * (np.hypot(x - centre[0], y - centre[1]) / 20) ** 2, centre=centre,
                   radius=20.0, h=0.5)
    res = _run(cloud, flat, cutoff_mm=2.0, outputs=["radial"])
    rep = res.report
    assert rep["radial"]["axis_mm"] == [pytest.approx(100.0), pytest.approx(50.0)]
    out = _write_all(res, tmp_path / "o")
    _, _, d = read_comment_csv(out / "correction_radial.csv")
    r, mean = d[:, 0], d[:, 1]
    ins = r <= 18.0
    # dz = −E less its piston: −1e-4 (r/20)² about the centre
    want = -1e-4 * (r[ins] / 20) ** 2
    assert np.max(np.abs((mean[ins] - mean[0]) - (want - want[0]))) < 2e-7
    assert rep["corrected_surface"]["fit_rms_nm"] <= 1.0 and (out / "corrected_surface.yaml").exists()
    # the default outputs of a flat include the radial program now
    assert "radial" in _run(cloud, flat, cutoff_mm=2.0).report["outputs"]


def _turned_down_edge(x, y):
    r = np.hypot(x, y)
    return 1e-4 * np.exp(-(x**2 + y**2) / (2 * 8**2)) - 3e-4 * np.clip((r - 22) / 3, 0, 1) ** 2


def test_the_removal_maps_zero_lies_in_the_clear_aperture():
    """A turned-down edge: the continuation beyond the rim kept its low value and the filter lifted
    the rim's inside, so the whole map's minimum lay in the run-out ring — every polishing job took
    51 nm more everywhere (+15 % depth, +21 % volume) for nothing, and min_depth_um, over the whole
    map, said 0 (a review). The zero is now the aperture's minimum; the ring is clipped at 0."""
    nom = EvenAsphere(1 / 200.0, -0.5, {}, aperture=50.0)
    cloud = _cloud(_turned_down_edge, radius=25.0, h=0.25)
    deep = []
    for extend in (None, 0.0):
        p = {} if extend is None else {"extend_mm": extend}
        rep = _run(cloud, nom, outputs=["polishing"], cutoff_mm=4.0, **p).report["removal"]
        assert rep["min_depth_um"] == pytest.approx(0.0, abs=1e-9)
        deep.append(rep["max_depth_um"])
    assert deep[0] == pytest.approx(deep[1], rel=1e-6)  # the run-out adds nothing to the part's removal


def test_an_error_map_in_nm_read_as_mm_is_refused_naming_the_unit():
    """An instrument's error map written "x,y,z" with z in nm is read as mm (the documented default):
    the correction was a 99 mm deep removal on a 40 mm part, status ok (a review). Its slopes (rad)
    no form error has: refused, naming the header's unit; heights in µm read as mm are warned of."""
    g = np.arange(-20.0, 20.01, 0.5)
    X, Y = np.meshgrid(g, g)
    keep = np.hypot(X, Y) <= 20.0
    x, y = X[keep], Y[keep]
    bump_mm = 1e-4 * np.exp(-(x**2 + y**2) / (2 * 4.0**2))  # 100 nm
    for cutoff in (2.0, 40.0):  # a cutoff as wide as the part too (a big tool: the check was skipped)
        with pytest.raises(StepError, match=r"rad.*read as mm.*z \[nm\]"):
            _run(PointCloud.from_xyz(x, y, bump_mm * 1e6), None, diameter=40.0, cutoff_mm=cutoff, channel="z")
    rep = _run(PointCloud.from_xyz(x, y, bump_mm * 1e3), None, diameter=40.0, cutoff_mm=2.0,
               channel="z").report  # in µm, read as mm: 0.1 mm deep
    assert any("µm PV" in w and "unit" in w for w in rep["warnings"])
    rep = _run(PointCloud.from_xyz(x, y, bump_mm), None, diameter=40.0, cutoff_mm=2.0, channel="z").report
    assert not any("unit" in w for w in rep["warnings"])


def test_the_correction_x3p_files_say_what_their_heights_mean(tmp_path):
    """correction.x3p (dz to add) and removal.x3p (material to remove) were plain height maps, nothing
    telling them from a form-error map.x3p of the opposite sign (a review): Record2's Comment states
    the convention."""
    import x3pio

    res = _run(_cloud(_bump, radius=20.0, h=0.5), None, diameter=40.0, cutoff_mm=2.0,
               outputs=["cutting", "polishing"])
    out = _write_all(res, tmp_path / "o")
    dz = x3pio.read(str(out / "correction.x3p")).metadata.comment
    rem = x3pio.read(str(out / "removal.x3p")).metadata.comment
    assert "height to ADD" in dz and "metres" in dz
    assert "REMOVE" in rem and "metres" in rem


def test_grid_files_write_the_nodes_as_their_decimals(tmp_path):
    """x, y of correction.csv were Python's repr of x0 + k·h: -2.8000000000000003 (a review)."""
    res = _run(_cloud(_bump, radius=20.0, h=0.2), None, diameter=40.0, cutoff_mm=2.0,
               outputs=["cutting", "polishing"])
    out = _write_all(res, tmp_path / "o")
    for name in ("correction.csv", "removal.csv"):
        rows = [ln.split(",") for ln in (out / name).read_text(encoding="utf-8").splitlines()
                if not ln.startswith("#")][1:]
        coords = [v for r in rows for v in r[:2]]
        assert max(len(v.split(".")[1]) for v in coords) == 1, name  # 0.2 mm nodes: one decimal
        assert "-2.8" in coords


def test_a_programmed_surface_key_without_a_value_is_named_with_the_fix():
    """`{type:even_asphere, R:-200}` (YAML: keys with no value) gave four lines of pydantic's union
    ("….float: Input should be a valid number (got None); ….bool …") — a review."""
    from pydantic import ValidationError

    from pointspro.plugins.correction import CorrectionParams

    with pytest.raises(ValidationError) as e:
        CorrectionParams.model_validate({"programmed_surface": {"type:even_asphere": None, "R:-200": None}})
    text = str(e.value)
    assert "key 'type:even_asphere' has no value: write `type: even_asphere`" in text
    assert text.count("Input should be") == 0


@pytest.mark.parametrize("pixel_um, diameter_mm", [(0.2, 0.1), (0.5, 0.25)])
def test_a_fine_pixel_maps_noise_is_no_unit_mistake(pixel_um, diameter_mm):
    """A micro-lens measured by an optical profiler (0.2–0.5 µm pixels, 40 nm PV of form error, 30 nm of
    noise) was refused as "heights in µm or nm read as mm": the raw map's node-to-node slope of its
    noise reads 0.1 rad. The plausibility check takes the slope of the low-passed error over the
    cutoff (a review of the check)."""
    rng = np.random.default_rng(0)
    h = pixel_um * 1e-3
    g = np.arange(-diameter_mm / 2, diameter_mm / 2 + h / 2, h)
    X, Y = np.meshgrid(g, g)
    keep = np.hypot(X, Y) <= diameter_mm / 2
    x, y = X[keep], Y[keep]
    z = 40e-6 * ((2 * np.hypot(x, y) / diameter_mm) ** 2 - 0.5) + 30e-6 * rng.standard_normal(x.size)
    rep = _run(PointCloud.from_xyz(x, y, z), None, diameter=diameter_mm, channel="z").report
    assert rep["correction_pv_um"] > 0.01 and not any("unit" in w for w in rep["warnings"])


def test_a_programmed_surface_may_say_null_as_the_recipes_surface_may():
    """`aperture: null` is accepted by surface_from_spec; the typo check refused it (a review)."""
    from pointspro.plugins.correction import CorrectionParams

    p = CorrectionParams.model_validate(
        {"programmed_surface": {"type": "even_asphere", "c": 0.005, "k": 0, "aperture": None}})
    assert p.programmed_surface["aperture"] is None

"""An independent review of the kinematic error map and its compensation (paper 003), from a generator
of its own: the truth e(X, c) = −EZX(X) + EZC(c) − X·(EBC(c) + EB0C), X the probe's signed position on
the X slide, the point probed on the workpiece X·(cos c, −sin c) (core.kinematics.htm's frame).

1. EZX was held at the straightness scan's end value (np.interp) wherever the squareness scans went
   beyond it: straightness over x 0–19 mm, squareness ±19 mm gave EB0C −0.176″ for +0.08″ and a map off
   by 6.9 nm RMS, without a word. Now EB0C is fitted where EZX is known, symmetric about the axis, with
   a warning naming both ranges, or refused saying how far the straightness scan must reach.
2. `kinematic` read every point at r = √(x² + y²), the probe on +X: a scan through the centre was made
   worse at X < 0 (26.6 nm RMS left against 17.9 nm before, flatness 79.5 → 120.9 nm) with no warning.
   Now X is signed, from x, y and c; a map of X ≥ 0 only is refused for such points; a compensation
   that worsens the flatness is warned.
3. A one-sided squareness scan (x 0–19 mm) put the flat's power into EB0C (−0.245″ for 0.08″): the
   reversal needs the flat read on both sides of the axis — refused.
"""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import InputError, StepError
from pointspro.core.kinematics.errormap import KinematicMap
from pointspro.core.kinematics.htm import TurningMachine
from pointspro.core.step import Context
from pointspro.plugins.kinematic import KinematicStep, flatness
from pointspro.plugins.kinematic_map import KinematicMapStep

AS = np.pi / 180 / 3600
R, L, NOISE = 19.0, 10.0, 0.3e-6   # mm; probe noise 0.3 nm
EB0C = 0.08 * AS


def ezx(x):
    x = np.asarray(x, dtype=np.float64)
    return 50e-6 * (0.6 * ((x / R) ** 2 - 1 / 3) + 0.4 * np.sin(2.3 * np.pi * x / R + 0.7))


def ezc(c):
    return 3e-6 + 4e-6 * np.cos(np.deg2rad(3 * np.asarray(c, dtype=np.float64)) + 1.0)


def ebc(c):
    a = np.deg2rad(np.asarray(c, dtype=np.float64))
    return (0.1 * np.cos(2 * a + 0.5) + 0.03 * np.sin(5 * a + 0.2)) * AS


def truth(x, c):
    return -ezx(x) + ezc(c) - np.asarray(x) * (ebc(c) + EB0C)


def flat(x):
    """The artefact's profile along a line through its centre: mostly power (the even form)."""
    return 30e-6 * (np.asarray(x) / R) ** 2 + 8e-6 * np.sin(3 * np.asarray(x) / R)


def _csv(path, header, *cols):
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.17g",
               encoding="utf-8")


def reversal_files(folder, seed, st=(-R, R), sq=(-R, R), theta=2.0 * AS):
    rng = np.random.default_rng(seed)
    n = lambda k: rng.normal(0, NOISE, k)  # noqa: E731
    x = np.linspace(st[0], st[1], int(round((st[1] - st[0]) / 0.25)) + 1)
    _csv(folder / "straightness.csv", "x,m1,m2", x, flat(x) - ezx(x) + n(x.size), flat(x) + ezx(x) + n(x.size))
    c = np.arange(0, 360, 1.0)
    F, G = 6e-6 * np.cos(np.deg2rad(2 * c) + 1.2), 2e-6 * np.cos(np.deg2rad(3 * c))
    _csv(folder / "facial.csv", "c,m1,m2,m3,m4", c, F + ezc(c) - L * ebc(c) + n(c.size),
         G + ezc(c) + n(c.size), -G + ezc(c) + n(c.size), F + ezc(c) + L * ebc(c) + n(c.size))
    xs = np.linspace(sq[0], sq[1], int(round((sq[1] - sq[0]) / 0.5)) + 1)
    s0 = flat(xs) + theta * xs + truth(xs, 0.0) + n(xs.size)       # the flat on the chuck, c = 0
    s180 = flat(-xs) - theta * xs + truth(xs, 180.0) + n(xs.size)  # turned 180°: read at −x
    _csv(folder / "squareness.csv", "x,m1,m2", xs, s0, s180)


def build(folder, **kw):
    return KinematicMapStep().run(PointCloud.from_xyz([0.0], [0.0], [0.0]), KinematicMapStep.Params(
        straightness="straightness.csv", facial="facial.csv", probe_distance=L, squareness="squareness.csv",
        **kw), Context(base_dir=folder))


@pytest.mark.parametrize("st, sq, fitted", [((-6.0, R), (-R, R), 6.0), ((-R, R), (-10.0, R), 10.0)])
def test_eb0c_fitted_where_ezx_is_known_and_symmetric(tmp_path, st, sq, fitted):
    """Straightness from −6 mm (or squareness from −10 mm) against squareness ±19 mm: EB0C from |x| ≤ 6
    (10) mm, within its noise of the truth, with a warning naming both ranges — not EZX held beyond
    the straightness scan (0.08″ read as 0.01–0.03″) nor the flat's power over an asymmetric range."""
    reversal_files(tmp_path, seed=2)                      # full scans first: no word
    rep = build(tmp_path).report
    assert rep["eb0c_arcsec"] == pytest.approx(0.08, abs=0.01)
    assert rep["warnings"] == []
    reversal_files(tmp_path, seed=2, st=st, sq=sq)
    rep = build(tmp_path).report
    assert rep["eb0c_arcsec"] == pytest.approx(0.08, abs=0.01), rep["eb0c_arcsec"]
    (w,) = [w for w in rep["warnings"] if w.startswith("squareness:")]
    assert f"|x| ≤ {fitted:g} mm" in w
    assert f"the squareness scan covers x {sq[0]:g}…{sq[1]:g} mm" in w
    assert f"the straightness scan x {st[0]:g}…{st[1]:g} mm" in w
    assert "not extrapolated" in w
    assert rep["x_range_mm"] == [st[0], R]  # the map stops where EZX does


def test_straightness_on_one_side_of_the_axis_is_refused_saying_what_is_needed(tmp_path):
    """Straightness over x 0–19 mm: EZX unknown at x < 0, so no squareness range symmetric about the
    axis is left — refused, naming both ranges and how far the straightness scan must reach (it gave
    −0.176″ for 0.08″)."""
    reversal_files(tmp_path, seed=3, st=(0.0, R))
    with pytest.raises(InputError, match=r"squareness\.csv: the kinematic_map step fits EB0C where the "
                                         r"straightness scan .* gives EZX.* covers x 0…19 mm and the squareness "
                                         r"scan x -19…19 mm .* at least 3 samples on each side are needed: the "
                                         r"straightness scan must cover x from −1\.5 to 1\.5 mm or more"):
        build(tmp_path)
    # without the squareness scan the map is built (EB0C = 0), over X ≥ 0 only
    rep = KinematicMapStep().run(PointCloud.from_xyz([0.0], [0.0], [0.0]), KinematicMapStep.Params(
        straightness="straightness.csv", facial="facial.csv", probe_distance=L), Context(base_dir=tmp_path)).report
    assert rep["x_range_mm"] == [0.0, R] and rep["eb0c_arcsec"] == 0.0


def test_one_sided_squareness_is_refused(tmp_path):
    """Squareness over x 0–19 mm only: turned by 180° the flat is read at −x, never at the same points,
    and its power went into EB0C (−0.245″ for 0.08″). The method needs both sides: refused."""
    reversal_files(tmp_path, seed=4, sq=(0.0, R))
    with pytest.raises(InputError, match=r"squareness\.csv: the kinematic_map step's squareness reversal needs "
                                         r"the scans across the spindle axis, at least 3 samples on each side of "
                                         r"x = 0 .* the file covers x 0…19 mm \(39 samples, 0 at x < 0, 38 at "
                                         r"x > 0\) — scan the flat through its centre"):
        build(tmp_path)


def cross_scan(seed=5, n=6000, sense=-1):
    """A spiral through the centre: the probe from X = +R to −R, the point probed X·(cos c, sense·sin c)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)
    X, c = R * (1 - 2 * t), (t * 50 * 360.0) % 360.0
    xw, yw = X * np.cos(np.deg2rad(c)), sense * X * np.sin(np.deg2rad(c))
    S = 15e-6 * (xw / R) ** 2 - 6e-6 * xw * yw / R**2 + 1e-5 * xw / R   # the part's own surface
    return X, xw, yw, S + truth(X, c) + rng.normal(0, NOISE, n), c, S


@pytest.mark.parametrize("sense", [-1, 1])
def test_scan_through_the_centre_is_compensated_on_both_sides(tmp_path, sense):
    """At X < 0 the map was read at |X|: 26.6 nm RMS left against 17.9 nm before. Now X is signed (003's
    frame, or the other sense of c that `pointspro simulate` writes) and the residual is the noise's."""
    m = TurningMachine({"EZX": ezx, "EZC": ezc, "EBC": ebc, "EB0C": EB0C})  # the generator is the project's
    xm, cm = np.array([-17.0, -12.0, -3.0, 4.0, 18.0]), np.array([10.0, 30.0, 200.0, 300.0, 180.0])
    assert np.allclose(m.measurement_error(xm, cm), truth(xm, cm), atol=1e-12)  # machine, both sides
    reversal_files(tmp_path, seed=6)
    (tmp_path / "map.json").write_text(build(tmp_path).artifacts["kinematic_map.json"], encoding="utf-8")
    X, x, y, z, c, S = cross_scan(sense=sense)
    out = KinematicStep().run(PointCloud.from_xyz(x, y, z, c=c), KinematicStep.Params(map="map.json"),
                              Context(base_dir=tmp_path))
    left = out.cloud.z - S
    neg = X < 0
    before = np.std((z - S)[neg]) * 1e6
    assert before > 10                                       # the machine's error is there to remove
    assert np.std(left[neg]) * 1e6 < 1.5, np.std(left[neg]) * 1e6
    assert np.std(left[~neg]) * 1e6 < 1.5
    assert np.allclose(out.cloud["kinematic_error"], truth(X, c), atol=2e-6)  # 2 nm
    rep = out.report
    assert rep["flatness_after_nm"] < 0.5 * rep["flatness_before_nm"]
    assert rep["flatness_after_nm"] == pytest.approx(flatness(x, y, out.cloud.z) * 1e6)
    assert rep["points_at_negative_x"] == int(neg.sum()) and rep["warnings"] == []


def test_map_without_negative_x_refuses_a_scan_through_the_centre(tmp_path):
    """A map of X ≥ 0 only (older, or from a straightness scan that starts at the axis) cannot give
    e(X, c) at X < 0: refused, not read at |X|; `probe_x: radius` (the user says the probe stays on +X)
    reads |X|, and the flatness made worse is then warned."""
    reversal_files(tmp_path, seed=7)
    m = KinematicMap.from_json(build(tmp_path).artifacts["kinematic_map.json"])
    k = m.r >= 0
    (tmp_path / "half.json").write_text(KinematicMap(m.r[k], m.c_deg, m.e[k], m.components).to_json(),
                                        encoding="utf-8")
    X, x, y, z, c, S = cross_scan(seed=8)
    cloud = PointCloud.from_xyz(x, y, z, c=c)
    with pytest.raises(StepError, match=r"3000 of 6000 points have the probe at X < 0 \(down to -19 mm: the "
                                        r"scan crosses the spindle axis\).* the kinematic map covers X 0…19 mm"):
        KinematicStep().run(cloud, KinematicStep.Params(map="half.json"), Context(base_dir=tmp_path))
    rep = KinematicStep().run(cloud, KinematicStep.Params(map="half.json", probe_x="radius"),
                              Context(base_dir=tmp_path)).report
    assert rep["flatness_after_nm"] > rep["flatness_before_nm"]
    assert any("the compensation made the flatness worse" in w for w in rep["warnings"])


def test_points_off_the_probe_line_are_taken_on_plus_x_with_a_warning(tmp_path):
    """x, y not in the spindle's frame (here turned by 20°): the probe's side cannot be told; read at
    √(x² + y²) as before, and said."""
    reversal_files(tmp_path, seed=9)
    (tmp_path / "map.json").write_text(build(tmp_path).artifacts["kinematic_map.json"], encoding="utf-8")
    rng = np.random.default_rng(10)
    r, c = R * np.sqrt(rng.random(2000)), rng.uniform(0, 360, 2000)
    a = np.deg2rad(-c + 20.0)
    x, y = r * np.cos(a), r * np.sin(a)
    z = truth(r, c)
    out = KinematicStep().run(PointCloud.from_xyz(x, y, z, c=c), KinematicStep.Params(map="map.json"),
                              Context(base_dir=tmp_path))
    assert np.allclose(out.cloud["kinematic_error"], truth(r, c), atol=2e-6)
    (w,) = out.report["warnings"]
    assert "do not lie on the probe's line" in w and "taken on +X" in w
    quiet = KinematicStep().run(PointCloud.from_xyz(x, y, z, c=c),
                                KinematicStep.Params(map="map.json", probe_x="radius"), Context(base_dir=tmp_path))
    assert quiet.report["warnings"] == []


def test_a_map_with_a_nan_or_axes_not_increasing_is_refused_naming_the_key():
    """A review: a NaN in e_mm wrote NaN heights with exit 0; a descending r_mm read as "the scan
    crosses the centre"; a repeated c_deg gave the interpolator's internal error."""
    import json

    import pytest

    from pointspro.core.errors import InputError
    from pointspro.core.kinematics.errormap import KinematicMap

    good = {"pointspro_kinematic_map": 1, "r_mm": [-10.0, 0.0, 10.0], "c_deg": [0.0, 90.0, 180.0, 270.0],
            "e_mm": [[0.0] * 4, [1e-6] * 4, [2e-6] * 4]}
    assert KinematicMap.from_json(json.dumps(good), "m.json").e.shape == (3, 4)
    bad = [({"e_mm": [[0.0] * 4, [float("nan")] * 4, [2e-6] * 4]}, "key 'e_mm' holds values that are not finite"),
           ({"r_mm": [10.0, 0.0, -10.0]}, "key 'r_mm' is not strictly increasing"),
           ({"c_deg": [0.0, 90.0, 90.0, 270.0]}, "key 'c_deg' is not strictly increasing"),
           ({"c_deg": [0.0, 90.0, 180.0, 400.0]}, "spans more than one turn")]
    for change, words in bad:
        with pytest.raises(InputError, match=rf"m\.json: .*{words}"):
            KinematicMap.from_json(json.dumps(good | change), "m.json")

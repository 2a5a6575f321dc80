"""Stylus profiles (issue 19): reading x, z files, probe_radius's 2-D offset curve, misalignment in the
profile's plane, profile metrics, crossed profiles' astigmatism, bad input. Every case is simulated
here with a known truth (tilt, decentre, form error, noise) — core/simulate is not used."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core import PointCloud
from pointspro.core.errors import InputError, StepError
from pointspro.core.io import read_cloud
from pointspro.core.step import Context
from pointspro.core.surfaces import EvenAsphere
from pointspro.plugins.misalignment import MisalignmentStep
from pointspro.plugins.probe_radius import ProbeRadiusStep

ASPHERE = EvenAsphere(1 / 50.0, -0.8, {4: 2e-7, 6: -1e-10}, 40)  # R 50 mm across 40 mm
CONVEX = EvenAsphere(-1 / 80.0, -1.2, {4: -1e-7}, 50)  # c < 0: convex seen from +z (docs/surfaces.md)
STEEP = EvenAsphere(1 / 10.0, 0.0, {}, 12.8)  # a sphere R 10 mm to 39.8° slope at r = 6.4 mm


def form_error(u, amp_mm, seed):
    """A smooth form error of RMS ~amp (zones and ripple of random phases), its slope along u."""
    rng = np.random.default_rng(seed + 1000)
    e = np.zeros_like(u)
    de = np.zeros_like(u)
    for lam in (23.0, 9.7, 4.1, 1.7):
        k = 2 * np.pi / lam * rng.uniform(0.8, 1.2)
        a, ph = rng.uniform(0.4, 1.0), rng.uniform(0, 2 * np.pi)
        e += a * np.cos(k * u + ph)
        de -= a * k * np.sin(k * u + ph)
    s = amp_mm / np.std(e)
    return e * s, de * s


def simulate(surface, half, n, *, rho=0.0, side=1, tilt_deg=0.0, ds=0.0, dz=0.0, amp=0.0, noise=0.0,
             seed=0, angle=0.0):
    """A profile across the part's axis at azimuth ``angle``: the real surface f(|u|) + e(u), the tip
    (radius ρ) touching it along its own normal, the part posed in the profile's plane by the tilt
    and (ds, dz) (the x–z restriction of docs/conventions.md's pose: tilt = β at 0°), noise on z.
    Returns (xyz of the tip centres, xyz of the true contacts, both in the measuring frame, u, e)."""
    rng = np.random.default_rng(seed)
    u = np.linspace(-half, half, n) + rng.uniform(-0.2, 0.2) * (2 * half / n)
    f, fr, _ = surface.profile_r(np.abs(u))
    fu = np.sign(u) * fr
    e, de = form_error(u, amp, seed) if amp else (np.zeros_like(u), np.zeros_like(u))
    w = f + e
    m = np.column_stack([-(fu + de), np.ones_like(u)])
    m /= np.linalg.norm(m, axis=1)[:, None]
    t = np.radians(tilt_deg)
    c, s_ = np.cos(t), np.sin(t)

    def pose(pu, pw):
        return c * pu + s_ * pw + ds, -s_ * pu + c * pw + dz

    cs, cz = pose(u + side * rho * m[:, 0], w + side * rho * m[:, 1])
    ts, tz = pose(u, w)
    cz = cz + noise * rng.standard_normal(n)
    a = np.radians(angle)

    def xyz(sv, zv):
        return np.column_stack([sv * np.cos(a), sv * np.sin(a), zv])

    return xyz(cs, cz), xyz(ts, tz), u, e


def run(step, q, surface, **params):
    channels = params.pop("channels", {})
    return step().run(PointCloud(q, channels), step.Params(**params), Context(surface=surface))


def beyond_noise_nm(err_mm, noise_mm):
    """How much an error RMS exceeds the noise the data carry (in quadrature), nm."""
    rms = np.sqrt(np.mean(err_mm ** 2))
    return np.sqrt(max(rms ** 2 - noise_mm ** 2, 0.0)) * 1e6


# --- reading ---------------------------------------------------------------------------------------

def test_xz_file_reads_as_a_profile_at_azimuth_0_and_at_a_reader_angle(tmp_path):
    p = tmp_path / "talysurf.csv"
    p.write_text("x [µm],z [µm]\n-1000,3.5\n0,0\n1000,3.25\n2000,13\n", encoding="utf-8")
    c = read_cloud(p)
    assert np.array_equal(c.x, [-1.0, 0.0, 1.0, 2.0]) and np.array_equal(c.y, np.zeros(4))
    assert np.array_equal(c.z, [0.0035, 0.0, 0.00325, 0.013])
    assert np.array_equal(c["angle"], np.zeros(4)) and c.meta["profile"]["angle_deg"] == 0.0
    c30 = read_cloud(p, profile_angle_deg=30)
    assert np.allclose(c30.x, c.x * np.cos(np.radians(30)), rtol=0, atol=1e-15)
    assert np.allclose(c30.y, c.x * np.sin(np.radians(30)), rtol=0, atol=1e-15)
    assert np.all(c30["angle"] == 30.0)
    # a header-less two-column export is x, z
    q = tmp_path / "plain.txt"
    q.write_text("0 1\n0.5 1.25\n1.0 2\n", encoding="utf-8")
    assert np.array_equal(read_cloud(q).z, [1, 1.25, 2])


def test_several_profiles_in_one_file_stay_together(tmp_path):
    from pointspro.core.profiles import profiles_of

    p = tmp_path / "two.csv"
    rows = ["x,z,angle"] + [f"{x},{x * x / 100},0" for x in range(-5, 6)] + \
           [f"{x},{x * x / 100 + 1e-4},90" for x in range(-5, 6)]
    p.write_text("\n".join(rows) + "\n", encoding="utf-8")
    c = read_cloud(p)
    profs = profiles_of(c)
    assert [pr.angle_deg for pr in profs] == [0.0, 90.0] and [len(pr.rows) for pr in profs] == [11, 11]
    assert np.allclose(c.y[11:], np.arange(-5, 6), atol=1e-12) and np.allclose(c.x[11:], 0, atol=1e-12)
    assert np.allclose(profs[1].s, np.arange(-5, 6), atol=1e-12)


@pytest.mark.parametrize("text,pattern", [
    ("x,z\n0,1\n1,2\n1,3\n2,4\n", r"p.csv, line 4: x = 1 mm repeats line 3's — a profile holds one height"),
    ("x,z\n0,1\n1,2\n3,3\n2,4\n", r"p.csv, line 5: the scan is not monotonic in x \(1 → 3 → 2 mm\)"),
    ("x,z\n0,1\n", r"p.csv: a profile of 1 point"),
])
def test_bad_profile_files_are_one_line(tmp_path, text, pattern):
    p = tmp_path / "p.csv"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=pattern):
        read_cloud(p)


def test_profile_angle_option_is_validated(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("x,y,z\n0,0,1\n0.5,0.5,2\n1,1,3\n", encoding="utf-8")
    c = read_cloud(p, profile_angle_deg=45)  # an x, y, z line: the option names its scan direction
    assert np.all(c["angle"] == 45.0)
    from pointspro.core.profiles import profiles_of

    (prof,) = profiles_of(c)
    assert np.allclose(prof.s, np.sqrt(2) * np.array([0, 0.5, 1])) and np.allclose(prof.a, 0, atol=1e-15)
    q = tmp_path / "q.csv"
    q.write_text("x,z,angle\n0,1,0\n1,2,0\n", encoding="utf-8")
    with pytest.raises(InputError, match="q.csv: has its own angle column"):
        read_cloud(q, profile_angle_deg=30)
    with pytest.raises(InputError, match="key 'profile_angle_deg'"):
        read_cloud(p, profile_angle_deg="north")


# --- probe_radius: the 2-D offset curve -----------------------------------------------------------

@pytest.mark.parametrize("surface,half,rho,side", [
    (ASPHERE, 20.0, 0.002, 1), (ASPHERE, 20.0, 2.0, 1), (CONVEX, 25.0, 2.0, 1),
    (STEEP, 6.4, 0.002, 1), (STEEP, 6.4, 2.0, 1), (STEEP, 6.4, 2.0, -1),
])
def test_probe_radius_on_a_profile_is_exact(surface, half, rho, side):
    """Sub-nm against a constructed truth with a 2 µm and a 2 mm tip, to 40° slopes, both sides."""
    for seed in range(3):
        q, truth, _, _ = simulate(surface, half, 1500, rho=rho, side=side, tilt_deg=0.4 - 0.3 * seed,
                                  ds=0.05 * seed - 0.03, dz=2.0, seed=seed, angle=30.0 * seed)
        res = run(ProbeRadiusStep, q, surface, radius=rho, side=side,
                  channels={"angle": np.full(len(q), 30.0 * seed)})
        err = np.sqrt(np.mean((res.cloud.xyz - truth) ** 2, axis=0)) * 1e6
        assert np.all(err < 0.01), (seed, err)  # nm
        rep = res.report
        assert "decentre across the profile" in rep["not_determined"]
        if surface is STEEP:  # a sphere: a tilt in the plane is a decentre along it, and it says so
            assert any("sphere: a tilt in the profile's plane is a decentre along it" in w
                       for w in rep["warnings"])
            assert rep["decentre_mm"] == pytest.approx(0.05 * seed - 0.03 + 10 * np.radians(0.4 - 0.3 * seed),
                                                       abs=1e-4)  # tilt τ about the vertex ≈ decentre R·τ
            continue
        assert rep["tilt_deg"] == pytest.approx(0.4 - 0.3 * seed, abs=1e-7)
        assert rep["decentre_mm"] == pytest.approx(0.05 * seed - 0.03, abs=1e-6)


@pytest.mark.parametrize("surface,half,rho", [(ASPHERE, 20.0, 2.0), (STEEP, 6.4, 2.0), (STEEP, 6.4, 0.002)])
def test_probe_radius_with_form_error_refines_the_normals(surface, half, rho):
    """A real part (50 nm form error): its own normal, not the design's, carries the tip."""
    for seed in range(3):
        q, truth, _, _ = simulate(surface, half, 2000, rho=rho, tilt_deg=0.2, ds=0.02, dz=1.0, amp=50e-6,
                                  seed=seed)
        res = run(ProbeRadiusStep, q, surface, radius=rho)
        design = run(ProbeRadiusStep, q, surface, radius=rho, normals="design")
        # the error along the part's normal (what the form error reads) and along its tangent
        tang = np.column_stack([np.gradient(truth[:, 0]), np.gradient(truth[:, 2])])
        tang /= np.linalg.norm(tang, axis=1)[:, None]
        nrm = np.column_stack([-tang[:, 1], tang[:, 0]])
        d = (res.cloud.xyz - truth)[:, [0, 2]]
        along_normal = np.sqrt(np.mean(np.einsum("ij,ij->i", d, nrm)[5:-5] ** 2)) * 1e6
        assert along_normal < 0.01, seed  # nm
        tangential = np.sqrt(np.mean(np.einsum("ij,ij->i", d, tang) ** 2))
        d0 = (design.cloud.xyz - truth)[:, [0, 2]]
        if rho > 1:  # the design normals put a 2 mm tip's contacts ~0.25 µm off along the surface
            assert tangential < np.sqrt(np.mean(np.einsum("ij,ij->i", d0, tang) ** 2)) / 4, seed


# --- misalignment in the profile's plane, and the goal ------------------------------------

def goal_case(surface, half, seed, n=2000, angle=0.0):
    return simulate(surface, half, n, rho=0.002, tilt_deg=[0.3, -0.5, 0.15][seed % 3],
                    ds=[0.08, -0.05, 0.12][seed % 3], dz=[1.5, -0.4, 0.2][seed % 3], amp=50e-6,
                    noise=5e-6, seed=seed, angle=angle)


def recovered(surface, q, angle=0.0, **mis):
    pr = run(ProbeRadiusStep, q, surface, radius=0.002, channels={"angle": np.full(len(q), angle)})
    return run(MisalignmentStep, pr.cloud.xyz, surface, channels=dict(pr.cloud.channels), **mis)


@pytest.mark.parametrize("surface,half", [(ASPHERE, 20.0), (CONVEX, 20.0),
                                          (EvenAsphere(1 / 50.0, -2.0, {4: 5e-7}, 40), 20.0)])
def test_goal_form_error_recovered_at_each_contact_point(surface, half):
    """Issue 19's goal: R 50 mm across 40 mm, 2 µm tip, tilted and decentred, 50 nm form error, 5 nm
    noise: the form error at each contact point within 1.5 nm RMS beyond the noise. The pose absorbs
    what of the form error looks like a pose (a tilt, a decentre's signature): that part is no form
    error a profile can show, so the truth is the form error less its projection on the fitted DOF."""
    for seed in range(4):
        q, truth, u, e = goal_case(surface, half, seed, angle=45.0 * seed)
        res = recovered(surface, q, 45.0 * seed)
        r = res.cloud["residual"]
        # the fitted DOF's signature at the truth (tilt, decentre along, height: Jacobian columns)
        from pointspro.core.profiles.fit import ProfileFit

        fit = ProfileFit(surface, u, surface.sag_r(np.abs(u)), ["tilt", "decentre", "dz"])
        _, J = fit.model(np.zeros(3), True)
        e_seen = e - J @ np.linalg.lstsq(J, e, rcond=None)[0]
        assert beyond_noise_nm(r - e_seen, 5e-6) <= 1.5, seed
        rep = res.report
        assert rep["rms_um"] == pytest.approx(np.std(e_seen) * 1e3, rel=0.1)
        assert rep["u_tilt_deg"] > 0 and rep["u_dz"] > 0 and res.cloud.frame == "part"
        t = np.radians(45.0 * seed)  # in the part frame on the profile's azimuth through the axis
        assert np.allclose(res.cloud.x * np.sin(t) - res.cloud.y * np.cos(t), 0, atol=1e-12)


def test_misalignment_recovers_the_pose_and_r_k_with_uncertainties():
    surface = ASPHERE
    q, _, u, _ = simulate(surface, 20.0, 3000, tilt_deg=0.25, ds=0.1, dz=0.7, noise=5e-6, seed=3)
    rep = run(MisalignmentStep, q, surface).report
    assert rep["tilt_deg"] == pytest.approx(0.25, abs=5 * rep["u_tilt_deg"])
    assert rep["decentre_mm"] == pytest.approx(0.1, abs=5 * rep["u_decentre_mm"])
    assert rep["dz"] == pytest.approx(0.7, abs=5 * rep["u_dz"])
    assert rep["rms_um"] == pytest.approx(5e-3, rel=0.1)
    # R and k free, from a wrong design (a stale drawing)
    wrong = EvenAsphere(1 / 50.3, -0.75, {4: 2e-7, 6: -1e-10}, 40)
    rep = run(MisalignmentStep, q, wrong, dof=["alpha", "beta", "dx", "dy", "dz", "radius", "conic"]).report
    assert rep["R"] == pytest.approx(50.0, abs=5 * rep["u_R"]) and rep["u_R"] < 1e-3
    assert rep["k"] == pytest.approx(-0.8, abs=5 * rep["u_k"]) and rep["u_k"] < 1e-3
    assert rep["parameters"] == ["tilt", "decentre", "dz", "radius", "conic"]


def test_profile_metrics_slope_error_and_psd():
    from pointspro.core.metrics.profiles import profile_psd, profile_slope

    u = np.linspace(-20, 20, 4001)
    lam, amp = 5.0, 50e-6
    r = amp * np.sin(2 * np.pi * u / lam)
    slope, window = profile_slope(u, r)
    true = amp * 2 * np.pi / lam * np.cos(2 * np.pi * u / lam)
    inner = np.abs(u) < 19
    assert np.max(np.abs(slope - true)[inner]) < 0.01 * np.max(true)  # 63 µrad peak, 1 % error
    f, p = profile_psd(u, r)
    assert f[np.argmax(p)] == pytest.approx(1 / lam, rel=0.05)
    assert np.sum(p) * (f[1] - f[0]) == pytest.approx(np.var(r), rel=0.05)  # ∫PSD = variance


def test_report_and_figures_of_a_profile(tmp_path):
    q, _, _, _ = goal_case(ASPHERE, 20.0, 1)
    res = recovered(ASPHERE, q)
    rep = res.report
    for key in ("rms_um", "pv_um", "slope_rms_urad", "tilt_deg", "decentre_mm", "dz", "not_determined"):
        assert key in rep
    assert 30 < rep["rms_um"] * 1e3 < 70 and rep["slope_rms_urad"] > 1
    for name in ("profile.png", "profile_psd.png"):
        res.artifacts[name](tmp_path / name)
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
    assert res.artifacts["profile_psd.csv"].startswith("profile,f [1/mm],psd [mm^3]\n0 deg,")


def test_crossed_profiles_give_an_astigmatism_estimate():
    """Two profiles at 0° and 90° of a part with 0.2 µm of astigmatism along 0°/90° (W = A ρ² cos 2θ):
    the difference of their powers is its PV over the common length, stated as such."""
    A = 0.1e-3 / 20.0 ** 2  # 0.1 µm at ρ = 20 mm: PV 0.2 µm
    qs, chans = [], []
    for k, ang in enumerate((0.0, 90.0)):
        q, _, u, _ = simulate(ASPHERE, 20.0, 1500, tilt_deg=0.1 * k, ds=0.02, dz=0.5, noise=5e-6,
                              seed=k, angle=ang)
        sign = 1.0 if ang == 0 else -1.0
        q[:, 2] += sign * A * u ** 2  # astigmatism adds ±A u² along the two azimuths (small tilt)
        qs.append(q)
        chans.append(np.full(len(q), ang))
    res = run(MisalignmentStep, np.vstack(qs), ASPHERE, channels={"angle": np.concatenate(chans)})
    ast = res.report["astigmatism"]
    assert ast["astigmatism_pv_estimate_um"] == pytest.approx(0.2, abs=0.01)
    assert "coarse estimate from two profiles" in ast["method"]
    assert len(res.report["profiles"]) == 2


def test_three_azimuths_give_the_astigmatism_axis():
    A, axis = 0.15e-3 / 20.0 ** 2, 30.0
    qs, chans = [], []
    for k, ang in enumerate((0.0, 60.0, 120.0)):
        q, _, u, _ = simulate(ASPHERE, 20.0, 1200, dz=0.5, noise=2e-6, seed=k, angle=ang)
        q[:, 2] += A * np.cos(2 * np.radians(ang - axis)) * u ** 2
        qs.append(q)
        chans.append(np.full(len(q), ang))
    ast = run(MisalignmentStep, np.vstack(qs), ASPHERE,
              channels={"angle": np.concatenate(chans)}).report["astigmatism"]
    assert ast["astigmatism_pv_estimate_um"] == pytest.approx(0.3, abs=0.01)
    assert ast["astigmatism_axis_deg"] == pytest.approx(axis, abs=1.0)


def test_an_x0z_cloud_is_a_profile_not_a_line_error():
    """The issue's complaint: an x, 0, z file stopped in probe_radius with "all points lie on a line"."""
    q, truth, _, _ = simulate(ASPHERE, 20.0, 800, rho=2.0, tilt_deg=0.1, ds=0.01, dz=3.0)
    assert np.all(q[:, 1] == 0)
    res = run(ProbeRadiusStep, q, ASPHERE, radius=2.0)
    assert np.sqrt(np.mean((res.cloud.xyz - truth) ** 2)) < 1e-9


@pytest.mark.parametrize("case,pattern", [
    ("repeat", r"profile 1 at 0°: x = .* mm is repeated \(input rows 10 and 11\)"),
    ("turn", r"profile 1 at 0°: the scan is not monotonic — it turns back at input row 10"),
    ("few", r"profile 1 at 0°: 3 points for 3 parameters \(tilt in the profile's plane, decentre along"),
    ("few_rk", r"5 points for 5 parameters"),
    ("not_line", r"its points leave the line by up to"),
    ("freeform", r"a profile is fitted to a surface of revolution's meridian"),
])
def test_bad_profiles_are_one_line(case, pattern):
    from pointspro.core.surfaces import XYPolynomial

    q, _, _, _ = simulate(ASPHERE, 20.0, 100, tilt_deg=0.1, dz=1.0)
    surface, chans, params = ASPHERE, {}, {}
    step = MisalignmentStep
    if case == "repeat":
        q[11, 0] = q[10, 0]
    elif case == "turn":
        q[[10, 11]] = q[[11, 10]]
    elif case == "few":
        q = q[:3]
    elif case == "few_rk":
        q = q[:5]
        params["dof"] = ["alpha", "beta", "dx", "dy", "dz", "radius", "conic"]
    elif case == "not_line":
        q[:, 1] = np.linspace(0, 5, len(q))
        chans = {"angle": np.zeros(len(q))}
    elif case == "freeform":
        surface = XYPolynomial({(2, 0): 1e-4}, c=1 / 50.0)
        step = ProbeRadiusStep
        params["radius"] = 1.0
    with pytest.raises(StepError, match=pattern) as ei:
        run(step, q, surface, channels=chans, **params)
    assert "\n" not in str(ei.value)


def test_batch_reads_and_reports_a_profile_file(tmp_path):
    """An x, z file through a recipe: probe_radius and misalignment; report.html has the figures."""
    import pointspro.core as pp

    q, _, _, _ = goal_case(ASPHERE, 20.0, 2, n=600)
    data = tmp_path / "profile.csv"
    data.write_text("x,z\n" + "\n".join(f"{x!r},{z!r}" for x, z in q[:, [0, 2]].tolist()) + "\n", encoding="utf-8")
    recipe = {"pointspro": 1, "input": {"profile_angle_deg": 0},
              "surface": {"type": "even_asphere", "c": 0.02, "k": -0.8, "A": {4: 2e-7, 6: -1e-10},
                          "aperture": 40},
              "steps": [{"probe_radius": {"radius": 0.002}}, {"misalignment": {}}]}
    result = pp.run(recipe, data)
    assert 0.03 < result.summary["rms_um"] < 0.07
    result.write(tmp_path / "out")
    html = (tmp_path / "out" / "profile" / "report.html").read_text(encoding="utf-8")
    assert "profile.png" in html and "profile_psd.png" in html and "not_determined" in html


def test_summary_of_profiles_has_no_areal_figures():
    """A profile has no area: the summary gives its PV and RMS, no PVr (a 36-term Zernike fit over a
    line) and no map slope RMS, and says so."""
    import pointspro.core as pp

    s = np.linspace(-20, 20, 801)
    z = s ** 2 / (50 * (1 + np.sqrt(1 - s ** 2 / 50 ** 2))) + 60e-6 * np.cos(2 * np.pi * s / 16)
    cloud = pp.PointCloud.from_xyz(s, np.zeros_like(s), z, angle=np.zeros_like(s))
    res = pp.run({"surface": {"type": "even_asphere", "c": 0.02, "k": 0, "aperture": 40},
                  "steps": [{"misalignment": {}}]}, cloud)
    summ = res.summary
    assert summ["pvr_um"] is None and summ["slope_rms_urad"] is None
    assert "stylus profiles" in summ["figures_of"]
    r = res.cloud["residual"]
    assert summ["rms_um"] == pytest.approx(np.std(r) * 1e3) and summ["pv_um"] == pytest.approx(np.ptp(r) * 1e3)

"""`pointspro explain`: gap = measured − simulated, the effects that explain it, the model updated
with them, and the gap before and after (explain.json, explain.html, model.updated.yaml)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, RecipeError
from ..metrics.area_weights import weighted_rms
from ..simulate.effects import ScanContext
from .select import RHO_GATE, select, separate_by

REGION_MIN_SIGMA = 5.0


def _stats(v, w=None) -> dict:
    """The reported RMS and PV of a gap (µm): the RMS over the area (``w``: the points' areas,
    core.metrics.area_weights; None: an even sampling, the points' plain RMS), docs/conventions.md,
    Summary figures. Only what is reported: the selection's statistics (F, BIC, σ) stay the points'."""
    v = np.asarray(v)
    return {"rms_um": weighted_rms(v, w) * 1e3, "pv_um": float(np.ptp(v) * 1e3)}


def regions(x, y, r, sigma, cells=24) -> list[dict]:
    """Clusters of cells whose mean residual is significant (|mean| > 5 σ/√n), each with its centre and
    the radius of a disk of the same area (mm); ``shape`` "ring" with ``inner_radius`` and
    ``outer_radius`` about that centre where the cluster goes round it (``_ring``), else "patch"."""
    from scipy import ndimage

    x0, x1, y0, y1 = x.min(), x.max(), y.min(), y.max()
    span = max(x1 - x0, y1 - y0) or 1.0
    h = span / cells
    ix = np.clip(((x - x0) / h).astype(int), 0, cells - 1)
    iy = np.clip(((y - y0) / h).astype(int), 0, cells - 1)
    k = iy * cells + ix
    n = np.bincount(k, minlength=cells * cells)
    s = np.bincount(k, weights=r, minlength=cells * cells)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, s / n, 0.0)
        z = np.abs(mean) * np.sqrt(n) / max(sigma, 1e-300)
    flag = (z > REGION_MIN_SIGMA) & (n >= 4)
    out = []
    # raised and sunk cells apart: a bump and the ring of the other sign its piston removal leaves
    # around it touch, and grouped by |mean| they were one region over the whole part, centred off the
    # bump with a mean of 0.006 nm (an independent review's 100 nm bump of σ 4 mm)
    for side in (mean > 0, mean < 0):
        lab, nlab = ndimage.label((flag & side).reshape(cells, cells))
        for i in range(1, nlab + 1):
            cellsi = np.flatnonzero(lab.ravel() == i)
            pts = np.isin(k, cellsi)
            w = np.abs(r[pts])
            cx = float(np.average(x[pts], weights=w + 1e-300))
            cy = float(np.average(y[pts], weights=w + 1e-300))
            reg = {"x": cx, "y": cy, "radius": float(np.sqrt(cellsi.size * h * h / np.pi)),
                   "mean_um": float(np.mean(r[pts]) * 1e3), "shape": "patch"}
            reg.update(_ring(x[pts] - cx, y[pts] - cy, h))
            out.append(reg)
    return sorted(out, key=lambda d: -abs(d["mean_um"]))


def _ring(dx, dy, h: float) -> dict:
    """A region that encloses a hole around its own centre — a zone of a turned or polished part —
    as a ring: its inner and outer radius about that centre (mm). Its centre alone (with the radius of
    a disc of the same area) placed a 20 nm zone at r = 12 mm "at the centre, radius 9.4 mm", where
    nothing is; a patch (a bump, a dig) has points at its centre and is left as it is. A ring: no
    point within two cells of the centre, and the points all round it (every eighth of the turn)."""
    d = np.hypot(dx, dy)
    if d.size < 16 or d.min() < 2.0 * h:
        return {}
    octant = ((np.arctan2(dy, dx) + np.pi) / (np.pi / 4)).astype(int) % 8
    if np.unique(octant).size < 8:
        return {}  # an arc or a crescent: its centre of mass lies off it, but it is no zone
    return {"shape": "ring", "inner_radius": float(np.percentile(d, 1)),
            "outer_radius": float(np.percentile(d, 99))}


def region_words(reg: dict) -> str:
    """A region as a person reads it: "ring r = 9.53–14.2 mm about (0.01, 0.09) mm, mean +9.87 nm" or
    "at (7.83, -4.88) mm, radius 3.7 mm, mean +11.4 nm"."""
    from ..units import format_length

    mean = format_length(reg["mean_um"] * 1e-3, 3)
    mean = mean if mean.startswith("-") else "+" + mean
    if reg.get("shape") == "ring":
        return (f"ring r = {reg['inner_radius']:.3g}–{reg['outer_radius']:.3g} mm about "
                f"({reg['x']:.2f}, {reg['y']:.2f}) mm, mean {mean}")
    return f"at ({reg['x']:.2f}, {reg['y']:.2f}) mm, radius {reg['radius']:.2g} mm, mean {mean}"


def _merge(effects: list[dict], name: str, params: dict) -> list[dict]:
    """Add fitted parameters to the model's effects (summed into an effect already there)."""
    out = [dict(e) for e in effects]
    for e in out:
        if name in e:
            old = dict(e[name] or {})
            if name == "vibration":
                break
            for k, v in params.items():
                old[k] = float(old.get(k, 0.0)) + v
            e[name] = old
            return out
    out.append({name: params})
    return out


def found_name(f: dict) -> str:
    """A found effect as a person names it: "vibration 61.7 Hz" (there may be several lines), else
    the effect's name."""
    hz = (f.get("params") or {}).get("frequency_hz") if f.get("effect") == "vibration" else None
    return f"vibration {hz:.4g} Hz" if isinstance(hz, (int, float)) else str(f.get("effect"))


def _view(name: str) -> str:
    return {"squareness": "radius", "straightness": "radius", "z_scale": "radius", "probe_radius": "radius",
            "spindle_tilt": "angle", "spindle_axial": "angle", "thermal_drift": "time",
            "dynamic_lag": "time", "vibration": "spectrum"}.get(name, "map")


#: fewer points cannot separate the library's signatures from the noise: a 1-point file came out
#: "nothing_missing" with a zero gap, a 3-point line "nothing missing, noise 808 µm"
MIN_POINTS = 100


def explain(measured: Path, out_dir: Path, model_path: Path | None = None, simulated: Path | None = None,
            bootstrap: int = 10, measured_cloud=None) -> dict:
    """``measured_cloud``: the measured points when they are not the file as read — the window's
    measurement less the points deleted there (``measured`` then names it)."""
    from ..io import read_cloud
    from ..simulate.model import check_scan, load_model

    meas = read_cloud(measured) if measured_cloud is None else measured_cloud
    if meas.n < MIN_POINTS:
        from ..errors import InputError

        raise InputError(f"{measured}: {meas.n} point(s); explain compares a scan with its simulation "
                         f"and needs {MIN_POINTS} points at least to tell an effect from the noise")
    model = None
    warnings: list[str] = []  # printed on stderr by `pointspro explain`, kept in explain.json
    dropped = int(meas.meta.get("invalid_dropped") or 0)
    if dropped:  # said, as the batch's report says it (a review: 5 NaN rows dropped without a word)
        warnings.append(f"{measured}: {dropped} row(s) with a NaN or infinite x, y or z dropped on reading "
                        f"({meas.n} points compared)")
    if model_path is not None:
        model = load_model(model_path)
        check_scan(model, model_path)  # the model simulates (explain evaluates it at the measured points only)
        ctx, z_sim, match = against_model(meas, model, Path(model_path).parent, measured, warnings)
    elif simulated is not None:
        ctx, z_sim, match = against_simulation(meas, simulated, warnings)
    else:
        raise RecipeError("explain needs --model MODEL.yaml or --simulated FILE")
    gap = meas.z - z_sim
    res = select(ctx, gap, bootstrap=bootstrap)
    sigma = res["sigma"]
    effects = list(model.effects) if model is not None else []
    from ..pipeline import area_weights_of

    # the points' areas for the reported gap RMS (a star or a spiral crowds its centre); None: even
    w = area_weights_of(meas)
    found, effects = found_effects(res, effects, w)
    warnings += unit_slip_warnings(found)
    ambiguous = ambiguities(res, sigma)
    updated = None
    if model is not None:
        updated = with_absolute_paths(model.model_copy(update={"effects": effects}), Path(model_path).parent)
    after = gap_after(meas, res, updated, model_path, ctx)
    regs = regions(meas.x, meas.y, after - after.mean(), sigma)
    structure = bool(regs) or res["rms"] > 1.25 * sigma
    if structure and found:
        # structure the library does not hold can be partly taken up by its effects (a 4 mm ripple read
        # as three vibrations 0.02 Hz apart and spindle tilt harmonics — a review): say so beside
        # the effects named, which model.updated.yaml holds
        warnings.append("the gap is not explained: structure above the noise is left "
                        f"({len(regs)} region(s)), and the effects named beside it "
                        f"({', '.join(found_name(f) for f in found)}) may be fitting part of it — check them "
                        "before using model.updated.yaml")
    report = {
        "verdict": verdict(structure, ambiguous, found), "gap_before": _stats(gap, w), "gap_after": _stats(after, w),
        "noise_um": sigma * 1e3, "noise_um_of_gap": res["sigma_gap"] * 1e3, "found": found, "ambiguous_with": ambiguous,
        "unexplained": {"rms_um": _stats(after, w)["rms_um"] if structure else 0.0, "regions": regs if structure else [],
                        **({"note": correlated_note(res["rho1"], res["dropped_under_correlated_noise"])}
                           if structure and res["rho1"] > RHO_GATE else {})},
        "checks": {"chi2_p": res["chi2_p"], "residual_lag1_autocorrelation": res["rho1"],
                   "residual_rms_over_noise": res["rms"] / max(sigma, 1e-300),
                   # effects the white-noise tests named but a test under the residual's own AR
                   # noise does not support (core/explain/select.py _correlated_noise_gate)
                   "dropped_under_correlated_noise": res["dropped_under_correlated_noise"],
                   # chosen on the way, then no longer supported beside the effects found after them
                   # (select.py _backward)
                   "dropped_unsupported": res.get("dropped_unsupported", [])},
        "not_observable_on_this_scan": res["unobservable"], "points": int(meas.n), "match": match,
        "measured": str(measured), "model": str(model_path) if model_path else None,
        "simulated": str(simulated) if simulated else None, "warnings": warnings,
    }
    _write(Path(out_dir), report, updated, effects, ctx, gap, after, found, res["order"], w)
    return report


#: a z scale found this far from 1 is no scale error a machine has (ppm to a few 0.1 %): heights in
#: another unit than x and y
UNIT_SLIP_SCALE = 0.01


def unit_slip_warnings(found) -> list[str]:
    """A z_scale of 999 (heights in µm beside x, y in mm, no header) was named with a squareness of 148″
    and no word (a review): say what it most likely is."""
    out = []
    for f in found:
        k = (f.get("params") or {}).get("scale") if f.get("effect") == "z_scale" else None
        if isinstance(k, (int, float)) and abs(k) > UNIT_SLIP_SCALE:
            ratio = 1.0 + k
            out.append(f"the heights read {ratio:.6g} × the model's (a z_scale of {k:.6g}); no machine's "
                       "z scale is that far off — are the heights in another unit than x and y? State it in the "
                       "header (`z [um]`, docs/formats.md)")
    return out


def clock_of(cloud, path) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(t in s, c in degrees) of a cloud, None where it has no such channel. A unit its header
    states (``t [ms]``, ``c [rad]``: core.io.text keeps it in meta["channel_units"]) is converted by
    core.units.read_in, as the kinematic and dynamic steps convert theirs; a column without one is
    read as s and degrees (docs/formats.md); an unknown unit is refused naming the file and the
    column. The numbers were taken as s and degrees whatever the header said: a 23.3 Hz vibration
    read 0.0233 Hz from ``t [ms]`` (issue 16's review)."""
    from ..units import read_in

    stated = cloud.meta.get("channel_units") or {}
    out = []
    for ch, unit in (("t", "s"), ("c", "deg")):
        if ch not in cloud.channels:
            out.append(None)
            continue
        given = stated.get(ch) if isinstance(stated, dict) else None
        out.append(read_in(cloud[ch], given, unit, str(path), ch, "explain"))
    return out[0], out[1]


def with_absolute_paths(model, base: Path):
    """The model with its nominal mesh's path made absolute (it is read relative to the model file's
    folder, ``base``). model.updated.yaml is written with absolute paths rather than paths relative
    to its own folder: the window saves it by copying it out of a temporary folder to wherever the
    user chooses, so only an absolute path works from every folder it may end up in (a review:
    written to another folder, the original's `path: part.stl` made `pointspro simulate` fail)."""
    surf = model.surface
    if isinstance(surf, dict) and isinstance(surf.get("path"), str) and not Path(surf["path"]).is_absolute():
        surf = {**surf, "path": str((Path(base) / surf["path"]).resolve())}
        return model.model_copy(update={"surface": surf})
    return model


#: a share of the measured points beyond the model's aperture above this is refused (see check_aperture)
OUTSIDE_APERTURE_MAX = 0.01


def model_aperture(model) -> tuple[float, str]:
    """The radius (mm) the model describes and what it is: half the surface's `aperture` when it
    states one, else the extent of the model's own scan (a spiral's, raster's or star's radius, the
    fiducial patches' farthest corner)."""
    ap = model.surface.get("aperture") if isinstance(model.surface, dict) else None
    if isinstance(ap, (int, float)) and ap > 0:
        return 0.5 * float(ap), f"the surface's aperture Ø {float(ap):.6g} mm"
    sc = model.scan
    if sc.type == "fiducials" and sc.centers:
        r = max(float(np.hypot(cx, cy)) for cx, cy in sc.centers) + sc.patch / np.sqrt(2.0)
        return r, f"the model's fiducial patches, out to a radius of {r:.6g} mm (the surface states no aperture)"
    return float(sc.radius), f"the model's {sc.type} scan of radius {sc.radius:.6g} mm (the surface states no aperture)"


def check_aperture(meas, model, measured, warnings: list[str]) -> None:
    """Refuse a measurement of which more than OUTSIDE_APERTURE_MAX of the points lie outside the
    model's aperture; warn of fewer. Why refuse rather than crop to the aperture and go on: the
    model says nothing about the part there (an edge, a bevel, a mount, or another part), and a gap
    there is not an error of the model — a review's measurement beyond the aperture was "explained"
    with z_scale ≈ −1 found. Cropping would hide that the files do not belong together (a wrong
    model, a wrong aperture, a measurement in another frame) behind a plausible report; the
    --simulated path refuses a measurement its simulation does not cover for the same reason. A few
    points just past the rim (a measurement's own centring) are kept, the model evaluated there,
    and the user told."""
    R, what = model_aperture(model)
    r = np.hypot(meas.x, meas.y)
    out = r > R * (1.0 + 1e-6)
    if not out.any():
        return
    from ..units import format_length

    n, beyond = int(out.sum()), float(r.max()) - R
    text = (f"{n} of {meas.n} measured points ({100.0 * n / meas.n:.3g} %) lie outside the model's aperture, "
            f"up to {format_length(beyond)} beyond it (radius {float(r.max()):.6g} mm against {what})")
    if n > OUTSIDE_APERTURE_MAX * meas.n:
        raise InputError(f"{measured}: {text}: the model says nothing about the part there, and explain "
                         "compares only where it does — crop the measurement to the aperture, or give the "
                         "model the aperture that was measured")
    warnings.append(f"{text}; kept, the model evaluated there")


def against_model(meas, model, base: Path, measured="the measurement", warnings: list[str] | None = None):
    """The model simulated at the measured positions, noise-free: (ScanContext, simulated z, how the
    points were matched). A measurement reaching beyond the model's aperture is refused
    (check_aperture). Time and spindle angle come from the measurement, or else — said in
    ``warnings``, never silently — from the nearest point of the model's scan path."""
    from ..simulate.model import simulate
    from ..simulate.scan import scan_points

    warnings = [] if warnings is None else warnings
    check_aperture(meas, model, measured, warnings)
    t, c = clock_of(meas, measured)
    if t is None or c is None:
        from scipy.spatial import cKDTree

        sp = scan_points(model.scan)
        d, j = cKDTree(np.column_stack([sp["x"], sp["y"]])).query(meas.xyz[:, :2])
        from ..units import format_length

        gone = [w for w, v in (("time 't'", t), ("spindle angle 'c'", c)) if v is None]
        judged = [w for w, v in (("the effects in time (thermal_drift, dynamic_lag, vibration)", t),
                                 ("the spindle errors", c)) if v is None]
        warnings.append(f"no {' and no '.join(gone)} column: taken from the nearest point of the model's "
                        f"{model.scan.type} scan path (up to {format_length(float(d.max()))} away), and "
                        f"{' and '.join(judged)} are judged on those borrowed values; give the measurement's own "
                        "columns for effects in time or angle")
        t = sp["t"][j] if t is None else t
        c = sp["c"][j] if c is None else c
    at = {"x": meas.x, "y": meas.y, "t": t, "c": c}
    sim = simulate(model, base, at=at, noise=False)
    surf = model.build_surface(base)
    own = scan_points(model.scan)  # the parameters found mean what they mean in the model
    ctx = ScanContext.from_surface(surf, meas.x, meas.y, t, c).with_norms_of(own["x"], own["y"], own["t"])
    if ctx.own_clock:
        warnings.append(f"the measured time t runs {float(np.min(t)):.6g} … {float(np.max(t)):.6g} s, outside the "
                        f"model's scan (0 … {float(np.ptp(own['t'])):.6g} s): thermal drift is counted from the "
                        "measurement's own start")
    return ctx, sim["z"], "model evaluated at the measured positions"


def _kept_rows(meas, simc):
    """The simulation's rows of a measurement some rows of which were deleted (its ``index`` the rows
    of the file as read, the simulation made at that file's positions), or None: matched by row, not by
    position (a review: five points deleted in the window turned "by row" into "by position", with a
    false warning that the simulation was not made at the measured positions)."""
    if simc.n <= meas.n or "index" not in meas.channels:
        return None
    idx = np.asarray(meas["index"])
    if idx.size == 0 or idx.min() < 0 or idx.max() >= simc.n or np.any(idx != np.round(idx)):
        return None
    idx = idx.astype(np.int64)
    if np.max(np.abs(simc.xyz[idx, :2] - meas.xyz[:, :2])) >= 1e-6:
        return None
    return idx


def against_simulation(meas, simulated: Path, warnings: list[str] | None = None):
    """A simulated cloud (with t and c) matched to the measurement by row when the positions agree,
    else by position: the simulation's heights interpolated to the measured positions
    (simulated_heights); its slopes from a global polynomial through it (core.explain.slopes:
    accurate enough for the probe_radius signature): (ScanContext, simulated z, how the points were
    matched and the slopes found)."""
    from ..io import read_cloud
    from .slopes import cloud_slopes, smooth_fit

    simc = read_cloud(simulated)
    for ch in ("t", "c"):
        if ch not in simc.channels:
            raise InputError(f"{simulated}: the simulation has no '{ch}' channel")
    t_sim, c_sim = clock_of(simc, simulated)
    order = np.argsort(t_sim, kind="stable")
    rows = _kept_rows(meas, simc)  # the measurement less rows deleted (the window): the same rows
    if rows is not None or (simc.n == meas.n and np.max(np.abs(simc.xyz[:, :2] - meas.xyz[:, :2])) < 1e-6):
        # slopes through the whole simulation, its scan normalising the effects (with_norms_of below)
        fx, fy, how = cloud_slopes(simc.x, simc.y, simc.z, order)
        j = np.arange(meas.n) if rows is None else rows
        z_sim, fx, fy = simc.z[j], fx[j], fy[j]
        match = "by row" if rows is None else f"by row (the simulation's rows of the {meas.n} points kept)"
    else:
        from scipy.spatial import cKDTree

        tree = cKDTree(simc.xyz[:, :2])
        d, j = tree.query(meas.xyz[:, :2])
        spacing = float(np.median(tree.query(simc.xyz[:, :2], k=2)[0][:, 1])) if simc.n > 1 else 0.0
        far = d > 3.0 * max(spacing, 1e-12)
        if far.any():
            # a review: a simulation of a 5 mm disc "explained" a measurement 15 mm across
            raise InputError(f"{simulated}: {int(far.sum())} measured point(s) lie up to {float(d.max()):.3g} mm "
                             f"from any simulated point (the simulation's spacing is {spacing:.3g} mm): simulate "
                             "the measured scan (or give --model to evaluate the model at the measured points)")
        fit, how = smooth_fit(simc.x, simc.y, simc.z, order)
        z_sim = simulated_heights(fit, simc, meas.x, meas.y, j)
        fx, fy = fit(meas.x, meas.y, dx=1), fit(meas.x, meas.y, dy=1)
        match = f"by position (measured points up to {float(d.max()):.3g} mm from the nearest simulated point; the " \
                "simulation's heights there from its smooth fit plus what the fit leaves, interpolated linearly " \
                "between the simulated points)"
        if warnings is not None:  # said, never borrowed silently
            own = [ch for ch in ("t", "c") if ch in meas.channels]
            warnings.append(f"the simulation was not made at the measured positions: each measured point's time and "
                            f"spindle angle are the nearest simulated point's (up to {float(d.max()):.3g} mm away)"
                            + (f"; the measurement's own {' and '.join(repr(c) for c in own)} not used" if own else ""))
    match += (f"; slopes from a degree-{how['degree']} polynomial through the simulation ({how['rest_rms_um'] * 1e3:.3g} "
              f"nm RMS left, its noise {how['noise_um'] * 1e3:.3g} nm"
              + ("; the rest by a smoothing spline)" if how["spline"] else ")"))
    ctx = ScanContext(meas.x, meas.y, z_sim, fx, fy, t_sim[j], c_sim[j]).with_norms_of(simc.x, simc.y, t_sim)
    return ctx, z_sim, match


def simulated_heights(fit, simc, x, y, nearest) -> np.ndarray:
    """The simulated cloud's heights at other positions (x, y): its smooth fit (core.explain.slopes:
    a global polynomial, and a spline where that leaves more than the noise) evaluated there, plus
    what the fit leaves at the simulated points (their noise, and detail finer than the fit)
    interpolated linearly over their Delaunay triangulation — the nearest point's (``nearest``) where
    (x, y) lies outside it. The nearest point's height carried along its slope left the curvature's
    0.5·κ·d² (65 nm on a review's 0.35 mm on a sloped part, and a spindle_tilt named); the fit holds
    the curvature, and the rest it leaves is nm at most, so interpolating it linearly errs far below."""
    rest = simc.z - fit(simc.x, simc.y)
    at = linear_interpolation(simc.xyz[:, :2], rest, np.column_stack([x, y]), nearest)
    return fit(x, y) + np.where(np.isfinite(at), at, rest[nearest])


def linear_interpolation(pts, values, q, nearest, chunk: int = 20_000) -> np.ndarray:
    """``values`` at the points ``pts`` (n, 2) interpolated linearly to ``q`` (m, 2) over the Delaunay
    triangulation of ``pts``, in the triangle holding q among those at its nearest point ``nearest``
    (nearly always one of them: all but 136 of 290,000 points offset on a spiral); NaN where none
    holds it (q outside the triangulation, or no triangulation: points all on a line). Not scipy's
    LinearNDInterpolator: its search for the triangle took 90 s for those 290,000 points, most of it
    on the points just outside the triangulation, where it tries every triangle."""
    from scipy.spatial import Delaunay, QhullError

    out = np.full(len(q), np.nan)
    try:
        tri = Delaunay(pts)
    except (QhullError, ValueError):
        return out
    S = tri.simplices
    flat = S.ravel()
    by_vertex = np.argsort(flat, kind="stable")
    simplex_of = by_vertex // 3  # the triangles at each vertex, vertex by vertex
    start = np.searchsorted(flat[by_vertex], np.arange(len(pts) + 1))
    K = int(min(np.max(np.diff(start)), 32))

    def barycentric(tris, p):  # (…, 3) weights of p in triangles tris; NaN for a degenerate one
        A, B, C = pts[S[tris, 0]], pts[S[tris, 1]], pts[S[tris, 2]]
        v0, v1, v2 = B - A, C - A, p - A
        det = v0[..., 0] * v1[..., 1] - v0[..., 1] * v1[..., 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            b = (v2[..., 0] * v1[..., 1] - v2[..., 1] * v1[..., 0]) / det
            c = (v0[..., 0] * v2[..., 1] - v0[..., 1] * v2[..., 0]) / det
        return np.stack([1.0 - b - c, b, c], axis=-1)

    found = np.zeros(len(q), dtype=bool)
    k = np.arange(K)
    for a in range(0, len(q), chunk):
        j, p = nearest[a:a + chunk], q[a:a + chunk]
        s0, deg = start[j], start[j + 1] - start[j]
        cand = simplex_of[np.minimum(s0[:, None] + k, len(simplex_of) - 1)]
        w = barycentric(cand, p[:, None, :])
        with np.errstate(invalid="ignore"):
            inside = (k < deg[:, None]) & np.all(w >= -1e-9, axis=-1)
        rows = np.flatnonzero(inside.any(axis=1))
        first = np.argmax(inside[rows], axis=1)
        tris = cand[rows, first]
        out[a + rows] = np.sum(values[S[tris]] * w[rows, first], axis=1)
        found[a + rows] = True
    rest = np.flatnonzero(~found)
    if rest.size:
        # the few whose triangle does not touch their nearest point (~1.6 % of a spiral's, a review):
        # Qhull's own search, for them alone (its cost is in the points outside the triangulation)
        s = tri.find_simplex(q[rest])
        inside = s >= 0
        if inside.any():
            idx, si = rest[inside], s[inside]
            T = tri.transform[si]
            b = np.einsum("nij,nj->ni", T[:, :2], q[idx] - T[:, 2])
            w = np.column_stack([b, 1.0 - b.sum(axis=1)])
            out[idx] = np.sum(values[S[si]] * w, axis=1)
    return out


def found_effects(res: dict, effects: list[dict], w=None) -> tuple[list[dict], list[dict]]:
    """Each chosen effect in the order it entered, with its parameters in the library's units, their
    uncertainties, the gap after it (its RMS over the area: ``w``, the points' areas) and its evidence;
    and the model's effects with them added."""
    found = []
    for f in res["found"]:
        params, unc, st = f["params"], f["uncertainty"], f["stage"]
        effects = _merge(effects, f["effect"], params)
        entry = {"effect": f["effect"], "params": params, "uncertainty": unc,
                 "gap_after": _stats(f["resid_upto"], w),
                 "evidence": {"F": st.F, "p": st.p, "delta_bic": st.delta_bic, "vif_max": f["vif_max"],
                              "stability": res["stability"].get(f["effect"]),
                              "ssr_before_um2": st.ssr_before * 1e6, "ssr_after_um2": st.ssr_after * 1e6}}
        if f["harmonics"] is not None:
            entry["harmonics"] = f["harmonics"]
            entry["evidence"]["harmonics"] = [{"harmonic": h.harmonic, "F": h.F, "p": h.p, "delta_bic": h.delta_bic}
                                              for h in f["stages"]]
        found.append(entry)
    return found, effects


def ambiguities(res: dict, sigma: float) -> list[dict]:
    """The pairs this scan cannot tell apart, why (their SSR difference in σ²) and what would."""
    out = []
    for f in res["found"]:
        for st in f["stages"]:
            for a in st.ambiguous_with:
                if any(set(o["effects"]) == {f["effect"], a["effect"]} for o in out):
                    continue
                what = f" at {a['harmonic']} undulations per revolution" if a.get("harmonic") else ""
                note = f"; {a['note']}" if a.get("note") else ""
                d = abs(a['ssr_excess']) / max(sigma, 1e-300) ** 2
                why = (f"on this scan path the two signatures{what} fit the gap equally well (their fits "
                       f"differ by {d:.3g} σ² in the sum of squares, below the χ² threshold){note}")
                if a.get("tie") is False:  # a vibration kept, its line synchronous (select._synchronous_lines)
                    why = (f"the vibration's line is within a quarter cycle over the record of {a['harmonic']} × "
                           f"the spindle frequency, closer than the record resolves in frequency: a synchronous line, as a "
                           f"spindle error of {a['harmonic']} undulations per revolution would give (a steady "
                           f"one fits {d:.3g} σ² worse in the sum of squares)")
                out.append({"effects": [f["effect"], a["effect"]], "why": why,
                            "separate_by": separate_by(f["effect"], a["effect"])})
    return out


def gap_after(meas, res: dict, updated, model_path, ctx: ScanContext) -> np.ndarray:
    """The gap after the found effects: measured − the updated model simulated again when there is a
    model, else the selection's residual."""
    if updated is None:
        return res["residual"]
    from ..simulate.model import simulate

    return meas.z - simulate(updated, Path(model_path).parent, at={"x": meas.x, "y": meas.y,
                             "t": ctx.t, "c": ctx.c}, noise=False)["z"]


def correlated_note(rho: float, dropped: list) -> str:
    """Why a gap can read as structure with correlated noise: the noise σ comes from second
    differences and the regions' test takes cell means as independent, both right for white noise;
    noise correlated along the scan makes the first small (AR(1) of ρ = 0.5: 0.65 of its σ) and the
    second's means wander — an AR(1) gap of ρ = 0.6 showed 32 "regions"."""
    gone = f"; not named, as only such noise supports them: {', '.join(dropped)}" if dropped else ""
    return (f"the residual is correlated along the scan (lag-1 autocorrelation {rho:.2f}): correlated noise (a "
            "probe's, an interferometer's), a local defect or a smooth effect the library lacks. The noise σ "
            "(second differences) and the regions' test assume white noise, so correlated noise reads as "
            f"structure too — look at the gap map before trusting the regions{gone}")


def verdict(structure: bool, ambiguous: list, found: list) -> str:
    """unexplained (structure left above the noise) > ambiguous > explained > nothing_missing."""
    if structure:
        return "unexplained"
    if ambiguous:
        return "ambiguous"
    if found:
        return "explained"
    return "nothing_missing"


def _write(out_dir: Path, report: dict, updated, effects: list[dict], ctx, gap, after, found, order,
           w=None) -> None:
    """explain.json, model.updated.yaml (the model with the found effects, or just the effects when
    the gap came from a simulated file), the figures and explain.html — all or nothing."""
    from ..io.atomic import atomic_dir
    from ..report import dumps, jsonable

    with atomic_dir(out_dir) as tmp:
        (tmp / "explain.json").write_text(dumps(jsonable(report)), encoding="utf-8")
        if updated is not None:
            (tmp / "model.updated.yaml").write_text(updated.to_yaml(), encoding="utf-8")
        else:
            import yaml

            (tmp / "model.updated.yaml").write_text(yaml.safe_dump({"effects": effects}, sort_keys=False),
                                                    encoding="utf-8")
        _figures(tmp, ctx, gap, after, found, order, w)
        (tmp / "explain.html").write_text(_html(report, tmp), encoding="utf-8")


def _figures(folder, ctx, gap, after, found, order, w=None):
    """gap_map.png (before/after maps) and gap_views.png: the gap against radius, spindle angle,
    time and scan velocity, and its spectrum along the scan — the first found effect's view first."""
    from ..figures import _figure, before_after, save_png

    save_png(before_after(ctx.x, ctx.y, gap, after, what="adding the found effects", weights=w),
             folder / "gap_map.png")
    t = ctx.t[order]
    uniform = np.ptp(t) > 0 and np.std(np.diff(t)) < 1e-3 * np.mean(np.diff(t))
    speed = scan_speed(ctx.x, ctx.y, ctx.t)
    views = [("radius (mm)", ctx.r), ("spindle angle c (deg)", ctx.c), ("time (s)", ctx.t),
             ("scan speed (mm/s)", speed)]
    first = _view(found[0]["effect"]) if found else "radius"
    views.sort(key=lambda v: 0 if v[0].startswith({"angle": "spindle", "time": "time", "spectrum": "time"}
                                                     .get(first, "radius")) else 1)
    fig = _figure(14, 7.5)
    axes = fig.subplots(2, 3).ravel()
    k = max(gap.size // 20000, 1)
    g0, a0 = gap - gap.mean(), after - after.mean()
    for ax, (lab, xv) in zip(axes[:4], views):
        ax.plot(xv[::k], g0[::k] * 1e3, ",", alpha=0.5, label="before")
        ax.plot(xv[::k], a0[::k] * 1e3, ",", alpha=0.5, label="after")
        ax.set_xlabel(lab, fontsize=8)
        ax.set_ylabel("gap (µm)", fontsize=8)
        ax.set_title("against " + lab.split(" (")[0], fontsize=9)
    axes[0].legend(markerscale=20, fontsize=8)
    ax = axes[4]
    if uniform:
        from scipy.signal import welch

        fs = 1.0 / np.mean(np.diff(t))
        for v, name in ((gap, "before"), (after, "after")):
            f, p = welch(v[order] - v.mean(), fs=fs, nperseg=min(v.size, 4096))
            ax.loglog(f[1:], p[1:] * 1e6, lw=1, label=name)
        ax.set_xlabel("frequency (Hz)", fontsize=8)
        ax.set_ylabel("PSD (µm²/Hz)", fontsize=8)
        ax.legend(fontsize=8)
        ax.set_title("spectrum along the scan", fontsize=9)
    else:
        ax.set_axis_off()
    axes[5].set_axis_off()
    fig.subplots_adjust(hspace=0.45, wspace=0.3)
    save_png(fig, folder / "gap_views.png")


def scan_speed(x, y, t) -> np.ndarray:
    """|d(x, y)/dt| along the scan (mm/s) at each point, in time order whatever the rows' order.
    Points that share a time stamp (a clock written to the ms, a probe reading several points at once)
    share their group's speed, from the group's mean position, as ScanContext.zdot shares their rate:
    np.gradient over a repeated stamp divided by zero and printed numpy's RuntimeWarnings (a review)."""
    speed = np.zeros_like(x)
    if t.size < 2 or not np.ptp(t) > 0:
        return speed
    order = np.argsort(t, kind="stable")
    tu, first, counts = np.unique(t[order], return_index=True, return_counts=True)
    xu = np.add.reduceat(x[order], first) / counts
    yu = np.add.reduceat(y[order], first) / counts
    speed[order] = np.repeat(np.hypot(np.gradient(xu, tu), np.gradient(yu, tu)), counts)
    return speed


def _html(report: dict, folder: Path) -> str:
    import html

    from ..report import _CSS, _img
    from ..report import table_html as _table
    from ..units import format_length

    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>PointsPro explain</title><style>{_CSS}"
             "</style></head><body><h1>Explain: where simulation and measurement disagree</h1>",
             f"<p><b>Verdict: {html.escape(report['verdict'])}</b> — gap "
             f"{format_length(report['gap_before']['rms_um'] * 1e-3, 4)} RMS before, "
             f"{format_length(report['gap_after']['rms_um'] * 1e-3, 4)} after; noise "
             f"{format_length(report['noise_um'] * 1e-3, 3)}.</p>",
             *(f"<p class='warn'>Warning: {html.escape(w)}.</p>" for w in report.get("warnings") or []),
             _img(folder, "gap_map.png"), _img(folder, "gap_views.png"), "<h2>Found (in the order added)</h2>"]
    for f in report["found"]:
        gap = (f"RMS {format_length(f['gap_after']['rms_um'] * 1e-3, 4)}, "
               f"PV {format_length(f['gap_after']['pv_um'] * 1e-3, 4)}")
        parts.append(f"<h3>{html.escape(f['effect'])}</h3>" + _table({**params_for_people(f), "gap after": gap,
                                                                     **{"evidence " + k: v for k, v in f["evidence"].items()}}))
    if not report["found"]:
        parts.append("<p class='muted'>No effect of the library is supported by the gap.</p>")
    if report["ambiguous_with"]:
        parts.append("<h2>Cannot be told apart on this scan</h2>")
        for a in report["ambiguous_with"]:
            parts.append(f"<p class='warn'>{html.escape(' / '.join(a['effects']))}: {html.escape(a['why'])}. "
                         f"Separate them by: {html.escape(a['separate_by'])}.</p>")
    if report["unexplained"]["regions"]:
        # one line each, as `pointspro explain` prints them (every number is in explain.json)
        parts.append("<h2>Unexplained regions</h2><ul>" + "".join(
            f"<li>{html.escape(region_words(r))}</li>" for r in report["unexplained"]["regions"]) + "</ul>")
    if report["unexplained"].get("note"):
        parts.append(f"<p class='warn'>{html.escape(report['unexplained']['note'])}.</p>")
    parts.append("<h2>Checks</h2>" + _table(report["checks"]) + "</body></html>\n")
    return "".join(parts)


def params_for_people(found: dict) -> dict[str, str]:
    """A found effect's parameters as text in their units — lengths in the unit their size asks for
    ("amplitude 8.01 nm ± 0.2 nm", the report's number 8.01e-06 being mm), the others with the
    library's unit (core/simulate/effects.py)."""
    from ..simulate.effects import LIBRARY

    eff = LIBRARY.get(found["effect"])
    units = {}
    if eff is not None:
        units = dict(zip(eff.params, eff.units)) if hasattr(eff, "units") else {}
        units.setdefault("*", getattr(eff, "unit", ""))
    from ..statement import _decimals
    from ..units import length_unit

    unc = found.get("uncertainty") or {}
    out = {}
    for name, v in found["params"].items():
        unit = units.get(name, units.get("*", ""))
        u = unc.get(name)
        if not isinstance(v, (int, float)):
            out[name] = str(v)
            continue
        k, sym, digits = 1.0, "" if unit in ("", "1") else f" {unit}", 4
        if unit == "mm":
            k, shown = length_unit(v if v else (u or 0.0))
            k, sym, digits = 1.0 / k, f" {shown}", 3
        elif unit == "s" and 0 < abs(v) < 1:  # a loop's time constant: µs or ms
            k, sym, digits = (1e6, " µs", 3) if abs(v) < 1e-3 else (1e3, " ms", 3)
        if isinstance(u, (int, float)) and u > 0 and np.isfinite(u):
            # the value to the decimal place of u's two significant digits (GUM §7.2.6): a vibration's
            # frequency read "23.3 Hz ± 5.9e-05 Hz"
            d = min(_decimals(u * k), 15)
            out[name] = f"{v * k:.{d}f}{sym} ± {u * k:.{d}f}{sym}"
        else:
            out[name] = f"{v * k:.{digits}g}{sym}"
    return out

"""`fiducials`: fiducial-aided calibration (seed papers 000 and 001).

Input cloud: probe points on the fiducial balls with a `fiducial` channel (ball id), e.g. 20 points on
a 6 × 6 mm patch per ball. ``reference``: CSV `fiducial, x, y, z` of the calibrated centres (the CMM's
frame). Each ball's centre is fitted (sphere of the calibrated ``diameter``, or free) with its
uncertainty; the 12-parameter transform by weighted least squares with its GUM covariance, checked by
Monte Carlo (GUM Supplement 1); the volumetric errors at the fiducials and Ev; the fiducial-count study
(000 Fig. 3); a GP of the volumetric error (core.calibration.gp: spectral mixtures of Q = 1, 2, 4, …
≤ ``Q`` components, RBF and Matérn 5/2, and "none" (the transform alone), chosen by 6-fold
cross-validation with the transform and the hyperparameters re-fitted in each fold — reported as
``gp_cv_rms_um`` beside ``no_gp_rms_um``; a GP only where it beats "none" by more than one standard
error; the noise term is bounded below by the centres' known σ; a ball the other balls cannot predict
is never held out, and with too few balls to hold out the error left comes from the residuals with
their degrees of freedom, or is unknown with 4 balls — said in the warnings and ``sigma_basis``). A
blocked cross-validation (spatial blocks of ~4 neighbouring balls held out whole, the transform and the
hyperparameters re-fitted without them) measures how the error grows with the distance d from the balls,
u_k² = s_k² + τ²·d (core.calibration.gp.distance_term; report ``blocked_cv``, model ``u_calibration``). Writes ``volumetric_model.json`` (what `volumetric` applies), ``volumetric_grid.csv``
(predicted error and its uncertainty on a grid over the workspace) and figures. The cloud passes
through unchanged.
"""
from __future__ import annotations

import numpy as np

from pointspro.core.calibration.fiducials import ball_points, example_layout, example_measured_centres
from pointspro.core.calibration.gp import MIN_HELD_OUT
from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context, Params, Step, StepResult, param

#: the GP's white noise is bounded above by this many times the declared noise at a fiducial,
#: σ_measured² + σ_reference². Without a ceiling the marginal likelihood of 24 balls often took the
#: whole error for noise and the selection fell back to no GP. An independent review's simulator (77
#: fields of 8 kinds, 24 balls, 0.2 µm noise): workpiece error 0.574 µm on average without a ceiling,
#: 0.552 with 2×, 0.514 with 1× (≤ 0.40 µm on 21 → 26 cases; affine alone 0.722, a fixed RBF at 0.4 ×
#: the extent 0.579); on null fields a GP is then chosen on 3 of 18 (0.02–0.03 µm worse than none)
NOISE_CEILING = 1.0


class FiducialsParams(Params):
    reference: str = param(file=True, help="calibrated centres: CSV fiducial, x, y, z (mm), relative to the recipe")
    diameter: float | None = param(9.997, gt=0, unit="mm", help="ball diameter; empty: fitted freely")
    sigma_reference: float = param(0.2, ge=0, unit="µm", help="standard uncertainty of the calibrated "
                                   "centres (001: 0.2 µm)")
    sigma_measured: float | None = param(None, gt=0, unit="µm", help="σ of the measured centres; empty: "
                                         "from the ball fits (RMS of their centre uncertainties)")
    Q: int = param(10, ge=1, le=30, help="most components of a spectral-mixture kernel tried (000: 10); "
                   "Q = 1, 2, 4, … are cross-validated while they improve")
    monte_carlo_runs: int = param(2000, ge=0, le=100000, help="GUM S1 check runs (0: none)")
    grid: int = param(9, ge=2, le=60, help="nodes per axis of the predicted-error grid")


def fit_centres(cloud, diameter):
    from pointspro.core.geometry.fits import fit_sphere

    ids = cloud["fiducial"].astype(int)
    out = {}
    for i in np.unique(ids):
        p = cloud.xyz[ids == i]
        if len(p) < 5:
            raise StepError(f"fiducial {i}: {len(p)} points — a ball needs at least 5")
        f = fit_sphere(p, None if diameter is None else diameter / 2)
        rms = float(np.sqrt(np.mean(f.residuals**2)))
        off_sphere = rms > 0.01 * (diameter or 10.0)
        free = fit_sphere(p, None) if off_sphere and diameter is not None else None
        free_fits = free is not None and np.sqrt(np.mean(free.residuals**2)) < 0.2 * rms
        if off_sphere and not free_fits:
            # a review: two balls measured under one id read "a free sphere fits them with diameter 1.02e+04 mm
            # — check `diameter`". Single-linkage clusters cut at 0.4 × the diameter (a probed patch's points
            # lie ~1.5 mm apart; two balls' top patches, 6 mm wide, ≥ 4 mm apart), named when their centroids
            # stand more than ~a diameter apart (two balls' centres are at least one apart)
            from scipy.cluster.hierarchy import fcluster, linkage

            dia = diameter or 10.0
            if len(p) > 1:
                lab = fcluster(linkage(p, "single"), t=0.4 * dia, criterion="distance")
                # clusters of 3 points or more: one far-off mis-probed point is no second ball
                big = [j for j in range(1, int(lab.max()) + 1) if np.count_nonzero(lab == j) >= 3]
                k = len(big)
                cen = np.array([p[lab == j].mean(axis=0) for j in big]) if big else np.zeros((1, 3))
                gap = float(np.max(np.linalg.norm(cen[:, None] - cen[None], axis=-1)))
                if k > 1 and gap > 0.95 * dia:
                    raise StepError(f"fiducial {i}: its {len(p)} points form {k} clusters up to {gap:.4g} mm apart "
                                    f"(more than a ball's diameter, {dia:g} mm) — {k} balls measured under one "
                                    "id? Give each ball its own id in the `fiducial` channel")
        if off_sphere:
            hint = ""
            if free is not None:
                # a review: Ø12.7 mm balls under the default 9.997 mm read only "not on a sphere"; the
                # clusters above are not looked for when a free sphere fits (5 points of one Ø12.7 ball
                # read "5 balls measured under one id?" — a review of the cluster test)
                d_free = 2 * float(free.params["radius"])
                if free_fits and abs(d_free - diameter) > 0.01 * diameter:
                    hint = (f" — a free sphere fits them with diameter {d_free:.4g} mm, not the {diameter:g} mm "
                            "given: check `diameter` (empty: fitted freely)")
            raise StepError(f"fiducial {i}: the points are not on a sphere (fit RMS {rms * 1e3:.3g} µm){hint}")
        out[int(i)] = (np.array([f.params["x0"], f.params["y0"], f.params["z0"]]), f.covariance[:3, :3], rms)
    return out


def arrows_figure(ref, errors, title):
    from pointspro.core.figures import _figure

    fig = _figure(11, 4.4)
    ax1, ax2 = fig.subplots(1, 2)
    e = errors * 1e3
    q = ax1.quiver(ref[:, 0], ref[:, 1], e[:, 0], e[:, 1], np.linalg.norm(e, axis=1), cmap="viridis")
    fig.colorbar(q, ax=ax1, label="|e| (µm)")
    ax1.set_xlabel("x (mm)")
    ax1.set_ylabel("y (mm)")
    ax1.set_title("volumetric errors at the fiducials (x–y)", fontsize=10)
    ax2.bar(np.arange(len(e)), np.linalg.norm(e, axis=1))
    ax2.set_xlabel("fiducial")
    ax2.set_ylabel("Ev (µm)")
    ax2.set_title(title, fontsize=10)
    return fig


def field_figure(G, pred, std, study, n_grid):
    """Predicted |e| on the middle z slice of the grid, its uncertainty, and the count study."""
    from pointspro.core.figures import _figure

    fig = _figure(14, 4.4)
    ax1, ax2, ax3 = fig.subplots(1, 3)
    g = G.reshape(n_grid, n_grid, n_grid, 3)
    k = n_grid // 2
    mag = np.linalg.norm(pred, axis=1).reshape(n_grid, n_grid, n_grid)[:, :, k] * 1e3
    unc = np.linalg.norm(std, axis=1).reshape(n_grid, n_grid, n_grid)[:, :, k] * 1e3
    ext = (g[0, 0, k, 0], g[-1, 0, k, 0], g[0, 0, k, 1], g[0, -1, k, 1])
    im = ax1.imshow(mag.T, origin="lower", extent=ext, aspect="auto", cmap="viridis")
    fig.colorbar(im, ax=ax1, label="|e| predicted (µm)")
    ax1.set_title(f"predicted error, z = {g[0, 0, k, 2]:.4g} mm", fontsize=10)
    im = ax2.imshow(unc.T, origin="lower", extent=ext, aspect="auto", cmap="magma")
    fig.colorbar(im, ax=ax2, label="σ (µm)")
    ax2.set_title("its standard uncertainty", fontsize=10)
    for ax in (ax1, ax2):
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
    if study:
        n = [s["fiducials"] for s in study]
        m = np.array([s["ev_mean_um"] for s in study])
        sd = np.array([s["ev_std_um"] for s in study])
        ax3.errorbar(n, m, yerr=sd, marker="o", capsize=3)
    ax3.set_xlabel("fiducials used")
    ax3.set_ylabel("Ev over all fiducials (µm)")
    ax3.set_title("fiducial-count study (000 Fig. 3)", fontsize=10)
    return fig


#: a ball farther than this (mm) from the transform fitted to all is a mislabelled one, not a machine's
#: volumetric error (µm to tens of µm after the affine part; balls stand ≥ their diameter apart)
MISLABEL_MM = 0.5


class FiducialsStep(Step):
    id = "fiducials"
    title = "Fiducial calibration (transform, GUM, GP)"
    summary = "Ball centres → 12-parameter transform with GUM uncertainty → GP volumetric model."
    Params = FiducialsParams

    def run(self, cloud, params: FiducialsParams, ctx: Context) -> StepResult:
        from pointspro.core.calibration import volumetric_model as vm
        from pointspro.core.calibration.fiducials import (
            OUTLIER_SIGMA,
            count_study,
            fit_affine,
            frame_check,
            held_out_outliers,
            monte_carlo,
        )
        from pointspro.core.figures import png_artifact
        from pointspro.core.io.text import read_table
        from pointspro.core.units import format_length
        if "fiducial" not in cloud.channels:
            raise StepError("the cloud has no 'fiducial' channel (ball id of each probe point)")
        ctx.progress.check()
        p = ctx.resolve(params.reference, "reference")
        ref_cols = read_table(p, ("fiducial", "x", "y", "z"))
        fid = np.asarray(ref_cols["fiducial"], dtype=np.float64)
        # a ball id is a whole number, each ball once (a review: 3.6 was taken as 3, and of two rows of
        # one id the first, silently — an Ev of 4.5 µm and χ² 1e9 with exit 0)
        frac = np.flatnonzero(fid != np.round(fid))
        if frac.size:
            raise InputError(f"{p}: fiducial id {fid[frac[0]]:g} (row {frac[0] + 1} of the data) is not a "
                             "whole number")
        uniq, counts = np.unique(fid, return_counts=True)
        if (counts > 1).any():
            raise InputError(f"{p}: fiducial {uniq[counts > 1][0]:g} has {counts[counts > 1][0]} rows; "
                             "give each ball's calibrated centre once")
        ref_ids = fid.astype(int).tolist()
        centres = fit_centres(cloud, params.diameter)
        missing = sorted(set(centres) - set(ref_ids))
        if missing:
            raise InputError(f"{p}: fiducial(s) {missing} are measured but not in the reference")
        absent = sorted(set(ref_ids) - set(centres))
        warnings = []
        if absent:
            warnings.append(f"fiducial(s) {absent} of the reference were not measured")
        ids = sorted(centres)
        ref = np.array([[ref_cols[a][ref_ids.index(i)] for a in "xyz"] for i in ids])
        meas = np.array([centres[i][0] for i in ids])
        sm = params.sigma_measured * 1e-3 if params.sigma_measured else float(
            np.sqrt(np.mean([np.trace(centres[i][1]) / 3 for i in ids])))
        sm = max(sm, 1e-7)
        sr = params.sigma_reference * 1e-3
        ctx.progress.update(0.2, "transform")
        fit = fit_affine(ref, meas, sm, sr)
        why = frame_check(fit.D, ref)
        if why:
            raise InputError(f"{p}: {why}")
        warnings += fit.warnings
        e = fit.volumetric_errors
        ev = np.linalg.norm(e, axis=1)
        far = np.flatnonzero(ev > MISLABEL_MM)
        if far.size:
            # a review: two neighbouring balls' ids swapped in the reference passed the frame check
            # (Ev 5.7 mm, χ²/dof 1e8) and wrote a model 60 µm off on the workpiece, exit 0
            worst = far[np.argsort(-ev[far])][:4]
            raise InputError(f"{p}: fiducial(s) {', '.join(str(ids[i]) for i in worst)} lie "
                             f"{', '.join(format_length(ev[i]) for i in worst)} off the 12-parameter transform "
                             f"fitted to all {len(ids)} (the median ball {format_length(float(np.median(ev)))}): "
                             "a machine's volumetric error is µm — check those balls' ids and coordinates "
                             "in the reference (two ids swapped?)")
        # a blunder on one ball (dirt, a mis-probed point): a review's 5 µm on one of 24 balls went unnamed —
        # the selection fell back to "none" and the workpiece error rose 0.53 → 0.84 µm. Each ball's held-out
        # residual against the others' prediction, in robust σ (held_out_outliers: 24 random balls, 0.2 µm
        # noise, no blunder — a ball named on 4 of 600 runs of fourier/kinematic/null fields, 12 of 1000 with
        # 4 more field kinds; a 5 µm blunder named on 298 of 300). Named, not dropped: the user decides
        outliers = held_out_outliers(ref, meas, np.sqrt(sm**2 + sr**2))
        for i, r, z in outliers:
            warnings.append(f"fiducial {ids[i]} lies {format_length(float(np.linalg.norm(r)))} off what the other "
                            f"balls predict for it (held out: the transform and a smooth fit through the others; "
                            f"{z:.1f} σ of their held-out residuals, {OUTLIER_SIGMA:g} σ the limit) — a blunder "
                            "(dirt on the ball, a mis-probed point)? Re-measure it, or leave it out of the cloud; "
                            "it is kept in this calibration")
        # the GP and the workspace live in the machine frame: that is where `volumetric` applies them
        lo, hi = meas.min(axis=0), meas.max(axis=0)
        centre = 0.5 * (ref.min(axis=0) + ref.max(axis=0))  # the reference layout's centre
        u_prop = fit.point_sigma(centre[None, :])[0]
        mc = None
        if params.monte_carlo_runs:
            ctx.progress.update(0.3, "Monte Carlo")
            mc = monte_carlo(ref, meas, sm, sr, centre[None, :], params.monte_carlo_runs)[0]
        ctx.progress.update(0.45, "Gaussian process")
        # a floor for the GP's noise (it must not interpolate the noise): the measured centres' σ,
        # found from the ball fits; between it and the declared noise at a fiducial, σm² + σr², the
        # marginal likelihood chooses — without that ceiling it could call the whole error noise
        # (NOISE_CEILING; core/calibration/gp.py, candidate_kernels)
        gps, gp_specs, loo, selection = vm.fit_error_gps(meas, e, Q=params.Q, check=ctx.progress.check,
                                                         noise_var=sm**2, ref=ref,
                                                         noise_max=NOISE_CEILING * (sm**2 + sr**2))
        # how the error left was found (core/calibration/gp.py, affine_folds and _without_cv): a fold's
        # transform re-fitted on balls that do not determine it gave held-out errors of mm, stored as
        # "none"'s σ (a review: 4 balls, or a plate and one tall ball — volumetric wrote u of 2.5–31 mm)
        basis = selection["sigma_basis"]
        if basis == "cross-validation" and selection["never_held_out"]:
            never = [ids[i] for i in selection["never_held_out"]]
            warnings.append(f"cross-validation: fiducial(s) {never} never held out — without them the other "
                            "balls do not determine the transform where they lie; the error left "
                            f"(no_gp_rms_um, gp_cv_rms_um) is that at the other {selection['held_out']} balls")
        elif basis == "in-sample residuals":
            warnings.append(f"too few fiducials to hold out for a cross-validation ({len(ids)}, at least "
                            f"{MIN_HELD_OUT} that the others determine): no GP; the error left's σ "
                            f"({format_length(selection['no_gp_rms_um']['norm'] * 1e-3)} in |e|) is the "
                            f"residuals' with their degrees of freedom, ν = {len(ids) - 4} per axis — a rough "
                            "estimate; add balls")
        elif basis == "unknown":
            warnings.append(f"{len(ids)} fiducials determine the 12-parameter transform exactly: the volumetric "
                            "error left between them is unknown, and `volumetric` writes u_x, u_y, u_z as "
                            f"unknown (nan) — add balls (a cross-validated σ needs at least {MIN_HELD_OUT} that "
                            "the others determine)")
        ctx.progress.update(0.85, "grid")
        axes = [np.linspace(lo[d], hi[d], params.grid) for d in range(3)]
        G = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        ps = [gps[n].predict(G, return_std=True) for n in ("ex", "ey", "ez")]
        pred = np.column_stack([m for m, _ in ps])
        std = np.column_stack([s for _, s in ps])
        grid_csv = "x,y,z,ex,ey,ez,ux,uy,uz\n" + "".join(
            ",".join(repr(float(v)) for v in row) + "\n" for row in np.column_stack([G, pred, std]))
        model_text = vm.model_text(fit, meas, gp_specs, loo, selection)
        counts = list(range(4, len(ids) + 1, max((len(ids) - 4) // 8, 1)))
        report = {
            "fiducials": len(ids), "sigma_measured_um": sm * 1e3, "sigma_reference_um": sr * 1e3,
            "transform": dict(zip(("D1", "D2", "D3", "D4", "D5", "D6", "D7", "D8", "D9", "Ax", "Ay", "Az"),
                                  fit.theta.tolist())),
            "uncertainty": dict(zip(("D1", "D2", "D3", "D4", "D5", "D6", "D7", "D8", "D9", "Ax", "Ay", "Az"),
                                    np.sqrt(np.diag(fit.cov)).tolist())),
            "chi2": fit.chi2, "dof": fit.dof, "chi2_reduced": fit.chi2 / max(fit.dof, 1),
            "condition_number": fit.cond,
            "ev_um": (ev * 1e3).tolist(), "ev_rms_um": float(np.sqrt(np.mean(ev**2)) * 1e3),
            "centre_uncertainty_gum_um": (u_prop * 1e3).tolist(),
            "centre_uncertainty_monte_carlo_um": None if mc is None else (mc * 1e3).tolist(),
            "gum_vs_monte_carlo": None if mc is None else (u_prop / mc).tolist(),
            "fiducial_count_study": count_study(ref, meas, sm, counts, runs=50),
            # the honest figure: held-out fiducials, hyperparameters re-fitted without them (it
            # includes their measurement noise); the kernel was chosen by it
            "gp_cv_rms_um": selection["gp_cv_rms_um"], "gp_selection": selection,
            # blocked cross-validation (gp.blocked_cv): spatial blocks of balls held out whole — how the
            # GP's error grows away from the balls, and the distance term τ² `volumetric` adds to u²
            "blocked_cv": selection.get("blocked_cv"),
            # closed-form LOO at hyperparameters fitted to all fiducials: biased low, not used to choose
            "gp_loo_rms_um": loo,
            # balls the others cannot predict (held_out_outliers), named in the warnings, kept in the fit
            "outliers": [{"fiducial": ids[i], "held_out_residual_um": (r * 1e3).tolist(), "sigma": z}
                         for i, r, z in outliers],
            "warnings": warnings,
        }
        arts = {"volumetric_model.json": model_text, "volumetric_grid.csv": grid_csv,
                "fiducial_errors.png": png_artifact(arrows_figure, meas, e,
                                                   f"Ev RMS {format_length(report['ev_rms_um'] * 1e-3)}"),
                "volumetric_field.png": png_artifact(field_figure, G, pred, std, report["fiducial_count_study"],
                                                     params.grid)}
        return StepResult(cloud.replace(), report, arts)


FiducialsStep.example_cloud = classmethod(lambda cls, cloud: _example_cloud())
FiducialsStep.example_params = classmethod(lambda cls: _example_params())


def _example_cloud():
    from pointspro.core import PointCloud

    ref = example_layout()
    pts, ids = ball_points(example_measured_centres(ref))
    return PointCloud.from_xyz(*pts.T, fiducial=ids)


def _example_params():
    import tempfile
    from pathlib import Path

    d = Path(tempfile.mkdtemp(prefix="pointspro-fid-"))
    ref = example_layout()
    np.savetxt(d / "reference.csv", np.column_stack([np.arange(1, len(ref) + 1), ref]), delimiter=",",
               header="fiducial,x,y,z", comments="", fmt="%.10g")
    return {"reference": str(d / "reference.csv"), "monte_carlo_runs": 100, "Q": 2}

"""Parameter pieces shared by the steps that fit a pose (misalignment, probe_radius; third-party steps
may use them too)."""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict

from pointspro.core.geometry.posed_fit import dof_names_valid
from pointspro.core.step import param

FIVE_DOF = ["alpha", "beta", "dx", "dy", "dz"]
INITIAL_HELP = "starting (or held) pose; empty values start at 0, dz from the data"
MAX_ITER_HELP = "iteration limit of the fit"


def validate_dof(names: list[str], aspheric_allowed: bool = True) -> list[str]:
    """The `dof` list of a pose fit: not empty, known names, none twice."""
    if not names:
        raise ValueError("fit at least one degree of freedom")
    if not aspheric_allowed:
        bad = [n for n in names if n.startswith("A")]
        if bad:
            raise ValueError(f"{bad}: aspheric coefficients are fitted by probe_radius, not here")
    return dof_names_valid(names)


class InitialPose(BaseModel):
    """Starting values (also the values of DOF left out of `dof`); missing ones start at 0 (dz: data)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN, ±inf: never
    alpha_deg: float | None = param(None, unit="deg", help="tilt about x")
    beta_deg: float | None = param(None, unit="deg", help="tilt about y")
    dx: float | None = param(None, unit="mm", help="decenter in x")
    dy: float | None = param(None, unit="mm", help="decenter in y")
    dz: float | None = param(None, unit="mm", help="height offset")

    def as_dof(self) -> dict:
        names = {"alpha_deg": "alpha", "beta_deg": "beta", "dx": "dx", "dy": "dy", "dz": "dz"}
        return {names[k]: v for k, v in self.model_dump().items() if v is not None}


#: what a flat (a plane, core.surfaces is_flat) determines: its tilt and its height
PLANE_DOF = ["alpha", "beta", "dz"]


def dof_for_surface(surface, dof: list[str], explicit: bool) -> tuple[list[str], str | None]:
    """The DOF to fit on ``surface`` and a note for the report.

    A plane is unchanged by a shift along itself, so dx, dy (and a conic) are not determined: the
    fit's normal matrix is singular, and its "uncertainties" are 10¹² mm (issue 15). With the
    default DOF the fit on a flat takes alpha, beta, dz and says so; DOF named in the recipe that a
    flat cannot determine are an error naming them."""
    from pointspro.core.errors import StepError

    if not (surface is not None and surface.is_flat()):
        return dof, None
    free = [d for d in dof if d in ("dx", "dy", "conic")]
    if not free:
        return dof, None
    if explicit:
        raise StepError(f"dof {free}: a flat (c = 0) is unchanged by a lateral shift, so "
                        f"{', '.join(free)} cannot be fitted — use dof: [alpha, beta, dz]")
    kept = [d for d in dof if d not in free]
    return kept, (f"the nominal is a flat: fitted {', '.join(kept)} (a plane determines its tilt and "
                  f"height, not {', '.join(free)})")


#: the pose fit's outlier exclusion (core/geometry/outliers.py), shared by misalignment and probe_radius
EXCLUDE_HELP = ("robust σ (1.4826·MAD of the residual) beyond which a point is left out of the pose fit — "
                "it stays in the cloud with its residual at the pose the other points give (the example's "
                "five outliers left its fitted dy 92 µm off the truth, tilt and decentre trading along the "
                "fit's valley); empty: every point, plain least squares "
                "(paper 002)")

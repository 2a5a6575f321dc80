"""Parameter pieces shared by the steps that fit a pose (misalignment, probe_radius)."""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict

from pointspro.core.step import param

FIVE_DOF = ["alpha", "beta", "dx", "dy", "dz"]


class InitialPose(BaseModel):
    """Starting values (also the values of DOF left out of `dof`); missing ones start at 0 (dz: data)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    alpha_deg: float | None = param(None, unit="deg", help="tilt about x")
    beta_deg: float | None = param(None, unit="deg", help="tilt about y")
    dx: float | None = param(None, unit="mm", help="decenter in x")
    dy: float | None = param(None, unit="mm", help="decenter in y")
    dz: float | None = param(None, unit="mm", help="height offset")

    def as_dof(self) -> dict:
        names = {"alpha_deg": "alpha", "beta_deg": "beta", "dx": "dx", "dy": "dy", "dz": "dz"}
        return {names[k]: v for k, v in self.model_dump().items() if v is not None}

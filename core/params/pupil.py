"""The pupil centre as steps take it (zernike, bspline_map): ``centre: [x, y]`` or the older
``center_x``/``center_y`` pair; empty: chosen by core.metrics.pupil (docs/conventions.md, Pupil)."""
from __future__ import annotations

from pydantic import model_validator

from pointspro.core.step import Params, param


class PupilCentreParams(Params):
    centre: tuple[float, float] | None = param(
        None, unit="mm", help="(x, y) of the pupil's centre; empty: the nominal surface's axis, or "
        "for a map with no nominal (or a flat) the bounding-box centre of the measured region")
    center_x: float | None = param(None, unit="mm", help="x of the centre (older form of `centre`; "
                                   "give center_x and center_y together)")
    center_y: float | None = param(None, unit="mm", help="y of the centre (older form of `centre`)")

    @model_validator(mode="after")
    def _one_centre(self):
        if (self.center_x is None) != (self.center_y is None):
            raise ValueError("give both center_x and center_y, or `centre: [x, y]`")
        if self.center_x is not None and self.centre is not None:
            raise ValueError("give the centre once: `centre: [x, y]` or center_x/center_y")
        return self

    @property
    def given_centre(self) -> tuple[float, float] | None:
        if self.centre is not None:
            return self.centre
        return None if self.center_x is None else (self.center_x, self.center_y)

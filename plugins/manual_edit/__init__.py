"""`manual_edit`: remove points by their `index` (the original input row).

The window records every deletion the optician makes as this step, so a saved recipe replays the
same cleanup in `pointspro --batch`. Indices are those of the input file, so they stay valid whatever
steps run before.
"""
from __future__ import annotations

import numpy as np
from pydantic import field_validator

from pointspro.core.step import Context, Params, Step, StepResult, param


class ManualEditParams(Params):
    remove: list[int] = param(default_factory=list, help="`index` values (input rows) to delete")
    note: str = param("", help="why (e.g. 'probe slipped off the edge'); kept in the report")

    @field_validator("remove")
    @classmethod
    def _non_negative(cls, v):
        if any(i < 0 for i in v):
            raise ValueError("indices are input rows and cannot be negative")
        return v


class ManualEditStep(Step):
    id = "manual_edit"
    title = "Manual edit"
    summary = "Delete points by input row (`index`), as recorded by the window."
    Params = ManualEditParams

    @classmethod
    def example_params(cls) -> dict:
        return {"remove": [0, 3, 5]}

    def run(self, cloud, params: ManualEditParams, ctx: Context) -> StepResult:
        ctx.progress.check()
        wanted = np.unique(np.asarray(params.remove, dtype=np.int64))
        hit = np.isin(cloud.index, wanted)
        absent = np.setdiff1d(wanted, cloud.index[hit])
        warnings = []
        if absent.size:
            warnings.append(f"{absent.size} index value(s) not in this cloud (already removed or out of "
                            f"range): {absent[:10].tolist()}{' …' if absent.size > 10 else ''}")
        out = cloud.select(~hit)
        ctx.progress.update(1.0, "removed")
        return StepResult(out, {"removed": int(hit.sum()), "not_found": absent.tolist(),
                                "note": params.note, "warnings": warnings})

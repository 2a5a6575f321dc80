"""`manual_edit`: remove points by their `index` (the original input row).

The window records every deletion the optician makes as this step, so a saved recipe replays the
same cleanup in `pointspro --batch`. Indices are those of the input file, so they stay valid whatever
steps run before.

Two keys name the rows, and the step removes their union: ``remove`` lists single rows,
``remove_ranges`` runs of consecutive rows as ``[first, last]`` pairs, both ends included. A lasso over
a map deletes whole stretches of its raster rows, so the window writes each run of two or more
consecutive rows as one pair (a 10⁶-point deletion is a few thousand pairs, not 10⁶ numbers in the
project file) and the isolated rows in ``remove``. A recipe with ``remove`` alone reads as it always did.
"""
from __future__ import annotations

import numpy as np
from pydantic import field_validator

from pointspro.core.step import Context, Params, Step, StepResult, param


class ManualEditParams(Params):
    remove: list[int] = param(default_factory=list, help="`index` values (input rows) to delete")
    remove_ranges: list[tuple[int, int]] = param(
        default_factory=list,
        help="runs of consecutive input rows to delete, [first, last] with both ends included "
             "(the window writes a deletion this way: one pair per run of rows)")
    note: str = param("", help="why (e.g. 'probe slipped off the edge'); kept in the report")

    @field_validator("remove")
    @classmethod
    def _non_negative(cls, v):
        if any(i < 0 for i in v):
            raise ValueError("indices are input rows and cannot be negative")
        if any(i > MAX_ROW for i in v):
            raise ValueError(f"an input row is at most {MAX_ROW} (2⁶²)")
        return v

    @field_validator("remove_ranges")
    @classmethod
    def _ordered(cls, v):
        for k, (a, b) in enumerate(v):
            if a < 0 or b < a:
                raise ValueError(f"pair {k + 1} is [{a}, {b}]: each pair is [first, last] input rows "
                                 "with 0 ≤ first ≤ last")
            if b > MAX_ROW:  # the runs' bounds ± 1 must stay int64 (reporting the absent rows)
                raise ValueError(f"pair {k + 1} is [{a}, {b}]: an input row is at most {MAX_ROW} (2⁶²)")
        return v


#: the largest input row a recipe may name: far beyond any cloud, and its neighbours stay in int64
MAX_ROW = 2**62


def _merged(ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The union of [first, last] pairs as sorted, disjoint, non-adjacent runs (starts, ends)."""
    r = ranges[np.argsort(ranges[:, 0], kind="stable")]
    reach = np.maximum.accumulate(r[:, 1])
    new = np.concatenate(([True], r[1:, 0] > reach[:-1] + 1))
    starts = r[new, 0]
    group = np.cumsum(new) - 1
    ends = np.full(starts.size, np.iinfo(np.int64).min)
    np.maximum.at(ends, group, r[:, 1])
    return starts, ends


def _in_runs(values: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    k = np.searchsorted(starts, values, side="right") - 1
    return (k >= 0) & (values <= ends[np.maximum(k, 0)])


def _absent_runs(present: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """[first, last] runs of the rows of the disjoint runs (starts, ends) not in ``present`` (sorted,
    distinct rows, each inside one run): the gaps between a run's bounds and its present rows."""
    k = np.searchsorted(starts, present, side="right") - 1
    # each run's rows bracketed by the sentinels first - 1 and last + 1, sorted by (run, row)
    vals = np.concatenate((starts - 1, present, ends + 1))
    runs = np.concatenate((np.arange(starts.size), k, np.arange(starts.size)))
    order = np.lexsort((vals, runs))
    vals, runs = vals[order], runs[order]
    gap = (runs[1:] == runs[:-1]) & (np.diff(vals) > 1)
    return np.column_stack([vals[:-1][gap] + 1, vals[1:][gap] - 1])


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
        index = np.asarray(cloud.index, dtype=np.int64)
        absent_runs = np.empty((0, 2), dtype=np.int64)
        if params.remove_ranges:
            # the runs are tested, never expanded: a pair [0, 10¹²] costs what [0, 10] does
            starts, ends = _merged(np.asarray(params.remove_ranges, dtype=np.int64).reshape(-1, 2))
            in_runs = _in_runs(index, starts, ends)
            wanted = wanted[~_in_runs(wanted, starts, ends)]
            hit = in_runs | np.isin(index, wanted)
            absent_runs = _absent_runs(np.unique(index[in_runs]), starts, ends)
        else:
            hit = np.isin(index, wanted)
        absent = np.setdiff1d(wanted, index[hit])
        n_absent = int(absent.size + (absent_runs[:, 1] - absent_runs[:, 0] + 1).sum())
        warnings = []
        if n_absent:
            shown = absent[:10].tolist() + [f"{a}-{b}" if b > a else a for a, b in absent_runs[:10].tolist()]
            more = n_absent > len(absent[:10]) + int(
                (absent_runs[:10, 1] - absent_runs[:10, 0] + 1).sum())
            warnings.append(f"{n_absent} index value(s) not in this cloud (already removed or out of "
                            f"range): {shown[:10]}{' …' if more or len(shown) > 10 else ''}")
        out = cloud.select(~hit)
        ctx.progress.update(1.0, "removed")
        summary = {"removed": int(hit.sum()), "not_found": absent.tolist(), "note": params.note,
                   "warnings": warnings}
        if params.remove_ranges:
            summary["not_found_ranges"] = absent_runs.tolist()
        return StepResult(out, summary)

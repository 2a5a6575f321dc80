"""The end of a batch: a table on the terminal and ``DIR/summary.json`` (per input: status, the error
line, seconds, points in/out, RMS/PV of the residual)."""
from __future__ import annotations

import json
import time

from . import __version__
from .errors import PointsProError
from .io import atomic_path


def entry(input_path: str, status: str, outcome=None, report: dict | None = None, error: str | None = None):
    s = (outcome.summary if outcome is not None and outcome.summary else
         (report or {}).get("summary", {})) or {}
    return {"input": input_path, "status": status,
            "error": error if error is not None else (outcome.error if outcome is not None else None),
            "seconds": round(outcome.seconds, 3) if outcome is not None else None,
            "points_in": s.get("points_in"), "points_out": s.get("points_out"),
            "rms_um": s.get("rms_um"), "pv_um": s.get("pv_um"),
            # the shop's answer (core/assessment.py): the verdict against the drawing, RMS's U95
            "verdict": (s.get("tolerance") or {}).get("verdict"),
            "rms_U95_um": _rms_unc(s).get("U95"), "rms_corrected_um": _rms_unc(s).get("value"),
            "rms_interval95_um": _rms_unc(s).get("interval95"),
            # a failed input keeps its traceback (a bug to report, or where a user error arose)
            "traceback": getattr(outcome, "traceback", None) if status == "failed" else None}


def _rms_unc(s: dict) -> dict:
    e = (s.get("uncertainty") or {}).get("rms_um")
    return e if isinstance(e, dict) else {}


def write_summary(out_dir, recipe_path, entries: list[dict], *, workers: int, scheduler: str | None,
                  seconds: float, interrupted: bool, figures: str | None = None,
                  overrides: list[str] | None = None) -> dict:
    """summary.json: the batch's options (``figures``: the --figures asked; ``overrides``: the --set
    texts, so a night's summary says how its inputs were run), counts and one entry per input."""
    counts: dict = {}
    for e in entries:
        counts[e["status"]] = counts.get(e["status"], 0) + 1
    data = {"pointspro": __version__, "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "recipe": str(recipe_path), "workers": workers, "scheduler": scheduler,
            "figures": figures, "overrides": list(overrides or []),
            "seconds": round(seconds, 3), "interrupted": interrupted, "counts": counts,
            "inputs": entries}
    try:
        with atomic_path(out_dir / "summary.json") as tmp:
            tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    except OSError as e:  # the machine (a full disk, a lost share), not a bug: one line naming the file
        # skipped (--resume): complete from an earlier run, as cli._batch_exit_code counts them
        done = sum(1 for e_ in entries if e_["status"] in ("ok", "skipped"))
        raise PointsProError(f"{out_dir / 'summary.json'}: cannot be written ({e.strerror or e}); "
                             f"{done} of {len(entries)} input(s) have their folder complete") from None
    return data


def table(entries: list[dict]) -> str:
    def f(v, fmt):
        return "—" if v is None else format(v, fmt)

    verdicts = any(e.get("verdict") for e in entries)  # a column only when a recipe has a tolerance
    # with an uncertainty the RMS is the noise-bias-corrected value ± U95 (the per-input line gives
    # the value as measured too): the header says which
    corrected = any(e.get("rms_U95_um") is not None for e in entries)
    rms_head = "RMS µm (corrected ± U95, or its 95 % interval)" if corrected else "RMS µm"
    rows = [("input", "status", "points", rms_head, "PV µm", "s") + (("verdict",) if verdicts else ())]
    for e in entries:
        pts = "—" if e["points_in"] is None else f"{e['points_in']}→{e['points_out']}"
        rms = f(e["rms_um"], ".4g")
        if e.get("rms_U95_um") is not None and e.get("rms_corrected_um") is not None:
            # noise bias removed; U95 to two significant digits, the value to the same place (GUM)
            from .statement import _decimals, value_and_uncertainty

            d = min(_decimals(e["rms_U95_um"]), 9)
            rms = value_and_uncertainty(e["rms_corrected_um"], e["rms_U95_um"], e.get("rms_interval95_um"), d)
        rows.append((e["input"], e["status"], pts, rms, f(e["pv_um"], ".4g"),
                     f(e["seconds"], ".2f")) + ((e.get("verdict") or "—",) if verdicts else ()))
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)

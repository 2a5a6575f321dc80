"""`dynamic_id`: identify the measuring loop's transfer function Gm from calibration steps (004).

Reads the calibration series (``calibration``: a CSV with columns t (s), xd and ref (mm), e.g. 10 steps
up and 10 down of 10 µm) and fits Gm by output error with the order chosen by BIC
(core.dynamics.identify). Writes ``dynamic_model.json`` (what the `dynamic` step's ``model`` reads)
and ``dynamic_fit.png``; reports the order, poles, resonances, DC gain, phase lag at 1, 5, 15, 50 Hz
and the fit's RMS, the real poles too (``real_poles``: z, decay time; a negative one alternates every
sample) and the orders set aside (``orders_set_aside``: a pole decaying slower than a quarter of the
calibration record). Refused: a DC gain ≤ 0 (ref's sign reversed); warned of: one outside 0.5–2. The
cloud passes through unchanged (run it in the recipe that corrects, or alone).
"""
from __future__ import annotations

import numpy as np

from pointspro.core.dynamics.identify import (  # noqa: F401  (LAG_FREQUENCIES: this step's report)
    LAG_FREQUENCIES,
    identify_from_file,
    model_report,
    model_warnings,
)
from pointspro.core.step import Context, Params, Step, StepResult, param


class DynamicIdParams(Params):
    calibration: str = param(file=True, help="calibration series (CSV with t, xd, ref), relative to the recipe")
    t: str = param("t", help="time column (s)")
    xd: str = param("xd", help="encoder column of the axis carrying the sensor (mm)")
    ref: str = param("ref", help="reference sensor column (mm)")
    order: int | None = param(None, ge=1, le=8, help="model order; empty: chosen by BIC")
    max_order: int = param(5, ge=1, le=8, help="largest order tried when the order is chosen")


def held_reference(xd, ref) -> tuple[int, float] | None:
    """(typical run length, share of the steps where xd moves and ref does not) when the reference
    holds its value over runs of samples while the command moves — a slower sensor logged at the
    record's rate (a review: a 250 Hz sensor held in a 1000 Hz log gave a 4× wrong phase lag, no word);
    None otherwise."""
    xd, ref = np.asarray(xd, float), np.asarray(ref, float)
    moving = np.diff(xd) != 0
    if moving.sum() < 5:
        return None
    same = np.diff(ref) == 0
    share = float(np.mean(same[moving]))
    if share < 0.5:
        return None
    change = np.flatnonzero(np.r_[True, ~same])  # where a new value starts
    runs = np.diff(np.r_[change, ref.size])
    return int(np.median(runs)), share


def fit_figure(model, t, xd, ref):
    """Reference against the model's Gm·xd around the largest step, and the frequency response."""
    from pointspro.core.figures import _figure
    from pointspro.core.units import format_length

    fig = _figure(11, 4.2)
    fig.subplots_adjust(right=0.92, wspace=0.3)  # room for the phase axis on the right
    ax1, ax2 = fig.subplots(1, 2)
    y = model.apply(xd)
    c = np.mean(ref - y)
    k = int(np.argmax(np.abs(np.diff(xd))))
    w = slice(max(k - int(0.02 * model.fs), 0), k + int(0.08 * model.fs))
    ax1.plot((t[w] - t[k]) * 1e3, (xd[w] - xd[k]) * 1e3, label="encoder xd", lw=1)
    ax1.plot((t[w] - t[k]) * 1e3, (ref[w] - c - xd[k]) * 1e3, ".", ms=3, label="reference")
    ax1.plot((t[w] - t[k]) * 1e3, (y[w] - xd[k]) * 1e3, label=f"Gm·xd (order {model.order})", lw=1)
    ax1.set_xlabel("time from the step (ms)")
    ax1.set_ylabel("displacement (µm)")
    ax1.legend(fontsize=8)
    ax1.set_title(f"fit RMS {format_length(model.fit_rms)}", fontsize=10)
    f = np.logspace(-1, np.log10(model.fs / 2 * 0.999), 400)
    h = model.response(f)
    ax2.semilogx(f, 20 * np.log10(np.abs(h)), color="#2c6fbb")
    ax2.set_xlabel("frequency (Hz)")
    ax2.set_ylabel("|Gm| (dB)", color="#2c6fbb")
    ax3 = ax2.twinx()
    ax3.semilogx(f, -np.degrees(np.angle(h)), color="#c0392b")
    ax3.set_ylabel("phase lag (deg)", color="#c0392b")
    ax2.set_title("identified Gm", fontsize=10)
    return fig


class DynamicIdStep(Step):
    id = "dynamic_id"
    title = "Dynamic error identification"
    summary = "Identify the measuring loop Gm from calibration steps; writes dynamic_model.json."
    Params = DynamicIdParams

    def run(self, cloud, params: DynamicIdParams, ctx: Context) -> StepResult:
        from pointspro.core.figures import png_artifact

        path = ctx.resolve(params.calibration, "calibration")
        names = (params.t, params.xd, params.ref)
        model, cols = identify_from_file(path, names, params.order, params.max_order, ctx, self.id)
        report = {"calibration": str(path), **model_report(model), "warnings": model_warnings(model)}
        better = sorted(n for n, v in model.bic.items() if n in model.set_aside and v < model.bic[model.order])
        if better:
            report["warnings"].append(
                f"order{'s' if len(better) > 1 else ''} {', '.join(map(str, better))} fitted the calibration "
                f"better (BIC) but {'were' if len(better) > 1 else 'was'} set aside: "
                f"{model.set_aside[better[0]]}, not seen to decay in the record; order {model.order} is used")
        if model.modes() and max(m["frequency_hz"] for m in model.modes()) > 0.8 * model.fs / 2:
            report["warnings"].append("a resonance lies near the Nyquist frequency: modes above it "
                                      "appear aliased; sample faster to resolve them")
        held = held_reference(cols[params.xd], cols[params.ref])
        if held:
            report["warnings"].append(
                f"the reference '{params.ref}' repeats its value in runs of ~{held[0]} samples while "
                f"'{params.xd}' moves ({held[1]:.0%} of its moving steps): a sensor sampled slower than the "
                f"record (about fs/{held[0]}) delays and distorts the identified loop — give the record at "
                "the sensor's own rate")
        arts = {"dynamic_model.json": model.to_json(),
                "dynamic_fit.png": png_artifact(fit_figure, model, cols[params.t], cols[params.xd],
                                                cols[params.ref])}
        return StepResult(cloud.replace(), report, arts)

    @classmethod
    def example_params(cls) -> dict:
        import tempfile

        from pointspro.core.dynamics.identify import write_example_calibration

        # the contract test runs every step on a generic cloud: give it a small calibration file
        return {"calibration": write_example_calibration(tempfile.mkdtemp(prefix="pointspro-dynid-"))}

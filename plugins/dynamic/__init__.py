"""`dynamic`: remove the measuring loop's dynamic error from an on-machine scan (004 eq 13).

The scan is a time series with channels t (s), xd (encoder of the axis carrying the sensor, mm) and
xc (sensor reading, mm), z = xd + xc. The sensor point sits at Gm·xd, not at xd, so
    z_corrected = Gm·xd + xc        (004 eq 13: the recursion x_o[k] = Σ b_i x[k−i] − Σ a_i x_o[k−i] + x_c[k])
with Gm identified from ``calibration`` (core.dynamics.identify, as `dynamic_id`) or read from
``model`` (a dynamic_model.json). The model's sampling rate must be the scan's. Channels added:
``z_raw`` (z before) and ``dynamic_error`` = z_raw − z (mm).

Vibration analysis in the report: PSD of the sensor signal in time and along the surface, its
largest peaks, the phase lag of the sensor point behind the carriage, the aliased frequency of each
known vibration (``vibrations``) and the sampling advice of 000 §3.1. Two lags: ``phase_lag_model_deg``,
the model's lag at the frequency of the largest line of the encoder's spectrum (the loop's lag for the
scan's dominant content: a periodogram of the whole record, which resolves a slow spindle; None, with
``phase_lag_model_note`` saying why, when the spectrum's largest bin is no true local maximum — a smooth
motion with no repeating content, as a spiral on a rotationally symmetric part — or no line stands
clearly above the spectrum's floor, as on a constant feed), and ``phase_lag_scan_deg``, the median over the scan of the Hilbert phase
difference between Gm·xd and xd — weighted by amplitude, so it follows the scan's largest (usually
slowest) content (0.0003° on a scan whose 12 Hz form lags 0.9°); it is not the loop's lag at any one
frequency.
"""
from __future__ import annotations

import numpy as np
from pydantic import field_validator, model_validator

from pointspro.core.errors import InputError, StepError
from pointspro.core.step import Context, Params, Step, StepResult, param


class DynamicParams(Params):
    calibration: str | None = param(None, file=True, help="calibration series (CSV with t, xd, ref): "
                                    "identify Gm here; give this or model")
    model: str | None = param(None, file=True, help="dynamic_model.json from dynamic_id; give this or "
                              "calibration")
    order: int | None = param(None, ge=1, le=8, help="model order when identifying; empty: by BIC")
    t: str = param("t", help="time channel of the scan (s)")
    xd: str = param("xd", help="encoder channel of the axis carrying the sensor (mm)")
    xc: str = param("xc", help="sensor reading channel (mm)")
    vibrations: list[float] = param(default_factory=list, unit="Hz",
                                    help="known vibration frequencies to check for aliasing (each > 0 Hz)")

    @field_validator("vibrations")
    @classmethod
    def _positive(cls, v):
        # a review: [0] was an internal ZeroDivisionError, [-5] advised a spatial period of −667 µm
        bad = [f for f in v if not f > 0]
        if bad:
            raise ValueError(f"{', '.join(f'{f:g}' for f in bad)} Hz: each vibration frequency must be > 0 Hz")
        return v

    @model_validator(mode="after")
    def _one_source(self):
        if (self.calibration is None) == (self.model is None):
            raise ValueError("give exactly one of calibration and model")
        return self


def _figure(t, z_raw, z, x, y, fs):
    from pointspro.core.dynamics.vibration import psd_space, psd_time
    from pointspro.core.figures import _figure as new
    from pointspro.core.figures import length_axis, plain_log_ticks
    from pointspro.core.units import format_length

    fig = new(11, 4.2)
    fig.subplots_adjust(top=1 - 0.6 / 4.2)  # room for the spatial-frequency axis along the top
    ax1, ax2 = fig.subplots(1, 2)
    n = len(t)
    w = slice(n // 2, min(n // 2 + int(5 * fs), n))
    e_mm = z_raw - z
    scale, unit = length_axis(e_mm[w])  # 004's dynamic errors are tens of nm: nm then
    ax1.plot(t[w], e_mm[w] * scale, lw=1)
    ax1.set_xlabel("time (s)")
    ax1.set_ylabel(f"dynamic error z_raw − z ({unit})")
    ax1.set_title(f"removed: RMS {format_length(np.std(e_mm))}, PV {format_length(np.ptp(e_mm))}", fontsize=10)
    f, p = psd_time(z - np.polyval(np.polyfit(t, z, 1), t), fs)
    ax2.loglog(f[1:], p[1:] * 1e6, lw=1, label="z in time (µm²/Hz)")
    ax2.set_xlabel("frequency (Hz)")
    fs_, ps = psd_space(x, y, z)
    ax3 = ax2.twiny()
    ax3.loglog(fs_[1:], ps[1:] * 1e6, lw=1, color="#c0392b", label="along the surface (µm²·mm)")
    ax3.set_xlabel("spatial frequency (1/mm)", color="#c0392b")
    # the title as the legend's (the top axis's labels stand where a title would), with both PSDs
    handles = ax2.get_legend_handles_labels()[0] + ax3.get_legend_handles_labels()[0]
    ax2.legend(handles=handles, fontsize=8, loc="upper right", title="PSD of the corrected height",
               title_fontsize=8)
    for axis in (ax2.xaxis, ax2.yaxis, ax3.xaxis):  # plain text, no mathtext (core/figures.py)
        plain_log_ticks(axis)
    return fig


def _file_lines(cloud) -> dict:
    """sampling_rate's ``lines`` (each sample's line in a text file: the header's line + 1 + its data
    row) and what the rows missing between two samples are. Array positions are not lines once the
    reader dropped a NaN row (a review: a duplicate on line 1003 was named on line 1002, and a dropped
    NaN row read as "the sampling interval changes"), so the row is taken from ``index`` — where the
    text reader made it (meta ``index_in_file`` False). A file's own index column numbers no line of
    it (PointsPro's cloud.csv carries the original input's row: a crop from row 20000 named "line
    21003" of a 3001-line file; other files count from 1): array positions then, as before."""
    text = cloud.meta.get("format") == "text"
    header = cloud.meta.get("header_line")
    first = (int(header) + 1) if text and header else 2
    if not (text and cloud.meta.get("index_in_file") is False):
        return {"lines": np.arange(cloud.n, dtype=np.int64) + first}
    dropped = int(cloud.meta.get("invalid_dropped") or 0)
    why = (f"dropped on reading for a NaN or infinite value ({dropped} row(s) of the file in all)" if dropped
           else "removed before this step")
    return {"lines": np.asarray(cloud.index, dtype=np.int64) + first, "missing": why}


class DynamicStep(Step):
    id = "dynamic"
    title = "Dynamic error correction"
    moves_points = True  # and hands a residual it finds on untouched (core/step.py)
    summary = "z = Gm·xd + xc: remove the measuring loop's lag from an on-machine scan (004 eq 13)."
    Params = DynamicParams

    def run(self, cloud, params: DynamicParams, ctx: Context) -> StepResult:
        from pointspro.core.dynamics.identify import (
            LoopModel,
            identify_from_file,
            model_report,
            model_warnings,
        )
        from pointspro.core.dynamics.timeseries import sampling_rate
        from pointspro.core.dynamics.vibration import (
            advice,
            aliased_frequency,
            dominant_frequency,
            dominant_peaks,
            phase_lag_hilbert_deg,
            psd_time,
        )
        from pointspro.core.figures import png_artifact

        missing = [c for c in (params.t, params.xd, params.xc) if c not in cloud.channels]
        if missing:
            raise StepError(f"the scan has no {'/'.join(missing)} channel (on-machine data need time t, "
                            "encoder xd and sensor xc)")
        from pointspro.core.units import channel_in

        src = cloud.meta.get("source", "scan")
        t = channel_in(cloud, params.t, "s", self.id)  # s, from the unit the file states (t [ms])
        where = _file_lines(cloud)
        fs = sampling_rate(t, src, **where)
        arts = {}
        if params.model is not None:
            from pointspro.core.io.text import read_parameter_text

            p = ctx.resolve(params.model, "model")
            if not p.is_file():
                raise InputError(f"{p}: dynamic model file not found")
            model = LoopModel.from_json(read_parameter_text(p, "dynamic model"), str(p))
        else:
            p = ctx.resolve(params.calibration, "calibration")
            model, _ = identify_from_file(p, ("t", "xd", "ref"), params.order, 5, ctx, self.id)
            arts["dynamic_model.json"] = model.to_json()
        if abs(model.fs - fs) > 0.01 * fs:
            raise StepError(f"the model was identified at {model.fs:g} Hz but the scan is sampled at "
                            f"{fs:g} Hz; identify at the scan's rate")
        ctx.progress.check()
        ctx.progress.update(0.6, "correcting")
        xd, xc = cloud[params.xd], cloud[params.xc]
        z_raw = cloud.z
        gap = np.abs(z_raw - (xd + xc))
        if gap.max() > 1e-6 * max(1.0, np.abs(z_raw).max()):
            i = int(np.argmax(gap))
            raise StepError(f"z ≠ xd + xc on line {int(where['lines'][i])} (off by {gap[i]:.3g} mm): the "
                            "channels are not the scan's encoder and sensor")
        sensor_point = model.apply(xd)
        z = sensor_point + xc
        e = z_raw - z
        ctx.progress.update(0.8, "vibrations")
        f, ps = psd_time(xc, fs)
        f_dom, no_dom = dominant_frequency(xd, fs)
        speed = float(np.sum(np.hypot(np.diff(cloud.x), np.diff(cloud.y))) / (t[-1] - t[0]))
        peaks = dominant_peaks(f, ps, 3, fmin=1.0)
        report = {
            "model": model_report(model), "fs_hz": fs, "samples": cloud.n,
            "dynamic_error_rms_um": float(np.std(e) * 1e3), "dynamic_error_pv_um": float(np.ptp(e) * 1e3),
            "phase_lag_model_deg": ({"frequency_hz": f_dom, "lag_deg": float(model.phase_lag_deg([f_dom])[0])}
                                    if f_dom is not None else None),
            "phase_lag_scan_deg": phase_lag_hilbert_deg(xd, sensor_point) if cloud.n > 100 else None,
            "scan_speed_mm_s": speed, "sensor_psd_peaks_hz": peaks,
            "vibrations": [{"frequency_hz": v, "aliased_hz": float(aliased_frequency(v, fs)),
                            "above_nyquist": bool(v > fs / 2)} for v in params.vibrations],
            "advice": advice(fs, params.vibrations, speed) if params.vibrations else [],
            "warnings": model_warnings(model),
        }
        if f_dom is None:
            report["phase_lag_model_note"] = no_dom
        if not np.isfinite(model.record_s) and model.slowest_decay_s > t[-1] - t[0]:
            report["warnings"].append(f"the model has a pole decaying in {model.slowest_decay_s:.3g} s, longer than "
                                      "the scan: its correction rings on through it — identify the model again")
        out = cloud.replace(xyz=np.column_stack([cloud.x, cloud.y, z]),
                            channels={"z_raw": z_raw, "dynamic_error": e})
        arts["dynamic.png"] = png_artifact(_figure, t, z_raw, z, cloud.x, cloud.y, fs)
        return StepResult(out, report, arts)

    @classmethod
    def example_cloud(cls, cloud):
        """On-machine channels on the generic cloud: sampled at 1 kHz, z = xd + xc."""
        t = np.arange(cloud.n) / 1000.0
        return cloud.replace(channels={"t": t, "xd": cloud.z.copy(), "xc": np.zeros(cloud.n)})

    @classmethod
    def example_params(cls) -> dict:
        import tempfile

        from pointspro.core.dynamics.identify import write_example_calibration

        return {"calibration": write_example_calibration(tempfile.mkdtemp(prefix="pointspro-dyn-"))}

"""The measuring loop's transfer function Gm from calibration steps (paper 004 §"System
identification", eqs 11–13).

The sensor point does not follow the carriage exactly: its displacement is Gm·xd, xd the encoder of
the axis carrying the sensor, so the height measured as xd + xc carries Edyn = (1 − Gm) xd (004 eq 1).
Calibration: the axis makes steps (004: 10 up and 10 down of 10 µm) while a fast reference sensor
(capacitive, 10 kHz) sees where the sensor point really is: ref = Gm·xd + offset + noise.

Identification, in discrete time at the file's sampling rate fs (scipy has no `invfreqs`, and a
continuous fit would still have to be discretised to correct the series):
 1. ARX least squares, y[k] + Σ a_i y[k−i] = Σ b_i u[k−i] + c — linear, but biased when the noise
    is on the output (it is: the reference sensor's), so only a starting point;
 2. output-error fit: min Σ (ref − c − lfilter(b, a, u))² by `scipy.optimize.least_squares`, the
    filter started at rest at the first sample; unbiased for output noise;
 3. the order n (numerator and denominator degree) by the Bayesian information criterion
    BIC = N ln(SSR/N) + p ln N over n = 1 … max_order.
u = xd − xd[0]: Gm acts on the displacement from the first sample, so a static position is measured
as it is (a DC gain ≠ 1 is a scale error of displacements, which the steps measure).
Continuous poles for the report: s = fs · ln(z) (exact for the poles of a sampled system; modes above
the Nyquist frequency fs/2 appear aliased — the report says so).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, StepError
from .timeseries import sampling_rate


@dataclass(frozen=True)
class LoopModel:
    """Discrete Gm(z) = Σ b_i z⁻ⁱ / (1 + Σ a_i z⁻ⁱ) at sampling rate fs (Hz)."""

    b: np.ndarray
    a: np.ndarray
    fs: float
    fit_rms: float = float("nan")           # mm, reference minus model on the calibration
    bic: dict = field(default_factory=dict)  # order → BIC
    steps: int = 0

    @property
    def order(self) -> int:
        return len(self.a) - 1

    @property
    def dc_gain(self) -> float:
        return float(np.sum(self.b) / np.sum(self.a))

    @property
    def poles_z(self) -> np.ndarray:
        return np.roots(self.a)

    @property
    def stable(self) -> bool:
        return bool(np.all(np.abs(self.poles_z) < 1.0))

    def poles_s(self) -> np.ndarray:
        """Continuous poles (1/s), s = fs ln z (principal branch)."""
        with np.errstate(divide="ignore"):
            return self.fs * np.log(self.poles_z.astype(complex))

    def modes(self) -> list[dict]:
        """Resonances: natural frequency (Hz) and damping ratio of each complex pole pair. A real
        pole is none — also a real negative z, whose ln has the imaginary part π·fs: it was reported
        as a mode at the Nyquist frequency (a z = −0.006 pole of an order-3 fit as "1906 Hz, ζ 0.85",
        and the advice to sample faster; issue 16's review)."""
        out = []
        z = np.asarray(self.poles_z, dtype=complex)
        for p, pz in zip(self.poles_s(), z):
            if pz.imag > 1e-12 * max(abs(pz), 1e-300):
                wn = abs(p)
                out.append({"frequency_hz": float(wn / (2 * np.pi)), "damping": float(-p.real / wn)})
        return sorted(out, key=lambda m: m["frequency_hz"])

    def response(self, f_hz) -> np.ndarray:
        """Gm(e^{jωT}) at frequencies f (Hz)."""
        from scipy.signal import freqz

        _, h = freqz(self.b, self.a, worN=2 * np.pi * np.asarray(f_hz, dtype=np.float64) / self.fs)
        return h

    def phase_lag_deg(self, f_hz) -> np.ndarray:
        """Phase lag of the sensor point behind the carriage (degrees, positive = lagging)."""
        return -np.degrees(np.angle(self.response(f_hz)))

    def apply(self, xd) -> np.ndarray:
        """Gm·xd (mm): the sensor point's position, the filter at rest at the first sample (004 eq 13
        is this recursion)."""
        from scipy.signal import lfilter, lfilter_zi

        xd = np.asarray(xd, dtype=np.float64)
        x0 = xd[0]
        y = lfilter(self.b, self.a, xd - x0, zi=lfilter_zi(self.b, self.a) * 0.0)[0]
        return y + x0

    def describe(self) -> dict:
        return {"order": self.order, "fs_hz": self.fs, "b": self.b.tolist(), "a": self.a.tolist(),
                "dc_gain": self.dc_gain, "poles_z": [[float(p.real), float(p.imag)] for p in self.poles_z],
                "modes": self.modes(), "fit_rms_um": self.fit_rms * 1e3,
                "bic": {str(k): v for k, v in self.bic.items()}, "steps": self.steps,
                "aliased_modes_possible": True}

    def to_json(self) -> str:
        return json.dumps({"pointspro_dynamic_model": 1, **self.describe()}, indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str, source: str = "model") -> "LoopModel":
        try:
            d = json.loads(text)
            if d.get("pointspro_dynamic_model") != 1:
                raise KeyError("pointspro_dynamic_model")
            m = cls(np.asarray(d["b"], dtype=np.float64), np.asarray(d["a"], dtype=np.float64),
                    float(d["fs_hz"]), float(d.get("fit_rms_um", float("nan"))) * 1e-3)
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            from ..io.text import json_problem  # quotes nothing of the file

            raise InputError(f"{source}: not a PointsPro dynamic model ({json_problem(e)})") from None
        if m.a[0] != 1.0 or not m.stable:
            raise InputError(f"{source}: the model is not a stable normalised filter")
        return m


def find_steps(u: np.ndarray, fs: float) -> int:
    """Number of steps (rises and falls) in a displacement series: 20 ms windows over which the
    displacement moves by more than a twentieth of its range and well above its noise. 0 when the
    data hold none (a still axis, or a slow ramp)."""
    w = max(int(0.02 * fs), 1)
    if u.size < 4 * w:
        return 0
    d = u[w:] - u[:-w]
    d1 = np.diff(u)
    noise = 1.4826 * np.median(np.abs(d1 - np.median(d1))) * np.sqrt(w) + 1e-15
    span = np.ptp(u)
    moving = np.abs(d) > max(10 * noise, 0.05 * span)
    if span == 0 or not moving.any():
        return 0
    idx = np.flatnonzero(moving)
    return 1 + int(np.sum(np.diff(idx) > w))  # windows of one edge overlap; a gap starts the next


def _arx(u, y, n):
    N = len(y)
    rows = np.arange(n, N)
    cols = [-y[rows - i] for i in range(1, n + 1)] + [u[rows - i] for i in range(0, n + 1)] + \
        [np.ones(rows.size)]
    A = np.column_stack(cols)
    theta, *_ = np.linalg.lstsq(A, y[rows], rcond=None)
    a = np.r_[1.0, theta[:n]]
    b = theta[n:2 * n + 1]
    return b, a, theta[-1]


def _stabilise(a):
    r = np.roots(a)
    bad = np.abs(r) >= 1
    if bad.any():
        r[bad] = 0.95 / np.conj(r[bad])
        a = np.real(np.poly(r))
    return a


def _oe(u, y, n, start):
    from scipy.optimize import least_squares
    from scipy.signal import lfilter

    b0, a0, c0 = start
    a0 = _stabilise(a0)
    scale = float(np.std(y)) or 1.0

    def resid(x):
        b = x[: n + 1]
        a = np.r_[1.0, x[n + 1: 2 * n + 1]]
        if np.any(np.abs(np.roots(a)) >= 1.0):
            return np.full(y.shape, 1e3 * scale)
        return (y - x[-1] - lfilter(b, a, u)) / scale

    x0 = np.r_[b0, a0[1:], c0]
    sol = least_squares(resid, x0, method="lm", xtol=1e-12, ftol=1e-12, max_nfev=200 * len(x0))
    b = sol.x[: n + 1]
    a = np.r_[1.0, sol.x[n + 1: 2 * n + 1]]
    r = resid(sol.x) * scale
    return b, a, sol.x[-1], float(r @ r)


def identify(t, xd, ref, max_order: int = 5, order: int | None = None,
             what: str = "calibration") -> LoopModel:
    """Gm from a calibration series (t s, xd and ref mm). StepError/InputError with the reason."""
    fs = sampling_rate(t, what, row_offset=2)
    u = np.asarray(xd, dtype=np.float64)
    y = np.asarray(ref, dtype=np.float64)
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise InputError(f"{what}: xd or ref holds values that are not numbers")
    steps = find_steps(u, fs)
    if steps == 0:
        raise StepError(f"{what}: the axis makes no step in xd — calibration needs steps "
                        "(004: 10 up and 10 down of 10 µm)")
    u = u - u[0]
    orders = [order] if order else list(range(1, max_order + 1))
    N = len(y)
    best = None
    bic = {}
    worst_pole = 0.0
    for n in orders:
        start = _arx(u, y, n)
        rho = float(np.max(np.abs(np.roots(start[1])), initial=0.0))
        if rho >= 1.0:  # the data themselves say the loop is unstable: never "stabilise" it away
            worst_pole = max(worst_pole, rho)
            continue
        b, a, c, ssr = _oe(u, y, n, start)
        p = 2 * n + 2
        bic[n] = float(N * np.log(max(ssr, 1e-300) / N) + p * np.log(N))
        if np.all(np.abs(np.roots(a)) < 1.0) and (best is None or bic[n] < best[0]):
            best = (bic[n], b, a, c, ssr)
    if best is None:
        raise StepError(f"{what}: the identified model is unstable (a pole at |z| = {worst_pole:.4g} ≥ 1): "
                        "the data do not describe a damped measuring loop — check the xd/ref columns")
    _, b, a, c, ssr = best
    return LoopModel(b, a, fs, float(np.sqrt(ssr / N)), bic, steps)


#: frequencies (Hz) at which reports quote the loop's phase lag
LAG_FREQUENCIES = (1.0, 5.0, 15.0, 50.0)


def identify_from_file(path, names, order, max_order, ctx, step: str = "dynamic_id"):
    """Gm from a calibration file (columns ``names`` = time, encoder, reference): (LoopModel, the
    columns read, time in s whatever unit its header states: ``t [ms]``). ``ctx``: the step's Context
    (progress and cancel); ``step``: the step's id, for messages."""
    from ..io.text import read_table

    ctx.progress.check()
    cols = read_table(path, names, units={names[0]: "s"}, reader=f"the {step} step")
    ctx.progress.update(0.2, "identifying Gm")
    model = identify(cols[names[0]], cols[names[1]], cols[names[2]], max_order=max_order, order=order,
                     what=str(path))
    return model, cols


def model_report(model) -> dict:
    """The model as reports give it: order, poles, modes, DC gain, fit RMS, phase lag at
    LAG_FREQUENCIES and the Nyquist frequency."""
    d = model.describe()
    d["phase_lag_deg"] = {f"{f:g}_hz": float(v) for f, v in
                          zip(LAG_FREQUENCIES, model.phase_lag_deg(LAG_FREQUENCIES))}
    d["nyquist_hz"] = model.fs / 2
    return d


def write_example_calibration(folder) -> str:
    """A small calibration series (1 kHz, one 10 µm step up and down through a 3-tap loop) written as
    ``calibration.csv`` (t, xd, ref) in ``folder``; its path. The dynamic steps' examples."""
    from pathlib import Path

    t = np.arange(2000) / 1000.0
    xd = np.where((t > 0.5) & (t < 1.5), 0.01, 0.0)
    xd = np.convolve(xd, np.ones(5) / 5, mode="same")
    ref = np.convolve(xd, [0.6, 0.3, 0.1], mode="full")[: len(xd)] + 1e-6 * np.sin(t * 7)
    p = Path(folder) / "calibration.csv"
    np.savetxt(p, np.column_stack([t, xd, ref]), delimiter=",", header="t,xd,ref", comments="")
    return str(p)

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
The reference's own zero (its offset c, millimetres from the encoder's) is removed before the fits (the
median of ref − u) and the output-error fit starts c at the least-squares offset of its start filter:
the ARX intercept is c·Σa, not c, and starting from it made the fit depend on where the reference's
zero lies (a 338 Hz loop read as order 5 with a 2.75 kHz resonance that is not there).
Accepted poles decay within DECAY_FRACTION of the calibration record (1/e time −1/(fs ln|z|)): a slower
pole — in practice one at z ≈ −1 that the fit pushes against |z| = 1 — is not seen to decay, so the
data cannot tell it from drift; it rings at the Nyquist frequency through every corrected scan.
A DC gain ≤ 0 (ref moving against xd: its sign reversed) is refused.
Continuous poles for the report: s = fs · ln(z) (exact for the poles of a sampled system; modes above
the Nyquist frequency fs/2 appear aliased — the report says so).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, StepError
from .timeseries import sampling_rate

#: LoopModel.apply's pre-roll: this many of the model's slowest decay times (e^−12 of a start
#: transient left), at most PREROLL_MAX samples
PREROLL_DECAYS = 12.0
PREROLL_MAX = 200_000
#: … run only where the initial velocity stands this many of its standard errors clear of 0
PREROLL_SIGNIFICANCE = 3.0
#: the initial velocity is fitted over this many of the loop's settling times (at least
#: VELOCITY_WINDOW_MIN samples)
VELOCITY_WINDOW = 4.0
VELOCITY_WINDOW_MIN = 8
#: … or over the longest of its halvings (down to VELOCITY_WINDOW_MIN samples) whose slope agrees with
#: every shorter one's within this many combined standard errors (the encoder noise's, estimated from
#: the 4th differences of at least VELOCITY_NOISE_MIN samples)
VELOCITY_AGREE = 3.0
VELOCITY_NOISE_MIN = 64

#: a pole is accepted when its decay time (1/e) is at most this fraction of the calibration record:
#: over the record it then decays by e⁴ ≈ 55× or more, which the steps show; a slower one is not seen
#: to decay (its time constant is not identified) and rings on through the correction
DECAY_FRACTION = 0.25
#: DC gains outside this range are warned of (the sensor point follows the carriage at rest: ≈ 1)
DC_GAIN_PLAUSIBLE = (0.5, 2.0)


@dataclass(frozen=True)
class LoopModel:
    """Discrete Gm(z) = Σ b_i z⁻ⁱ / (1 + Σ a_i z⁻ⁱ) at sampling rate fs (Hz)."""

    b: np.ndarray
    a: np.ndarray
    fs: float
    fit_rms: float = float("nan")           # mm, reference minus model on the calibration
    bic: dict = field(default_factory=dict)  # order → BIC
    steps: int = 0
    record_s: float = float("nan")           # duration of the calibration record (s)
    set_aside: dict = field(default_factory=dict)  # order → why its fit was not accepted

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

    def decay_times_s(self) -> np.ndarray:
        """1/e decay time of each pole (s), −1/(fs ln|z|); inf for |z| ≥ 1."""
        r = np.abs(self.poles_z)
        out = np.full(r.shape, np.inf)
        ok = r < 1.0
        with np.errstate(divide="ignore"):
            out[ok] = -1.0 / (self.fs * np.log(r[ok]))
        return out

    @property
    def slowest_decay_s(self) -> float:
        return float(np.max(self.decay_times_s(), initial=0.0))

    def real_poles(self) -> list[dict]:
        """The real poles, which modes() leaves out: z, decay time (s); a negative one alternates in
        sign every sample (a response at the Nyquist frequency, which no sampled continuous loop has
        as a single pole)."""
        z = np.asarray(self.poles_z, dtype=complex)
        tau = self.decay_times_s()
        out = [{"z": float(p.real), "decay_time_s": float(d), "alternating": bool(p.real < 0)}
               for p, d in zip(z, tau) if abs(p.imag) <= 1e-12 * max(abs(p), 1e-300)]
        return sorted(out, key=lambda r: -abs(r["z"]))

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
        """Gm·xd (mm): the sensor point's position by 004 eq 13's recursion, started in the steady
        state of the axis's initial motion: where the axis moves at the first sample, the filter runs
        first over a pre-roll of PREROLL_DECAYS of its slowest decay times on xd extrapolated backwards
        at its initial velocity. Started at rest, a scan that begins while the axis moves (a cropped
        stream, a scan started on the fly) carried the loop's start transient: 609 nm over its first
        20 ms at 1.8 mm/s (a review). The initial velocity is a least-squares cubic's over the
        loop's settling window, or the longest of its halvings that agrees with the shorter ones
        (_initial_velocity), and the pre-roll is run only where it stands
        PREROLL_SIGNIFICANCE standard errors clear of 0: a scan that starts at rest is filtered from
        rest, as before — also on a real encoder, whose noise made a 3-point difference's velocity
        noise (2 nm at rest through 004's Gm at 10 kHz: a start error of 17 nm instead of 2.2 nm; a
        100 Hz, ζ 0.5 loop: 57 nm instead of 1.3 nm; a review). An acceleration at the first sample
        is not extrapolated (a start at rest accelerates too): its transient remains, second order
        (5 nm at 25 mm/s² through a 300 Hz, ζ 0.2 loop)."""
        from scipy.signal import lfilter

        xd = np.asarray(xd, dtype=np.float64)
        x0 = xd[0]
        u = xd - x0
        L = self._preroll_samples()
        v0 = self._initial_velocity(u, self._velocity_window()) if L > 0 else 0.0
        if v0 != 0.0:
            return lfilter(self.b, self.a, np.r_[v0 * np.arange(-L, 0, dtype=np.float64), u])[L:] + x0
        return lfilter(self.b, self.a, u) + x0

    def _preroll_samples(self) -> int:
        """PREROLL_DECAYS slowest decay times in samples (at least 10, at most PREROLL_MAX); 0 for a
        model with a pole that does not decay."""
        tau = self.slowest_decay_s
        if not np.isfinite(tau):
            return 0
        return int(min(max(np.ceil(PREROLL_DECAYS * tau * self.fs), 10), PREROLL_MAX))

    def _velocity_window(self) -> int:
        """Samples over which the initial velocity is fitted: VELOCITY_WINDOW times the loop's settling
        time — the longer of its slowest decay time and its lag at 0 Hz, the time over which the
        start transient is made — at least VELOCITY_WINDOW_MIN samples."""
        k = np.arange(max(self.b.size, self.a.size), dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):  # a DC gain of 0: no lag, the decay time
            lag = abs(float(k[:self.b.size] @ self.b / np.sum(self.b) - k[:self.a.size] @ self.a / np.sum(self.a)))
        settle = max(self.slowest_decay_s * self.fs, lag if np.isfinite(lag) else 0.0)
        return int(min(max(np.ceil(VELOCITY_WINDOW * settle), VELOCITY_WINDOW_MIN), PREROLL_MAX))

    @staticmethod
    def _initial_velocity(u: np.ndarray, window: int) -> float:
        """du/dk at the first sample (mm per sample): the slope at k = 0 of a least-squares cubic (an
        axis accelerating from rest reads ≈ 0; a cubic, as the jerk of a 2 Hz, 0.2 mm motion left a
        quadratic's slope 3 nm of transient), or 0 where it is not PREROLL_SIGNIFICANCE of its standard
        errors clear of 0 — encoder noise, quantisation, a start at rest (the 3-point difference before
        made 2 nm of noise a velocity). Its standard error: the fit's (from the residuals) and its
        truncation, the change from the quadratic's slope, in quadrature — a smooth start at rest fits
        no polynomial exactly; 0 with fewer than 6 samples.

        The window, adaptive (Lepski's rule): ``window`` (the loop's settling window) and its halvings
        down to VELOCITY_WINDOW_MIN samples are fitted from the shortest up, and the longest is taken
        whose slope lies within VELOCITY_AGREE = 3 combined standard errors (in quadrature) of every
        shorter window's. A long window averages the noise away, but over a slow loop's settling
        window a motion of about that period is no cubic: a 10 Hz, ζ 0.7 loop at 1 kHz fits 92
        samples, where a 0.2 mm, 5 Hz sine's slope read 23 % high (a start error of 40.5 µm, 9.1 µm
        with the 3-point difference; a 3 Hz loop, 2 Hz sine: 54 %, 130 µm against 29 µm; a review);
        the shorter windows disagree, and 11 and 9 samples are taken (9.1 µm, 29 µm). The standard
        errors here are the noise's alone, σ from the 4th differences (their variance is 70 σ² for
        white noise; a smooth motion adds (2πf/fs)⁴ of its amplitude to them: 0.2 nm for that 5 Hz
        sine, σ 0.02 nm) over the window, at least VELOCITY_NOISE_MIN samples — a window's own
        residuals, 4 degrees of freedom at 8 samples, cut 4 % of noisy starts short. Nested least-
        squares slopes differ by √(se_short² − se_long²) < their combined standard error, so a motion
        that is a cubic is cut short by chance in under 1 start in 100 (1.8 mm/s and 2 nm of noise
        through a 100 Hz, ζ 0.5 loop at 10 kHz: 8 in 1000, its velocity then from 64 samples or
        fewer); a start at rest keeps the significance test above."""
        n = int(min(window, u.size))
        if n < 6:
            return 0.0
        d4 = np.diff(u[:min(u.size, max(n, VELOCITY_NOISE_MIN))], 4)
        sigma = float(np.sqrt(np.mean(d4 * d4) / 70.0)) if d4.size else 0.0
        grid = [n]
        while grid[-1] // 2 >= VELOCITY_WINDOW_MIN:
            grid.append(grid[-1] // 2)
        shorter, fit = [], None
        for m in reversed(grid):
            v3, v2, se, gain = LoopModel._cubic_slope(u[:m])
            if any(abs(v3 - v) > VELOCITY_AGREE * np.hypot(sigma * gain, s) for v, s in shorter):
                break
            shorter.append((v3, sigma * gain))
            fit = (v3, v2, se)
        v0, v2, se = fit
        return v0 if abs(v0) > PREROLL_SIGNIFICANCE * np.hypot(se, v0 - v2) else 0.0

    @staticmethod
    def _cubic_slope(y: np.ndarray) -> tuple[float, float, float, float]:
        """Slopes at the first sample (per sample) of the least-squares cubic and quadratic through
        ``y`` (at least 5 samples), the cubic's standard error from its residuals, and that of unit
        white noise (its gain: times σ, the slope's standard error from noise of σ)."""
        n = y.size
        k = np.arange(n, dtype=np.float64) / (n - 1)  # scaled: a long window stays well conditioned
        out = []
        for deg in (3, 2):
            A = np.vander(k, deg + 1, increasing=True)
            coef, *_ = np.linalg.lstsq(A, y, rcond=None)
            out.append(float(coef[1]) / (n - 1))
            if deg == 3:
                r = y - A @ coef
                gain = float(np.sqrt(np.linalg.inv(A.T @ A)[1, 1])) / (n - 1)
                se = float(np.sqrt(float(r @ r) / (n - 4))) * gain
        return out[0], out[1], se, gain

    def describe(self) -> dict:
        return {"order": self.order, "fs_hz": self.fs, "b": self.b.tolist(), "a": self.a.tolist(),
                "dc_gain": self.dc_gain, "poles_z": [[float(p.real), float(p.imag)] for p in self.poles_z],
                "modes": self.modes(), "real_poles": self.real_poles(),
                "slowest_decay_s": self.slowest_decay_s, "fit_rms_um": self.fit_rms * 1e3,
                "bic": {str(k): v for k, v in self.bic.items()}, "steps": self.steps,
                "record_s": self.record_s if np.isfinite(self.record_s) else None,
                "orders_set_aside": {str(k): v for k, v in self.set_aside.items()},
                "aliased_modes_possible": True}

    def to_json(self) -> str:
        return json.dumps({"pointspro_dynamic_model": 1, **self.describe()}, indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str, source: str = "model") -> "LoopModel":
        try:
            d = json.loads(text)
            if d.get("pointspro_dynamic_model") != 1:
                raise KeyError("pointspro_dynamic_model")
            record = d.get("record_s")
            m = cls(np.asarray(d["b"], dtype=np.float64), np.asarray(d["a"], dtype=np.float64),
                    float(d["fs_hz"]), float(d.get("fit_rms_um", float("nan"))) * 1e-3,
                    record_s=float("nan") if record is None else float(record))
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            from ..io.text import json_problem  # quotes nothing of the file

            raise InputError(f"{source}: not a PointsPro dynamic model ({json_problem(e)})") from None
        if m.a[0] != 1.0 or not m.stable:
            raise InputError(f"{source}: the model is not a stable normalised filter")
        if np.isfinite(m.record_s) and m.slowest_decay_s > DECAY_FRACTION * m.record_s:
            raise InputError(f"{source}: the model has a pole decaying in {m.slowest_decay_s:.3g} s, more than "
                             f"{DECAY_FRACTION:g} of its {m.record_s:.3g} s calibration record: identify it again")
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

    b0, a0, _ = start  # the ARX intercept is c·Σa, not the offset c
    a0 = _stabilise(a0)
    scale = float(np.std(y)) or 1.0
    y_start = lfilter(b0, a0, u)
    c0 = float(np.mean(y - y_start))  # the offset that fits best with the start filter
    r0 = (y - c0 - y_start) / scale
    # an unstable trial costs more than the start whatever the data's units and zero: never accepted
    penalty = 1e3 * max(1.0, float(np.sqrt(np.mean(r0 * r0))))

    def resid(x):
        b = x[: n + 1]
        a = np.r_[1.0, x[n + 1: 2 * n + 1]]
        if np.any(np.abs(np.roots(a)) >= 1.0):
            return np.full(y.shape, penalty)
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
    level = float(np.median(y - u))  # the reference's zero: the fits see ref from about 0 whatever it is
    y = y - level
    orders = [order] if order else list(range(1, max_order + 1))
    N = len(y)
    record = N / fs
    max_decay = DECAY_FRACTION * record
    best = None
    bic = {}
    arx_unstable = {}   # order → the ARX start's largest |z|
    set_aside = {}      # order → why the fit was not accepted
    for n in orders:
        start = _arx(u, y, n)
        rho = float(np.max(np.abs(np.roots(start[1])), initial=0.0))
        if rho >= 1.0:  # never "stabilise" an unstable start away silently
            arx_unstable[n] = rho
            continue
        b, a, c, ssr = _oe(u, y, n, start)
        p = 2 * n + 2
        bic[n] = float(N * np.log(max(ssr, 1e-300) / N) + p * np.log(N))
        fit = LoopModel(b, a, fs)
        tau = fit.decay_times_s()
        k = int(np.argmax(tau))
        if tau[k] > max_decay:
            z = fit.poles_z[k]
            zs = f"{z.real:.6g}" if abs(z.imag) <= 1e-12 * abs(z) else f"{z.real:.4g}{z.imag:+.4g}j"
            set_aside[n] = (f"a pole at z = {zs} (|z| = {abs(z):.9g}) decaying in {tau[k]:.3g} s"
                            + (", ringing at the Nyquist frequency" if z.real < 0 else ""))
            continue
        if best is None or bic[n] < best[0]:
            best = (bic[n], b, a, c + level, ssr)
    if best is None:
        raise StepError(_no_model_message(what, order, orders, arx_unstable, set_aside, max_decay, record))
    _, b, a, c, ssr = best
    model = LoopModel(b, a, fs, float(np.sqrt(ssr / N)), bic, steps, record, set_aside)
    g = model.dc_gain
    if not g > 0.0:
        raise StepError(f"{what}: the identified DC gain is {g:.4g} ≤ 0 — ref moves against xd: the reference "
                        "sensor's sign is likely reversed (negate ref)")
    return model


def _no_model_message(what, order, orders, arx_unstable, set_aside, max_decay, record) -> str:
    if order is not None and order in arx_unstable:
        return (f"{what}: order {order} cannot be fitted: its ARX start (the linear least-squares fit the "
                f"output-error fit starts from, biased by the reference's noise) has a pole at |z| = "
                f"{arx_unstable[order]:.4g} ≥ 1 — try another order, or leave order empty to choose it by BIC")
    if not set_aside:  # every order's start unstable: the data themselves run away
        return (f"{what}: the identified model is unstable at every order {orders[0]}–{orders[-1]} (a pole "
                f"at |z| = {max(arx_unstable.values()):.4g} ≥ 1): the data do not describe a damped measuring "
                "loop — check the xd/ref columns")
    why = "; ".join(f"order {n}: {r}" for n, r in set_aside.items())
    if arx_unstable:
        why += "; " + ", ".join(f"order {n}: unstable ARX start (|z| = {r:.4g})" for n, r in arx_unstable.items())
    advice = ("try another order, or leave order empty to choose it by BIC" if order is not None else
              "check the calibration (steps that settle well within the record, the reference's noise)")
    return (f"{what}: no model whose poles decay within {DECAY_FRACTION:g} of the {record:.3g} s calibration "
            f"record ({max_decay:.3g} s): {why} — the record does not show a pole that slow decaying, so it "
            f"is not identified (in practice a fitting artefact) and would ring through the correction; {advice}")


def model_warnings(model) -> list[str]:
    """What a report should say about an accepted model: a DC gain far from 1."""
    g = model.dc_gain
    lo, hi = DC_GAIN_PLAUSIBLE
    if lo <= g <= hi:
        return []
    how = f"{g / hi:.3g}× the largest" if g > hi else f"{lo / g:.3g}× below the smallest"
    return [f"the DC gain is {g:.4g} ({how} plausible, {lo:g}–{hi:g}): at rest the sensor point follows the "
            "carriage (a gain ≈ 1); this far off, ref and xd are likely in different units or the wrong "
            "columns, and the correction scales every displacement by it"]


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

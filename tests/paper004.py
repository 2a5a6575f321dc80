"""Simulated set-ups of paper 004 (dynamic error calibration of on-machine measurement).

Gm: the paper's identified loop, eq 12, Gm(s) = (1.29e5 s² − 3.07e8 s + 1.26e12) /
(s³ + 5.17e4 s² + 1.22e8 s + 1.27e12) (the printed denominator's s on 1.22e8 restored); its phase lag
is 1.8° at 15 Hz (the paper: ~2°) and its DC gain 0.992. The continuous loop is simulated by
scipy.signal.lsim at 1 kHz (input linear between samples), so the identification never sees the
model class it fits.
"""
from __future__ import annotations

import numpy as np
from scipy import signal

GM_NUM = [1.29e5, -3.07e8, 1.26e12]
GM_DEN = [1.0, 5.17e4, 1.22e8, 1.27e12]
FS = 1000.0


def loop(u, fs=FS):
    """Sensor-point displacement Gm·u for u sampled at fs (u from rest at u[0])."""
    t = np.arange(len(u)) / fs
    _, y, _ = signal.lsim((GM_NUM, GM_DEN), u - u[0], t)
    return y + u[0]


def servo(cmd, fs=FS, bw_hz=40.0, zeta=0.7):
    """The axis following its command (a 2nd-order servo); the encoder reads this."""
    w = 2 * np.pi * bw_hz
    t = np.arange(len(cmd)) / fs
    _, y, _ = signal.lsim(([w * w], [1, 2 * zeta * w, w * w]), cmd - cmd[0], t)
    return y + cmd[0]


def calibration(seed=0, steps=10, height=10e-3, dwell=0.4, noise=2e-6, offset=0.0371):
    """10 up and 10 down steps of 10 µm (mm); columns t, xd, ref with the reference's own offset."""
    n_dw = int(dwell * FS)
    levels = np.r_[np.arange(steps + 1), np.arange(steps - 1, -1, -1)] * height
    cmd = np.repeat(levels, n_dw) + 12.5  # the axis sits at 12.5 mm
    xd = servo(cmd)
    rng = np.random.default_rng(seed)
    ref = loop(xd) - 12.5 + offset + rng.normal(0, noise, len(xd))
    t = np.arange(len(xd)) / FS
    return t, xd, ref


def oap_height(u, v, efl=50.8):
    """90° off-axis paraboloid (EFL 50.8 mm, parent focal length f = 25.4 mm, off-axis d = 50.8 mm),
    height along the normal at its centre as a function of the tangent-plane coordinates (mm)."""
    f = efl / 2.0
    d = 2.0 * f
    z0 = d * d / (4 * f)
    n = np.array([-d / (2 * f), 0.0, 1.0])
    n /= np.linalg.norm(n)
    e1 = np.array([n[2], 0.0, -n[0]])
    px = d + u * e1[0]
    pz = z0 + u * e1[2]
    # (px + w nx)² + v² − 4f(pz + w nz) = 0, the small root in w
    A = n[0] ** 2
    B = 2 * n[0] * px - 4 * f * n[2]
    C = px * px + v * v - 4 * f * pz
    return 2 * C / (-B - np.sign(B) * np.sqrt(B * B - 4 * A * C))


def spiral_scan(seed=1, radius=12.7, rpm=30.0, pitch=0.1, form_nm=40.0, noise=5e-6):
    """The OAP measured on a spiral at 30 rpm, 0.1 mm/rev, 1 kHz (004 §validation): returns the cloud
    columns x, y, z (= xd + xc), t, c (deg), xd, xc and the true height h."""
    revs = radius / pitch
    T = revs * 60.0 / rpm
    t = np.arange(int(T * FS)) / FS
    c = 360.0 * rpm / 60.0 * t
    r = radius - pitch * rpm / 60.0 * t
    x, y = r * np.cos(np.deg2rad(c)), r * np.sin(np.deg2rad(c))
    h_nom = oap_height(x, y)
    form = form_nm * 1e-6 * np.cos(2 * np.pi * x / 6.0) * np.sin(2 * np.pi * y / 9.0)
    h = h_nom + form
    xd = servo(h_nom + 3.0)          # Z follows the nominal (plus a stand-off) on its encoder
    sensor_point = loop(xd)          # where the sensor's focus really is
    rng = np.random.default_rng(seed)
    xc = (h + 3.0) - sensor_point + rng.normal(0, noise, len(t))
    return {"x": x, "y": y, "z": xd + xc, "t": t, "c": c, "xd": xd, "xc": xc, "h": h + 3.0}

"""Stylus profiles: clouds whose points lie on one line through the axis, or on several lines at
azimuths (docs/conventions.md, Profiles).

A profilometer (Form Talysurf and the like) records x, z of the tip centre along one scan line. Here a
profile is a PointCloud like any other, in the measuring frame, with its points on the vertical plane
at azimuth θ (the scan direction in x, y):

    x = s·cos θ − a·sin θ,   y = s·sin θ + a·cos θ        (s along the scan, a across it: 0 as read)

and the channel ``angle`` (deg) naming θ; several profiles of one part share one cloud and are told
apart by the channel ``profile`` (or by distinct ``angle`` values). A text file with x, z columns reads
this way (core.io.text; ``input: {profile_angle_deg: 30}``); a cloud with every y equal (an x, 0, z
file) is a profile along x, every x equal one along y.

What a profile determines of the part's pose (core.profiles.fit): the tilt in its plane, the decentre
along it and the height (and R, k, A_n of the design). Not the decentre across it nor the tilt about
its own line — both change the profile only at second order; they are held at zero (the profile is
taken to pass through the axis) and the reports say so.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import StepError

#: how far points may stray across their line (a fraction of the profile's length) and still be one
ACROSS_TOLERANCE = 0.01
NOT_DETERMINED = ("the decentre across the profile and the tilt about its own line (both change a "
                  "profile only at second order: held at 0, the profile taken through the axis)")


@dataclass(frozen=True)
class Profile:
    """One scan line of a cloud: its rows, azimuth θ (deg, measuring frame), the coordinate s along
    it and a across it (mm), and a label for messages and reports."""

    rows: np.ndarray
    angle_deg: float
    s: np.ndarray
    a: np.ndarray
    label: str

    @property
    def name(self) -> str:
        return f"profile {self.label} at {self.angle_deg:g}°"


def is_profile(cloud) -> bool:
    """True when the cloud holds stylus profiles (an ``angle``/``profile`` channel, or every y equal,
    or every x equal) rather than areal data."""
    return profiles_of(cloud) is not None


def profiles_of(cloud) -> list[Profile] | None:
    """The cloud's profiles, or None for areal data. Raises StepError when a profile's points do not
    lie on one line or a group's angle is not constant."""
    n = cloud.n
    if n == 0:
        return None
    chans = cloud.channels
    x, y = cloud.x, cloud.y
    if "profile" in chans or "angle" in chans:
        key = np.asarray(chans["profile"] if "profile" in chans else chans["angle"], dtype=np.float64)
        values = list(dict.fromkeys(key.tolist()))  # in order of first appearance
        out = []
        for v in values:
            rows = np.flatnonzero(key == v)
            if "angle" in chans:
                ang = np.asarray(chans["angle"])[rows]
                if np.ptp(ang) > 0:
                    raise StepError(f"profile {v:g}: its `angle` channel is not constant ({ang.min():g}° "
                                    f"to {ang.max():g}°); a profile is one straight scan")
                theta = float(ang[0])
            else:
                theta = _direction(x[rows], y[rows])
            label = f"{v:g}" if "profile" in chans else str(len(out) + 1)
            out.append(_profile(rows, theta, x, y, label))
        return out
    if n >= 2 and np.ptp(y) == 0 and np.ptp(x) > 0:
        return [_profile(np.arange(n), 0.0, x, y, "1")]
    if n >= 2 and np.ptp(x) == 0 and np.ptp(y) > 0:
        return [_profile(np.arange(n), 90.0, x, y, "1")]
    return None


def _direction(x, y) -> float:
    """Azimuth (deg, in (−90, 90]) of the principal direction of points in x, y."""
    if len(x) < 2:
        return 0.0
    c = np.cov(np.vstack([x, y]))
    w, v = np.linalg.eigh(c)
    d = v[:, 1]
    t = float(np.degrees(np.arctan2(d[1], d[0])))
    if t <= -90.0:
        t += 180.0
    elif t > 90.0:
        t -= 180.0
    return t


def _profile(rows, theta, x, y, label) -> Profile:
    t = np.radians(theta)
    c, s_ = np.cos(t), np.sin(t)
    xr, yr = x[rows], y[rows]
    s = xr * c + yr * s_
    a = -xr * s_ + yr * c
    p = Profile(rows, float(theta), s, a, label)
    length = np.ptp(s) if len(s) else 0.0
    if len(s) > 1 and np.ptp(a) > ACROSS_TOLERANCE * max(length, 1e-300):
        raise StepError(f"{p.name}: its points leave the line by up to {np.ptp(a):.4g} mm across a "
                        f"{length:.4g} mm scan — not one straight profile (check the `angle` channel)")
    return p


def check_scan(p: Profile, index: np.ndarray | None = None) -> None:
    """A stylus visits each x once, in one direction: one x value repeated and a scan that turns back
    are refused in one line naming the points (``index``: the cloud's input rows)."""
    s = p.s
    if len(s) < 2:
        return
    idx = p.rows if index is None else np.asarray(index)[p.rows]
    d = np.diff(s)
    rep = np.flatnonzero(d == 0)
    if rep.size:
        i = int(rep[0])
        raise StepError(f"{p.name}: x = {s[i]:.9g} mm is repeated (input rows {idx[i]} and "
                        f"{idx[i + 1]}): a profile holds one height per position — remove the duplicate")
    sign = np.sign(d)
    turn = np.flatnonzero(sign[1:] != sign[0])
    if turn.size:
        i = int(turn[0]) + 1
        raise StepError(f"{p.name}: the scan is not monotonic — it turns back at input row {idx[i]} "
                        f"(x {s[i - 1]:.9g} → {s[i]:.9g} → {s[i + 1]:.9g} mm); sort it or split it into "
                        "profiles")


def place(p: Profile, s_new: np.ndarray, a: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """x, y of positions s along the profile's line (a across it, default the profile's own)."""
    t = np.radians(p.angle_deg)
    a = p.a if a is None else a
    return s_new * np.cos(t) - a * np.sin(t), s_new * np.sin(t) + a * np.cos(t)


def with_profile_hint(err: StepError) -> StepError:
    """The areal fit's "all points lie on a line" with the way to read those points as a profile."""
    msg = str(err)
    if msg.startswith("all points lie on a line"):
        return StepError(msg + "; a stylus profile is read as one when it says its azimuth: an `angle` "
                         "channel or the reader option `profile_angle_deg`")
    return err

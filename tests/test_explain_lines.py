"""Vibration lines closer than the record resolves (core/explain/select.py LINE_RESOLUTION_BINS): a
second line is searched for only outside the main lobe around the lines already chosen, so a zone the
scan crosses once is not fitted as a packet of "vibrations" 0.01 Hz apart. Fixed seeds."""
from __future__ import annotations

import numpy as np
import pytest

from pointspro.core.explain import select as S
from pointspro.core.simulate.effects import ScanContext
from tests import test_explain_cases as T


def _ctx(n=6000, fs=200.0):
    t = np.arange(n) / fs
    x = np.cos(t)
    y = np.sin(t)
    zero = np.zeros(n)
    return ScanContext(x, y, zero, zero, zero, t, np.rad2deg(t))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_second_line_is_searched_outside_the_first_ones_main_lobe(seed):
    rng = np.random.default_rng(seed)
    ctx = _ctx()
    T_rec = np.ptp(ctx.t)
    order = np.arange(ctx.t.size)
    f1 = rng.uniform(10, 20)
    near = f1 + 0.8 / T_rec  # inside the lobe: not a tone of its own on this record
    far = f1 + rng.uniform(5, 15)
    r = (3 * np.sin(2 * np.pi * f1 * ctx.t) + 2 * np.sin(2 * np.pi * near * ctx.t + 1.0)
         + 1 * np.sin(2 * np.pi * far * ctx.t + 2.0) + 0.1 * rng.normal(size=ctx.t.size))
    first = S.vibration_group(ctx, r, order)
    assert abs(first.frequency - f1) < 1.0 / T_rec
    second = S.vibration_group(ctx, r, order, [first.frequency])
    assert abs(second.frequency - far) < 0.5 / T_rec, (second.frequency, far)
    # fewer frequencies are searched: the Bonferroni family shrinks by the bins left out
    assert second.n_search < first.n_search


@pytest.mark.parametrize("scan", ["spiral", "outward"])
@pytest.mark.parametrize("seed", [106, 110])
def test_a_zone_crossed_once_is_not_a_packet_of_vibrations(tmp_path, scan, seed):
    """A 4.5–7 nm ring (σ 0.6–1.3 mm) on a spiral: before, straightness and four "vibrations" at
    0.200–0.233 Hz over a 30 s record (their spacing a third of one bin); no two lines within the
    main lobe now."""
    rng = np.random.default_rng(seed)
    r0, w, a = rng.uniform(3, 12), rng.uniform(0.5, 2), rng.uniform(4e-6, 8e-6)
    scans = {"spiral": T.SPIRAL, "outward": T.SPIRAL_OUT}
    rep = T.run(tmp_path, T.STEEP, scans[scan], [], seed=seed,
                extra=lambda x, y, t: a * np.exp(-(np.hypot(x, y) - r0) ** 2 / (2 * w * w)))
    hz = sorted(f["params"]["frequency_hz"] for f in rep["found"] if f["effect"] == "vibration")
    T_rec = 15.0 / T.SPIRAL["pitch"] * 60.0 / T.SPIRAL["rpm"] if scan == "spiral" else \
        15.0 / T.SPIRAL_OUT["pitch"] * 60.0 / T.SPIRAL_OUT["rpm"]
    assert all(b - a >= S.LINE_RESOLUTION_BINS / T_rec * 0.99 for a, b in zip(hz, hz[1:])), hz
    assert rep["verdict"] != "explained"

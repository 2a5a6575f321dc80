"""A vibration line at a whole multiple of the spindle frequency on a constant-speed spiral is judged
again against the spindle's axial harmonic once all effects are in (select._synchronous_lines). An
independent review hid spindle_axial b6 = 4 nm and spindle_tilt a6 = 0.1″ together on an inward 40 rpm
spiral: explain named "vibration 4.0026 Hz" (6 × the 0.667 Hz spindle frequency, detuned by 0.15
cycles over the record) and a tilt of 0.047″ ± 0.0014 (z ≈ −37), with no word of synchrony.
Fixed seeds throughout."""
from __future__ import annotations

import pytest

from .test_explain_cases import names, run  # the cases' simulator and helpers

SPHERE = {"type": "even_asphere", "R": 60.0, "k": 0.0, "aperture": 40.0}
SPIRAL_40 = {"type": "spiral", "radius": 12.0, "rpm": 40.0, "pitch": 0.3, "fs": 200.0}  # 60 s, 0.667 Hz
FS = 40.0 / 60.0
T = 60.0


@pytest.mark.parametrize("seed", [905, 915])
def test_axial_and_tilt_at_6_upr_are_named_not_a_synchronous_vibration(tmp_path, seed):
    hidden = [{"spindle_axial": {"b6": 4e-6}}, {"spindle_tilt": {"a6_arcsec": 0.1}}]
    rep = run(tmp_path, SPHERE, SPIRAL_40, hidden, seed=seed)
    assert sorted(names(rep)) == ["spindle_axial", "spindle_tilt"], (names(rep), rep["ambiguous_with"])
    f = {e["effect"]: e for e in rep["found"]}
    assert f["spindle_axial"]["harmonics"] == [6] and f["spindle_tilt"]["harmonics"] == [6]
    for eff, key, true in [("spindle_axial", "b6", 4e-6), ("spindle_tilt", "a6_arcsec", 0.1)]:
        est, u = f[eff]["params"][key], f[eff]["uncertainty"][key]
        assert abs(est - true) < 4 * u, (eff, est, u)
    # the synchronous vibration the scan cannot tell from the axial harmonic is reported
    assert any(set(a["effects"]) == {"spindle_axial", "vibration"} for a in rep["ambiguous_with"])


@pytest.mark.parametrize("freq", [23.3, 4.2 * FS])
def test_a_vibration_off_the_spindle_harmonics_stays_a_vibration(tmp_path, freq):
    hidden = [{"vibration": {"frequency_hz": freq, "amplitude": 4e-6, "phase_deg": 30.0}}]
    rep = run(tmp_path, SPHERE, SPIRAL_40, hidden, seed=941)
    assert names(rep) == ["vibration"] and rep["verdict"] == "explained", rep["ambiguous_with"]
    assert rep["found"][0]["params"]["frequency_hz"] == pytest.approx(freq, abs=0.01)


def test_a_vibration_kept_near_a_spindle_harmonic_is_reported_synchronous(tmp_path):
    """A line 0.2 cycles over the record off 6 × the spindle frequency, strong enough that a steady
    axial harmonic fits far worse: a vibration, and its synchrony said."""
    freq = 6 * FS + 0.2 / T
    hidden = [{"vibration": {"frequency_hz": freq, "amplitude": 15e-6, "phase_deg": 30.0}}]
    rep = run(tmp_path, SPHERE, SPIRAL_40, hidden, seed=941)
    assert names(rep) == ["vibration"]
    amb = [a for a in rep["ambiguous_with"] if set(a["effects"]) == {"vibration", "spindle_axial"}]
    assert amb and "6 × the spindle frequency" in amb[0]["why"] and "spindle speed" in amb[0]["separate_by"]

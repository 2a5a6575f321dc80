"""The window's Report panel states the shop's answer (issue 23): the verdict banner and each figure
as value ± U95 after a recipe with `uncertainty:` and `tolerance:` blocks."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")


def test_report_panel_shows_the_verdict_banner_and_figures_with_uncertainty(qtbot):
    from pointspro.app.report_panel import ReportPanel
    from pointspro.core import api as pp
    from pointspro.core.cloud import PointCloud

    rng = np.random.default_rng(3)
    x, y = (a.ravel() for a in np.meshgrid(np.linspace(-20, 20, 41), np.linspace(-20, 20, 41)))
    keep = np.hypot(x, y) <= 20
    x, y = x[keep], y[keep]
    rho2 = (x * x + y * y) / 400.0
    z = 2e-4 * (6 * rho2 * rho2 - 6 * rho2 + 1) + rng.normal(0, 2e-5, x.size)  # spherical, 20 nm noise
    res = pp.run({"pointspro": 1, "steps": [], "uncertainty": {"samples": 50, "seed": 1},
                  "tolerance": {"rms_um": 0.01}}, PointCloud(np.column_stack([x, y, z])))
    s = res.summary
    assert s["tolerance"]["verdict"] == "does not conform"  # RMS ≈ 0.2 µm against 0.01 µm
    panel = ReportPanel()
    qtbot.addWidget(panel)
    panel.set_result(res._run)
    page = panel.html_for(0)
    assert "DOES NOT CONFORM" in page and "#b3261e" in page
    assert "± " in page and "(k = " in page
    assert "Uncertainty (Monte Carlo" in page

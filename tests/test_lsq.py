"""core/geometry/lsq.py: when Levenberg–Marquardt says it has converged."""
from __future__ import annotations

import numpy as np

from pointspro.core.geometry.lsq import RMS_FLOOR_MM, levenberg_marquardt


def _halving(x, want_jacobian=True):
    """A residual that each Gauss–Newton step halves, never reaching zero: r = (x, x) with a Jacobian
    twice the true one, so each step goes half way. Cost falls by 3/4 a step (never "small gain"),
    the step is half of x (never "small step" near 0): only the residual's size can stop it."""
    r = np.array([x[0], x[0]])
    return r, np.array([[2.0], [2.0]])


def test_a_residual_below_a_femtometre_is_converged():
    """A review: noise-free points whose cost sat at rounding, each step still lowering it by more than
    ftol·cost, were refused as "did not converge" after 100 iterations."""
    res = levenberg_marquardt(_halving, [1e-6])
    assert res.converged and res.iterations < 40
    assert np.sqrt(res.cost / 2) <= RMS_FLOOR_MM
    res = levenberg_marquardt(_halving, [1.0], max_iter=100)  # from 1 mm: ~40 halvings to 1e-12
    assert res.converged and res.iterations < 60

"""core.parallel.interrupts_deferred: a Ctrl-C or SIGTERM inside takes effect as the block closes —
scipy's threaded cKDTree queries were interrupted mid-join, and their threads read freed arrays (a
sequential batch interrupted at the wrong moment ended in a segmentation fault, a review)."""
import os
import signal
import sys

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pointspro.core.parallel import interrupts_deferred, threaded_query

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals sent with os.kill")


def test_a_ctrl_c_inside_is_raised_as_the_block_closes_and_the_handler_restored():
    before = signal.getsignal(signal.SIGINT)
    reached_the_end = False
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # bytecodes run: Python's handler would have raised here
                pass
            reached_the_end = True
    assert reached_the_end
    assert signal.getsignal(signal.SIGINT) is before


def test_a_handler_of_ones_own_runs_once_at_the_end():
    seen = []
    before = signal.signal(signal.SIGTERM, lambda s, f: seen.append(s))
    try:
        with interrupts_deferred():
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):
                pass
            assert seen == []
        assert seen == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, before)


def test_no_signal_no_change_and_the_query_answers_as_scipy():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, (5000, 2))
    tree = cKDTree(pts)
    d1, i1 = threaded_query(tree, pts, k=4, workers=2)
    d2, i2 = tree.query(pts, k=4, workers=2)
    assert np.array_equal(i1, i2) and np.array_equal(d1, d2)

"""`quiet` (core/io/instruments.py) silences the process's stdout, stderr and warnings while a file
is read; blocks that overlap in two threads and end out of order must leave all three as found
(contextlib.redirect_stdout restores what it saw, so the first thread out restored the terminal and
the last one a StringIO: every later print went nowhere — a review)."""
import sys
import threading
import warnings

from pointspro.core.io.instruments import quiet


def _overlap(first_out: str, terminal):
    """Thread A enters, then B; ``first_out`` leaves first."""
    entered = {k: threading.Event() for k in "AB"}
    leave = {k: threading.Event() for k in "AB"}
    left = {k: threading.Event() for k in "AB"}
    seen = {}

    def body(name):
        with quiet():
            seen[name] = sys.stdout
            entered[name].set()
            leave[name].wait(10)
        left[name].set()

    a = threading.Thread(target=body, args=("A",))
    b = threading.Thread(target=body, args=("B",))
    a.start()
    entered["A"].wait(10)
    b.start()
    entered["B"].wait(10)
    second_out = "B" if first_out == "A" else "A"
    leave[first_out].set()
    left[first_out].wait(10)
    assert sys.stdout is not terminal, "silenced while the other block is still open"
    leave[second_out].set()
    a.join(10)
    b.join(10)
    return seen


def test_overlapping_blocks_in_two_threads_restore_the_terminal_in_either_order():
    for first_out in "AB":
        out, err = sys.stdout, sys.stderr
        filters = list(warnings.filters)
        seen = _overlap(first_out, out)
        assert seen["A"] is not out and seen["B"] is not out  # silenced inside
        assert sys.stdout is out and sys.stderr is err, first_out
        assert list(warnings.filters) == filters, first_out


def test_nested_blocks_in_one_thread_restore_on_the_outer_exit():
    out = sys.stdout
    with quiet():
        inner_seen = None
        with quiet():
            inner_seen = sys.stdout
            print("not shown")
        assert inner_seen is not out and sys.stdout is not out  # still silenced: the outer block is open
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warnings.warn("inside a user's own catch")
        assert caught
    assert sys.stdout is out

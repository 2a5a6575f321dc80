"""core/events.py: named events, connect/disconnect, a failing listener logged and not fatal."""
from __future__ import annotations

import gc
import logging

import pytest

from pointspro.core.events import EmitterGroup, Event, EventEmitter


def test_emit_reaches_listeners_in_connection_order_once_each():
    em = EventEmitter(source="model", type="ran")
    got = []
    first = em.connect(lambda e: got.append(("first", e)))
    em.connect(lambda e: got.append(("second", e.value)))
    em.connect(first)  # again: still once
    ev = em(value=42)
    assert ev == Event("ran", "model", 42)
    assert got == [("first", ev), ("second", 42)]


def test_disconnect_one_or_all_and_unknown_is_quiet():
    em = EventEmitter(type="x")
    got = []

    def a(e):
        got.append("a")

    def b(e):
        got.append("b")
    em.connect(a)
    em.connect(b)
    em.disconnect(a)
    em.disconnect(a)  # not connected any more: nothing happens
    em()
    assert got == ["b"]
    em.disconnect()
    em()
    assert got == ["b"] and em.callbacks == []


def test_a_failing_listener_is_logged_and_the_others_still_run(caplog):
    em = EventEmitter(type="steps")
    got = []

    def broken(e):
        raise ZeroDivisionError("division by zero")
    em.connect(broken)
    em.connect(got.append)
    with caplog.at_level(logging.ERROR, logger="pointspro.core.events"):
        ev = em("v")
    assert got == [ev]
    rec = [r for r in caplog.records if r.name == "pointspro.core.events"]
    assert len(rec) == 1 and "steps" in rec[0].getMessage() and rec[0].exc_info[0] is ZeroDivisionError


def test_bound_methods_are_held_weakly():
    em = EventEmitter(type="opened")

    class View:
        def __init__(self):
            self.seen = []

        def on(self, e):
            self.seen.append(e.type)
    v = View()
    em.connect(v.on)
    em()
    assert v.seen == ["opened"]
    em.disconnect(v.on)
    em.connect(v.on)
    del v
    gc.collect()
    em()  # the dead listener is dropped, not called
    assert em.callbacks == []


def test_blocked_emits_nothing():
    em = EventEmitter(type="x")
    got = []
    em.connect(got.append)
    with em.blocked():
        em()
    em()
    assert len(got) == 1


def test_group_names_attributes_and_listening_to_all():
    g = EmitterGroup("src", "opened", "ran")
    one, every = [], []
    g.ran.connect(one.append)
    g.connect(every.append)
    g.opened()
    g.ran(value=1)
    assert [e.type for e in every] == ["opened", "ran"] and [e.value for e in one] == [1]
    assert all(e.source == "src" for e in every)
    assert g.names == ["opened", "ran"] and g["ran"] is g.ran
    g.disconnect(every.append)
    g.opened()
    assert len(every) == 2
    with g.blocked():
        g.ran()
    assert len(one) == 1


def test_group_rejects_unknown_and_bad_names():
    g = EmitterGroup(None, "opened")
    with pytest.raises(AttributeError, match="no event 'opend'.*opened"):
        g.opend.connect(print)
    for bad in ("opened", "connect", "not a name", "_private"):
        with pytest.raises(ValueError):
            g.add(bad)
    with pytest.raises(TypeError):
        g.opened.connect(42)

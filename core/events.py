"""Named events for Qt-free models (napari's ``EventEmitter``/``EmitterGroup`` is the model).

A model declares its events once::

    self.events = EmitterGroup(self, "opened", "steps", "ran")
    self.events.ran(value=result)              # emit: every listener gets Event("ran", self, result)

and a view subscribes to one event or to all of them::

    session.events.ran.connect(view.on_ran)    # one
    session.events.connect(window.on_any)      # every event of the group (event.type says which)
    session.events.ran.disconnect(view.on_ran)

Listeners are called in the order they connected, each once however often it connects. A listener
that raises is logged (logger ``pointspro.core.events``, with its traceback) and skipped: the model's
change has already happened, and the next listener still hears of it — one broken view must not
leave the others showing a stale model. Bound methods are held weakly (as napari does): a closed
window that forgot to disconnect is not kept alive by the model, and is dropped from its listeners.
Naming an event the group does not declare is an AttributeError, so a typo fails at once.
"""
from __future__ import annotations

import logging
import weakref
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterator

log = logging.getLogger(__name__)

Callback = Callable[["Event"], Any]


@dataclass(frozen=True)
class Event:
    """What a listener receives: the event's name, the object that emitted it, and a value."""

    type: str
    source: Any = None
    value: Any = None


def _ref(callback: Callback):
    """A weak reference for a bound method, the callable itself otherwise (see the module doc)."""
    if getattr(callback, "__self__", None) is not None and getattr(callback, "__func__", None) is not None:
        return weakref.WeakMethod(callback)
    return callback


def _deref(ref) -> Callback | None:
    return ref() if isinstance(ref, weakref.WeakMethod) else ref


class EventEmitter:
    """One named event: ``connect``, ``disconnect``, and calling it emits."""

    def __init__(self, source: Any = None, type: str = "event"):  # noqa: A002 - napari's name
        self.source = source
        self.type = type
        self._refs: list = []
        self._blocked = 0

    # -- listeners ----------------------------------------------------------------------------------
    @property
    def callbacks(self) -> list[Callback]:
        """The live listeners, in connection order."""
        return [c for c in (_deref(r) for r in self._refs) if c is not None]

    def connect(self, callback: Callback) -> Callback:
        """Add a listener (once; connecting it again changes nothing). Returns it: usable as a
        decorator."""
        if not callable(callback):
            raise TypeError(f"{callback!r} is not callable")
        if callback not in self.callbacks:
            self._refs.append(_ref(callback))
        return callback

    def disconnect(self, callback: Callback | None = None) -> None:
        """Remove a listener (no error when it was not connected); all of them when None."""
        if callback is None:
            self._refs.clear()
            return
        self._refs = [r for r in self._refs if _deref(r) is not None and _deref(r) != callback]

    # -- emitting -----------------------------------------------------------------------------------
    def __call__(self, value: Any = None) -> Event:
        """Emit: each listener gets the Event; a failing listener is logged, the others still run."""
        event = Event(self.type, self.source, value)
        if self._blocked:
            return event
        dead = False
        for r in list(self._refs):
            cb = _deref(r)
            if cb is None:
                dead = True
                continue
            try:
                cb(event)
            except Exception:  # noqa: BLE001 - a broken listener must not break the model or the others
                log.exception("listener %r of event %r failed", cb, self.type)
        if dead:
            self._refs = [r for r in self._refs if _deref(r) is not None]
        return event

    emit = __call__

    @contextmanager
    def blocked(self) -> Iterator[None]:
        """Emit nothing inside the block (nested blocks allowed)."""
        self._blocked += 1
        try:
            yield
        finally:
            self._blocked -= 1

    def __repr__(self) -> str:
        return f"<EventEmitter {self.type!r}: {len(self._refs)} listener(s)>"


class EmitterGroup:
    """A model's events, one EventEmitter per name (attributes), plus listeners of every event."""

    def __init__(self, source: Any = None, *names: str):
        self.source = source
        self._emitters: dict[str, EventEmitter] = {}
        for name in names:
            self.add(name)

    def add(self, name: str) -> EventEmitter:
        if not name.isidentifier() or name.startswith("_") or hasattr(type(self), name):
            raise ValueError(f"{name!r} cannot name an event")
        if name in self._emitters:
            raise ValueError(f"event {name!r} is declared twice")
        em = self._emitters[name] = EventEmitter(self.source, name)
        return em

    def __getattr__(self, name: str) -> EventEmitter:
        emitters = self.__dict__.get("_emitters", {})
        if name in emitters:
            return emitters[name]
        raise AttributeError(f"no event {name!r} (events: {', '.join(emitters) or 'none'})")

    def __getitem__(self, name: str) -> EventEmitter:
        return getattr(self, name)

    @property
    def names(self) -> list[str]:
        return list(self._emitters)

    def __iter__(self):
        return iter(self._emitters.values())

    def connect(self, callback: Callback) -> Callback:
        """Listen to every event of the group (``event.type`` tells which)."""
        for em in self._emitters.values():
            em.connect(callback)
        return callback

    def disconnect(self, callback: Callback | None = None) -> None:
        """Stop listening to every event (all listeners of every event when None)."""
        for em in self._emitters.values():
            em.disconnect(callback)

    @contextmanager
    def blocked(self) -> Iterator[None]:
        """Emit none of the group's events inside the block."""
        emitters = list(self._emitters.values())
        for em in emitters:
            em._blocked += 1
        try:
            yield
        finally:
            for em in emitters:
                em._blocked -= 1

    def __repr__(self) -> str:
        return f"<EmitterGroup {', '.join(self._emitters)}>"

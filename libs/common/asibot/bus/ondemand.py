"""A subscription held only while someone asks for what it brings.

A camera picture nobody receives is not rendered (the sim skips it: most of its CPU), so a
service that needs pictures only now and then (the web while a page watches, perception when
asked to find an object) subscribes at the first ask and lets go once nobody has asked for
`linger_s`. The first ask after a quiet time waits, at most FIRST_S, for what it needs to come.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

from asibot.bus.base import Bus, Closable

#: The subscription stays this long after the last ask: asks that come again sooner (the web's
#: 3D view asks for its cameras every 5 s, its points three times a second) keep it, s.
LINGER_S = 10.0
#: How long the first ask after a quiet time waits for the first messages: the sim renders at
#: 10 Hz from the tick after it sees the subscriber, a real camera at its own rate, s.
FIRST_S = 1.0


class OnDemand:
    """The subscription that `declare()` makes on `bus`, declared at the first `want()` and
    undeclared `linger_s` after the last.

    >>> pictures = OnDemand(bus, lambda: bus.subscribe_raw(key, keep_newest))
    >>> pictures.want(lambda: newest is not None)     # subscribed; the first picture has come
    """

    def __init__(self, bus: Bus, declare: Callable[[], Closable], *, linger_s: float = LINGER_S,
                 name: str = "on-demand") -> None:
        self._bus, self._declare, self.linger_s = bus, declare, linger_s
        self._lock = threading.Lock()
        self._sub: Closable | None = None
        self._since = self._asked = 0.0
        self._closed = threading.Event()
        threading.Thread(target=self._let_go_when_idle, name=name, daemon=True).start()

    def want(self, ready: Callable[[], object] = lambda: True) -> None:
        """Subscribe now if not yet; within FIRST_S of subscribing, wait until `ready()` (what
        the caller needs has come) or FIRST_S has passed."""
        with self._lock:
            if self._closed.is_set():
                return
            now = time.monotonic()
            self._asked = now
            if self._sub is None:
                self._sub = self._declare()
                self._since = now
            deadline = self._since + FIRST_S
        # Polled: only the first ask after a quiet time waits, for a few frames at most.
        while not ready() and time.monotonic() < deadline:
            time.sleep(0.01)

    def _let_go_when_idle(self) -> None:
        while not self._closed.wait(min(1.0, self.linger_s / 4)):
            with self._lock:
                idle = self._sub is not None and time.monotonic() - self._asked > self.linger_s
                sub, self._sub = (self._sub, None) if idle else (None, self._sub)
            if sub is not None:
                self._bus.undeclare(sub)

    def close(self) -> None:
        self._closed.set()
        with self._lock:
            sub, self._sub = self._sub, None
        if sub is not None:
            self._bus.undeclare(sub)

"""The in-process backend of the bus: `Bus(name, "mem://NAME")`, like python-can's virtual bus.

Every bus opened on the same `mem://NAME` in one process shares one `Network`, with Zenoh's
semantics where services rely on them: key expressions with `*` and `**` on both sides,
per-subscription queues that drop their oldest when full (never wait), queries answered by
every matching queryable with a timeout, liveliness tokens that appear and vanish with their
bus, and latched values. Unit tests of a service run on it with no router and no sockets;
multi-process tests keep the real router.
"""

from __future__ import annotations

import collections
import functools
import itertools
import os
import threading
import time
from typing import Any, Callable

from asibot.bus.base import MEMORY_SCHEME, Answer, Bus, Drain, Prelude

#: The environment variable of the default endpoint (asibot.bus.zenoh_backend.ROUTER_ENV,
#: spelled here too so that this backend does not import zenoh).
ROUTER_ENV = "ASIBOT_ROUTER"

_networks: dict[str, "Network"] = {}
_networks_lock = threading.Lock()
_ids = itertools.count()


@functools.lru_cache(maxsize=4096)
def _meets(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    if not a or not b:
        return all(c == "**" for c in a + b)
    if a[0] == "**":
        return _meets(a[1:], b) or _meets(a, b[1:])
    if b[0] == "**":
        return _meets(a, b[1:]) or _meets(a[1:], b)
    return (a[0] == b[0] or "*" in (a[0], b[0])) and _meets(a[1:], b[1:])


def intersects(a: str, b: str) -> bool:
    """Whether two key expressions share a key: `*` is one chunk, `**` any number of chunks."""
    return _meets(tuple(a.split("/")), tuple(b.split("/")))


class Channel:
    """What a subscription or a server received and has not handled yet: `maxsize` at most.

    `push` never waits, as Zenoh's RingChannel: when full, the oldest item is dropped (and
    `on_drop(item)` told). `pop` waits for an item and raises EOFError once closed and empty."""

    def __init__(self, maxsize: int = 1024, on_drop: Callable[[Any], None] | None = None) -> None:
        self._items: collections.deque = collections.deque()
        self._maxsize = maxsize or 1024
        self._on_drop = on_drop
        self._cond = threading.Condition()
        self._closed = False

    def push(self, item: Any) -> None:
        with self._cond:
            if self._closed:
                return
            oldest = self._items.popleft() if len(self._items) >= self._maxsize else None
            self._items.append(item)
            self._cond.notify()
        if oldest is not None and self._on_drop is not None:
            self._on_drop(oldest)

    def pop(self) -> Any:
        with self._cond:
            while not self._items:
                if self._closed:
                    raise EOFError("channel closed")
                self._cond.wait()
            return self._items.popleft()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()


class _Query:
    """One query in flight: answers arrive from queryable threads, the caller waits for all."""

    def __init__(self, key: str, payload: bytes, expected: int) -> None:
        self.key, self.payload = key, payload
        self.answers: list[tuple[str, bytes] | None] = []
        self._pending = expected
        self._cond = threading.Condition()

    def finish(self, answer: tuple[str, bytes] | None, answered: bool) -> None:
        with self._cond:
            if answered:
                self.answers.append(answer)
            self._pending -= 1
            self._cond.notify_all()

    def wait(self, timeout: float) -> list[tuple[str, bytes] | None]:
        with self._cond:
            self._cond.wait_for(lambda: self._pending <= 0, timeout)
            return list(self.answers)


class Network:
    """Everything declared on one `mem://NAME`: subscribers, queryables, tokens, watchers."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.subscribers: dict[int, tuple[str, Channel]] = {}
        self.queryables: dict[int, tuple[str, Channel]] = {}
        self.tokens: dict[int, str] = {}
        self.watchers: dict[int, tuple[str, Channel]] = {}

    def put(self, key: str, payload: bytes) -> None:
        with self.lock:
            targets = [ch for expr, ch in self.subscribers.values() if intersects(expr, key)]
        for ch in targets:
            ch.push((key, payload))

    def query(self, key: str, payload: bytes, timeout: float) -> list[tuple[str, bytes] | None]:
        with self.lock:
            targets = [ch for expr, ch in self.queryables.values() if intersects(expr, key)]
        query = _Query(key, payload, len(targets))
        for ch in targets:
            ch.push(query)
        return query.wait(timeout) if targets else []

    def set_token(self, ident: int, key: str | None) -> None:
        with self.lock:
            if key is None:
                key = self.tokens.pop(ident, None)
                alive = False
            else:
                self.tokens[ident] = key
                alive = True
            watchers = [ch for expr, ch in self.watchers.values() if key and intersects(expr, key)]
        for ch in watchers:
            ch.push((key, alive))


def network(name: str) -> Network:
    with _networks_lock:
        return _networks.setdefault(name, Network())


class _Declared:
    """Removes one declaration from its network's table when closed."""

    def __init__(self, table: dict, ident: int, channel: Channel, lock: threading.Lock) -> None:
        self._table, self._ident, self._channel, self._lock = table, ident, channel, lock

    def close(self) -> None:
        with self._lock:
            self._table.pop(self._ident, None)
        self._channel.close()


class _Publisher:
    def __init__(self, net: Network, key: str) -> None:
        self._net, self._key = net, key

    def put(self, payload: bytes | bytearray) -> None:
        self._net.put(self._key, bytes(payload))

    def matching(self) -> bool:
        with self._net.lock:
            return any(intersects(expr, self._key) for expr, _ in self._net.subscribers.values())

    def close(self) -> None:
        pass


class _Token:
    def __init__(self, net: Network, key: str) -> None:
        self._net, self._ident = net, next(_ids)
        net.set_token(self._ident, key)

    def close(self) -> None:
        self._net.set_token(self._ident, None)


class MemoryBus(Bus):
    """The bus inside one process: `Bus("test", "mem://NAME")`. Same semantics, no router."""

    def __init__(self, name: str, endpoint: str | None = None, *, wait: float | None = None,
                 stop: threading.Event | None = None) -> None:
        if endpoint is None:  # as the factory chose: $ASIBOT_ROUTER (testing.memory_bus sets it)
            endpoint = os.environ.get(ROUTER_ENV, "")
            if not endpoint.startswith(MEMORY_SCHEME):
                endpoint = MEMORY_SCHEME + "default"
        if not endpoint.startswith(MEMORY_SCHEME) or not endpoint[len(MEMORY_SCHEME):]:
            raise ValueError(f"a memory bus endpoint looks like mem://NAME, not {endpoint!r}")
        self._open(name, endpoint)
        self.network = network(endpoint[len(MEMORY_SCHEME):])

    def _declare(self, table: dict, key: str, channel: Channel) -> _Declared:
        ident = next(_ids)
        with self.network.lock:
            table[ident] = (key, channel)
        return _Declared(table, ident, channel, self.network.lock)

    def _declare_publisher(self, key: str, express: bool, block: bool) -> _Publisher:
        return _Publisher(self.network, key)

    def _declare_subscriber(self, key: str, deliver: Callable[[str, bytes], None], maxsize: int,
                            prelude: Prelude | None = None) -> Drain:
        channel = Channel(maxsize)
        declared = self._declare(self.network.subscribers, key, channel)
        return Drain(f"{self.name}-sub", channel.pop, lambda item: deliver(*item), declared.close,
                     prelude=prelude)

    def _declare_queryable(self, key: str, answer: Answer, workers: int) -> Drain:
        # A query dropped unanswered (256 waiting) is finished at once, as Zenoh finalises a
        # dropped query: its caller hears "no answer" rather than waiting for its whole timeout.
        channel = Channel(256, lambda query: query.finish(None, False))

        def run(query: _Query) -> None:
            result, answered = None, False
            try:
                result = answer(query.key, query.payload)
                answered = result is not None
            finally:
                query.finish(result, answered)  # finalise, whatever happened

        declared = self._declare(self.network.queryables, key, channel)
        return Drain(f"{self.name}-rpc", channel.pop, run, declared.close, workers)

    def _get(self, key: str, payload: bytes, timeout: float) -> list[tuple[str, bytes] | None]:
        return self.network.query(key, payload, timeout)

    def _put(self, key: str, payload: bytes) -> None:
        self.network.put(key, bytes(payload))

    def _wait_for_queryable(self, key: str, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while True:
            with self.network.lock:
                if any(intersects(expr, key) for expr, _ in self.network.queryables.values()):
                    return True
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)

    def _declare_token(self, key: str) -> _Token:
        return _Token(self.network, key)

    def _watch_tokens(self, pattern: str, on_change: Callable[[str, bool], None]) -> Drain:
        channel = Channel(1 << 16)
        with self.network.lock:  # history first, then changes: no token slips between
            for key in self.network.tokens.values():
                if intersects(pattern, key):
                    channel.push((key, True))
            ident = next(_ids)
            self.network.watchers[ident] = (pattern, channel)
        declared = _Declared(self.network.watchers, ident, channel, self.network.lock)
        return Drain(f"{self.name}-watch", channel.pop, lambda item: on_change(*item), declared.close)

    def _tokens(self, pattern: str, timeout: float) -> list[str]:
        with self.network.lock:
            return [key for key in self.network.tokens.values() if intersects(pattern, key)]

    def _close_transport(self) -> None:
        pass

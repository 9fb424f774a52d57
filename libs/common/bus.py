"""The bus: the only module that talks to Zenoh.

Why a wrapper at all: zenoh-python forbids blocking in its callbacks and needs every Query
finalised, and every service needs the same client configuration (one router, no multicast,
retry until the router exists). Doing that once here keeps services free of Zenoh details.
Callbacks given to this module run on worker threads owned by the bus, never on Zenoh's.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from typing import Any, Callable, Generic, TypeVar

import zenoh

from asibot import messages
from asibot.errors import MessageError, RpcError, Timeout, Unavailable

log = logging.getLogger("asibot.bus")

ROUTER_ENV = "ASIBOT_ROUTER"
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
#: Threads answering one RPC key: a slow request (a `wait`) leaves the others free.
RPC_WORKERS = 3

M = TypeVar("M")


def router_endpoint(explicit: str | None = None) -> str:
    """The router endpoint: an explicit value, else $ASIBOT_ROUTER, else the loopback default."""
    return explicit or os.environ.get(ROUTER_ENV) or DEFAULT_ROUTER


def _base_config(mode: str) -> zenoh.Config:
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    # Loopback-only machines and predictable deployments: never scout by multicast.
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("scouting/gossip/enabled", "false")
    return cfg


def client_config(endpoint: str, connect_timeout_ms: int = 1000) -> zenoh.Config:
    cfg = _base_config("client")
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    # Explicit, because 1.10.2 clients still fail at once by default (reference/middleware.md).
    cfg.insert_json5("connect/timeout_ms", json.dumps(connect_timeout_ms))
    cfg.insert_json5("connect/exit_on_failure", "true")
    return cfg


def router_config(endpoint: str) -> zenoh.Config:
    cfg = _base_config("router")
    cfg.insert_json5("listen/endpoints", json.dumps([endpoint]))
    return cfg


def open_client(endpoint: str, *, wait: float | None = None,
                stop: threading.Event | None = None) -> zenoh.Session:
    """Open a client session, retrying every second until the router answers.

    Retrying in Python (instead of Zenoh's endless connect) keeps the process responsive
    to SIGTERM while it waits. `wait=None` waits forever; `stop` aborts the wait.
    """
    deadline = None if wait is None else time.monotonic() + wait
    announced = False
    while True:
        try:
            return zenoh.open(client_config(endpoint))
        except zenoh.ZError as exc:
            if deadline is not None and time.monotonic() >= deadline:
                raise Unavailable(
                    f"No Zenoh router answers at {endpoint}. Start it with `asibot router` "
                    f"or `asibot up`, or set {ROUTER_ENV}."
                ) from exc
            if not announced:
                log.warning("waiting for the router at %s ...", endpoint)
                announced = True
            if stop is not None and stop.wait(0.5):
                raise Unavailable("stopped while waiting for the router") from exc
            if stop is None:
                time.sleep(0.5)


def _worker(name: str, target: Callable[[], None]) -> threading.Thread:
    t = threading.Thread(target=target, name=name, daemon=True)
    t.start()
    return t


class Publisher(Generic[M]):
    """Typed publisher: put() refuses anything that is not a `msg_type`."""

    def __init__(self, pub: zenoh.Publisher, key: str, msg_type: type[M]) -> None:
        self._pub = pub
        self.key = key
        self.msg_type = msg_type

    def put(self, msg: M) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"{self.key} carries {self.msg_type.__name__}, not {type(msg).__name__}")
        self._pub.put(messages.encode(msg))

    def put_raw(self, payload: bytes) -> None:
        """Publish already-encoded bytes (replay)."""
        self._pub.put(payload)

    def wait_for_subscribers(self, timeout: float = 5.0) -> bool:
        """Wait until at least one subscriber matches this key; True if one does in time."""
        deadline = time.monotonic() + timeout
        while not self._pub.matching_status.matching:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)
        return True

    def close(self) -> None:
        self._pub.undeclare()


class Subscription:
    """A subscriber (or queryable) drained by its own thread(s).

    Samples wait in a Zenoh channel (a Rust-side queue), and Python threads pull them: this
    avoids a Python callback on Zenoh's thread per sample (twice the throughput, one thread
    hand-off less for RPC) and keeps user code off Zenoh's threads, as zenoh-python requires.
    Several `workers` may pull from one channel, so one slow request does not hold up the next.
    """

    def __init__(self, name: str, declared: Any, handle: Callable[[Any], None],
                 prelude: Callable[[], list] | None = None, workers: int = 1) -> None:
        self._handle = handle
        self._declared = declared
        # Receive from the handler, not the subscriber: a blocked `Subscriber.recv()` holds a
        # borrow that makes `undeclare()` fail, while undeclaring closes the handler's channel
        # and wakes a blocked `handler.recv()` at once, so close() is immediate.
        self._channel = declared.handler
        self._prelude = prelude
        self._threads = [_worker(name, lambda first=(i == 0): self._run(first)) for i in range(workers)]

    def _run(self, first: bool) -> None:
        if first and self._prelude is not None:
            for item in self._prelude():
                self._call(item)
        while True:
            try:
                item = self._channel.recv()
            except Exception:  # undeclared or session closed: the channel is finished
                return
            self._call(item)  # after close() this drains what already arrived, then ends

    def _call(self, item: Any) -> None:
        try:
            self._handle(item)
        except Exception:  # a bad callback must not kill the subscription
            log.exception("callback failed")

    def close(self) -> None:
        try:
            self._declared.undeclare()
        except Exception:
            pass
        for t in self._threads:
            if threading.current_thread() is not t:
                t.join(1.0)


class Bus:
    """One service's connection to the router, with typed helpers.

    >>> bus = Bus("kinematics")
    >>> bus.subscribe(keys.arm_state("asibot-sim"), ArmState, on_state)
    """

    def __init__(self, name: str, router: str | None = None, *, wait: float | None = None,
                 stop: threading.Event | None = None) -> None:
        self.name = name
        self.endpoint = router_endpoint(router)
        self.session = open_client(self.endpoint, wait=wait, stop=stop)
        self.rejected = 0
        self._last_reject_log = 0.0
        self._closables: list[Any] = []
        self._lock = threading.Lock()
        self._latched: dict[str, bytes] = {}
        self._closed = False

    # ------------------------------------------------------------ bookkeeping
    def _keep(self, obj: Any) -> Any:
        with self._lock:
            self._closables.append(obj)
        return obj

    def reject(self, key: str, error: Exception) -> None:
        """Count and log (at most once a second) a message that failed validation."""
        with self._lock:
            self.rejected += 1
            now = time.monotonic()
            loud = now - self._last_reject_log > 1.0
            if loud:
                self._last_reject_log = now
        if loud:
            log.warning("rejected a message on %s: %s (%d rejected so far)", key, error, self.rejected)

    # ------------------------------------------------------------ pub/sub
    def publisher(self, key: str, msg_type: type[M], *, express: bool = False,
                  block: bool = False) -> Publisher[M]:
        """`express` skips batching (commands); `block` never drops (recordings, benchmarks)."""
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        pub = self.session.declare_publisher(key, express=express, congestion_control=cc)
        return self._keep(Publisher(pub, key, msg_type))

    def _channel(self, maxsize: int, ring: bool) -> Any:
        size = maxsize or 1024
        return zenoh.handlers.RingChannel(size) if ring else zenoh.handlers.FifoChannel(size)

    def subscribe(self, key: str, msg_type: type[M], callback: Callable[..., None], *,
                  latest: bool = False, with_key: bool = False, maxsize: int = 0,
                  ring: bool = False) -> Subscription:
        """Call `callback(msg)` (or `callback(key, msg)`) on a worker thread for every valid message.

        `latest=True` first asks latching publishers for their current value, so a late
        joiner learns the estop state at once. `ring=True` keeps only the newest `maxsize`
        samples when the callback is slower than the stream (cameras); otherwise a full
        queue pushes back on the sender. Invalid messages are counted, logged, dropped.
        """

        def deliver(k: str, payload: bytes) -> None:
            try:
                msg = messages.decode(msg_type, payload)
            except MessageError as exc:
                self.reject(k, exc)
                return
            callback(k, msg) if with_key else callback(msg)

        def handle(item: Any) -> None:
            if isinstance(item, tuple):
                deliver(*item)
            else:
                deliver(str(item.key_expr), item.payload.to_bytes())

        prelude = (lambda: self._newest_latched(key)) if latest else None
        sub = self.session.declare_subscriber(key, self._channel(maxsize, ring))
        return self._keep(Subscription(f"{self.name}-sub", sub, handle, prelude))

    def _newest_latched(self, key: str) -> list[tuple[str, bytes]]:
        """Current latched values on `key`: per concrete key, the one with the newest stamp
        (two processes may have latched the same key; the later decision wins)."""
        newest: dict[str, tuple[int, bytes]] = {}
        for k, payload in self._get_raw(key, {}, timeout=1.0, allow_empty=True):
            try:
                stamp = int(messages.unpack(payload).get("stamp", 0))
            except Exception:
                stamp = 0
            if k not in newest or stamp > newest[k][0]:
                newest[k] = (stamp, payload)
        return [(k, p) for k, (_, p) in newest.items()]

    def subscribe_raw(self, key: str, callback: Callable[[str, bytes, int], None], *,
                      maxsize: int = 0, ring: bool = False) -> Subscription:
        """Untyped: callback(key, payload, receive_time_ns). For the recorder and tools."""
        sub = self.session.declare_subscriber(key, self._channel(maxsize, ring))
        return self._keep(Subscription(
            f"{self.name}-raw", sub,
            lambda sample: callback(str(sample.key_expr), sample.payload.to_bytes(), time.time_ns())))

    def put_raw(self, key: str, payload: bytes) -> None:
        self.session.put(key, payload)

    def latch(self, key: str, msg: Any) -> None:
        """Publish `msg` and keep answering `subscribe(..., latest=True)` with it."""
        payload = messages.encode(msg)
        with self._lock:
            first = key not in self._latched
            self._latched[key] = payload
        if first:
            def answer(request: dict) -> dict:
                with self._lock:
                    return {"ok": True, "latched": self._latched[key]}
            self._serve_raw(key, answer, latched=True)
        self.session.put(key, payload)

    # ------------------------------------------------------------ RPC
    def serve(self, key: str, handler: Callable[[dict], dict | None]) -> Any:
        """Answer queries on `key` with `handler(request) -> dict` on a worker thread.

        The handler raises RpcError to refuse; any other exception becomes an `internal`
        error reply, so a bug never leaves a caller hanging. Every query is finalised.
        """
        return self._serve_raw(key, handler, latched=False)

    def _serve_raw(self, key: str, handler: Callable[[dict], dict | None], latched: bool) -> Any:
        def run(query: zenoh.Query) -> None:
            try:
                if self._closed:
                    return
                reply = self._answer(query, handler)
                # A concrete key answers in its own name, so a wildcard caller learns who replied.
                query.reply(query.key_expr if "*" in key else key, reply, express=True)
            except Exception:
                log.exception("could not reply on %s", key)
            finally:
                query.drop()  # finalise: otherwise the caller waits for its full timeout

        queryable = self.session.declare_queryable(key, zenoh.handlers.FifoChannel(256))
        return self._keep(Subscription(f"{self.name}-rpc", queryable, run,
                                       workers=1 if latched else RPC_WORKERS))

    def _answer(self, query: zenoh.Query, handler: Callable[[dict], dict | None]) -> bytes:
        try:
            raw = query.payload.to_bytes() if query.payload is not None else b""
            request = messages.unpack(raw) if raw else {}
            if not isinstance(request, dict):
                raise RpcError("bad_request", "The request must be a map of named arguments.")
            result = handler(request)
            if isinstance(result, dict) and "latched" in result:
                return result["latched"]
            body = {"ok": True}
            body.update(result or {})
            return messages.pack(body)
        except RpcError as exc:
            return messages.pack(exc.to_reply())
        except MessageError as exc:
            return messages.pack({"ok": False, "error": "bad_request", "message": str(exc)})
        except Exception as exc:
            log.exception("handler for %s failed", query.key_expr)
            return messages.pack({
                "ok": False, "error": "internal",
                "message": f"{self.name} failed on {query.key_expr}: {type(exc).__name__}: {exc}",
            })

    def _get_raw(self, key: str, request: dict, timeout: float,
                 allow_empty: bool = False) -> list[tuple[str, bytes]]:
        # No consolidation: several latches on one key must all answer so the newest wins.
        replies = self.session.get(key, payload=messages.pack(request), timeout=timeout,
                                   consolidation=zenoh.ConsolidationMode.NONE, express=True)
        out = []
        for reply in replies:
            if reply.ok is not None:
                out.append((str(reply.ok.key_expr), reply.ok.payload.to_bytes()))
            elif not allow_empty:
                out.append(("", b""))
        return out

    def call(self, key: str, request: dict | None = None, timeout: float = 2.0) -> dict:
        """Send one request and return the `ok` reply; raise RpcError on refusal.

        Raises `Unavailable` when nobody serves `key` and `Timeout` when the server is too slow.
        """
        if timeout <= 0:
            raise ValueError("timeout must be positive: a caller always bounds its wait")
        start = time.monotonic()
        replies = self._get_raw(key, request or {}, timeout)
        good = [payload for k, payload in replies if k]
        if not good:
            if replies or time.monotonic() - start >= timeout * 0.95:
                raise Timeout(f"No answer from {key} within {timeout:g} s.")
            raise Unavailable(f"Nobody answers on {key}: is the service running? (`asibot status`)")
        reply = messages.unpack(good[0])
        if not isinstance(reply, dict) or "ok" not in reply:
            raise RpcError("internal", f"The reply from {key} is not a valid RPC reply.")
        if not reply["ok"]:
            raise RpcError(str(reply.get("error", "internal")), str(reply.get("message", "")))
        return reply

    def wait_for(self, key: str, timeout: float = 5.0) -> bool:
        """Wait until some server answers on `key` (declarations take a moment to propagate
        through the router); True if one does within `timeout`."""
        querier = self.session.declare_querier(key)
        try:
            deadline = time.monotonic() + timeout
            while not querier.matching_status.matching:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.005)
            return True
        finally:
            querier.undeclare()

    # ------------------------------------------------------------ liveliness
    def announce(self, key: str) -> Any:
        """Declare a liveliness token; it vanishes when this process dies or closes the bus."""
        return self._keep(self.session.liveliness().declare_token(key))

    def watch(self, pattern: str, on_change: Callable[[str, bool], None]) -> Subscription:
        """Call on_change(key, alive) for tokens matching `pattern`; existing ones first."""
        sub = self.session.liveliness().declare_subscriber(
            pattern, zenoh.handlers.FifoChannel(1024), history=True)
        return self._keep(Subscription(
            f"{self.name}-watch", sub,
            lambda s: on_change(str(s.key_expr), s.kind == zenoh.SampleKind.PUT)))

    def alive(self, pattern: str = "svc/**", timeout: float = 1.0) -> list[str]:
        """A snapshot of the liveliness tokens matching `pattern`, sorted."""
        replies = self.session.liveliness().get(pattern, timeout=timeout)
        return sorted({str(r.ok.key_expr) for r in replies if r.ok is not None})

    # ------------------------------------------------------------ lifetime
    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        with self._lock:
            items, self._closables = self._closables[::-1], []
        for obj in items:
            try:
                if isinstance(obj, (Subscription, Publisher)):
                    obj.close()
                else:
                    obj.undeclare()
            except Exception:
                pass
        try:
            self.session.close()
        except Exception:
            pass

    def __enter__(self) -> "Bus":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_router(endpoint: str | None = None, stop: threading.Event | None = None) -> None:
    """Run a Zenoh router in this process until `stop` is set (or forever)."""
    ep = router_endpoint(endpoint)
    session = zenoh.open(router_config(ep))
    log.info("router listening on %s", ep)
    try:
        (stop or threading.Event()).wait()
    finally:
        session.close()


def open_router(endpoint: str) -> zenoh.Session:
    """Open (and return) an in-process router session, for tests and `asibot up`."""
    return zenoh.open(router_config(endpoint))

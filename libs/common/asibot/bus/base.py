"""The bus interface: typed pub/sub, RPC, latching and presence, whatever carries the bytes.

`Bus` is small and abstract, like python-can's BusABC: the typed part (encoding, validation
and rejection, RPC replies, latching, bookkeeping) is written once here, and a backend only
moves bytes (the `_declare_*` methods). `Bus(name, endpoint)` picks the backend from the
endpoint, so a service never names one: `mem://NAME` is the in-process bus for unit tests,
anything else is a Zenoh router.
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
import weakref
from typing import Any, Callable, Generic, Protocol, TypeVar

from asibot import keys, messages
from asibot.errors import CODES, MessageError, NotAllowed, RpcError, Timeout, Unavailable

log = logging.getLogger("asibot.bus")

M = TypeVar("M")
#: Threads answering one RPC key: a slow request (a `wait`) leaves the others free.
RPC_WORKERS = 3
#: Largest RPC request a server reads; larger ones are refused unread (memory stays flat).
MAX_REQUEST_BYTES = 1 << 20
#: `mem://NAME` selects the in-process backend; everything else is a Zenoh endpoint.
MEMORY_SCHEME = "mem://"

#: What a queryable's answer function gets (the query's key, its payload) and returns:
#: the key to answer in and the reply bytes, or None to give no answer.
Answer = Callable[[str, bytes], "tuple[str, bytes] | None"]
#: Items a subscriber delivers before its first sample (the latched values).
Prelude = Callable[[], "list[tuple[str, bytes]]"]


#: Every bus not closed yet: closed at exit, so a program that forgets close() still ends
#: cleanly. (Otherwise a drain thread inside Zenoh's recv when the interpreter finalises is
#: torn down through Rust frames: "FATAL: exception not rethrown", exit 134.)
_open_buses: "weakref.WeakSet[Bus]" = weakref.WeakSet()


@atexit.register
def _close_forgotten_buses() -> None:
    for bus in list(_open_buses):
        bus.close()


class Closable(Protocol):
    def close(self) -> None: ...


class RawPublisher(Protocol):
    """What a backend declares for `Bus.publisher`: bytes out, and who listens."""

    def put(self, payload: bytes | bytearray) -> None: ...
    def matching(self) -> bool: ...
    def close(self) -> None: ...


class Publisher(Generic[M]):
    """Typed publisher: put() refuses anything that is not a `msg_type`."""

    def __init__(self, raw: RawPublisher, key: str, msg_type: type[M]) -> None:
        self._raw = raw
        self.key = key
        self.msg_type = msg_type

    def put(self, msg: M) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"{self.key} carries {self.msg_type.__name__}, not {type(msg).__name__}")
        self._raw.put(messages.encode(msg))

    def put_raw(self, payload: bytes) -> None:
        """Publish already-encoded bytes (replay)."""
        self._raw.put(payload)

    def matching(self) -> bool:
        """Whether a subscriber matches this key now: a producer may skip work nobody receives."""
        return self._raw.matching()

    def wait_for_subscribers(self, timeout: float = 5.0) -> bool:
        """Wait until at least one subscriber matches this key; True if one does in time."""
        deadline = time.monotonic() + timeout
        while not self.matching():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)
        return True

    def close(self) -> None:
        self._raw.close()


class Bus:
    """One service's connection to the others, with typed helpers.

    >>> bus = Bus("kinematics")                      # the router of $ASIBOT_ROUTER
    >>> bus = Bus("test", "mem://kitchen")           # in this process only
    >>> bus.subscribe(keys.arm_state("asibot-sim"), ArmState, on_state)

    A backend overrides every method under "what a backend provides". Bus is no abc.ABC only
    because `Bus(...)` is the factory too, and a type checker refuses any call of an abstract class.
    """

    # The signature every backend's __init__ takes. Bus itself has no __init__ (backends
    # call `_open`), so that a type checker reads `Bus(...)` from this __new__.
    def __new__(cls, name: str = "", endpoint: str | None = None, *, wait: float | None = None,
                stop: threading.Event | None = None) -> Bus:
        if cls is Bus:  # the factory: choose the backend from the endpoint (python-can's Bus)
            from asibot.bus import memory, zenoh_backend
            endpoint = zenoh_backend.router_endpoint(endpoint)
            cls = memory.MemoryBus if endpoint.startswith(MEMORY_SCHEME) else zenoh_backend.ZenohBus
        return super().__new__(cls)

    def _open(self, name: str, endpoint: str) -> None:
        """What a backend's __init__ calls first, with the endpoint it resolved."""
        self.name = name
        self.endpoint = endpoint
        self.rejected = 0
        self._last_reject_log = 0.0
        self._closables: list[Closable] = []
        self._lock = threading.Lock()
        self._latched: dict[str, bytes] = {}
        self._closed = False
        self._warned: set[str] = set()
        _open_buses.add(self)

    # ------------------------------------------------------------ what a backend provides
    def _declare_publisher(self, key: str, express: bool, block: bool) -> RawPublisher:
        """A publisher of bytes on `key`. `express` skips batching; `block` never drops."""
        raise NotImplementedError

    def _declare_subscriber(self, key: str, deliver: Callable[[str, bytes], None], maxsize: int,
                            prelude: Prelude | None = None) -> Closable:
        """Call deliver(key, payload) on a bus-owned thread, in order, for each sample on `key`,
        after delivering the (key, payload) pairs `prelude()` returns on that same thread.
        At most `maxsize` samples wait; when full, the oldest waiting one is dropped. A slow
        subscription never holds up the sender or the bus's other traffic."""
        raise NotImplementedError

    def _declare_queryable(self, key: str, answer: Answer, workers: int) -> Closable:
        """Answer queries on `key` with `answer(query_key, payload)` on `workers` threads."""
        raise NotImplementedError

    def _get(self, key: str, payload: bytes, timeout: float) -> list[tuple[str, bytes] | None]:
        """Every answer to a query on `key` within `timeout`; None stands for an error answer."""
        raise NotImplementedError

    def _put(self, key: str, payload: bytes) -> None:
        """Publish bytes once, without declaring a publisher."""
        raise NotImplementedError

    def _wait_for_queryable(self, key: str, timeout: float) -> bool:
        """Wait until some queryable matches `key`; False if none does within `timeout`."""
        raise NotImplementedError

    def _declare_token(self, key: str) -> Closable:
        """A liveliness token: it vanishes when closed or when this process dies."""
        raise NotImplementedError

    def _watch_tokens(self, pattern: str, on_change: Callable[[str, bool], None]) -> Closable:
        """on_change(key, alive) on a bus-owned thread; the tokens alive now come first."""
        raise NotImplementedError

    def _tokens(self, pattern: str, timeout: float) -> list[str]:
        """The keys of the liveliness tokens matching `pattern` now."""
        raise NotImplementedError

    def _close_transport(self) -> None:
        """Close the connection itself, after every declaration was closed."""
        raise NotImplementedError

    def refusal(self, message: str, key: str) -> str | None:
        """Why the router would refuse this session `message` on `key`; None when it may.
        Only a router with access control refuses anything (see ZenohBus)."""
        return None

    # ------------------------------------------------------------ bookkeeping
    def _keep(self, obj: Any) -> Any:
        with self._lock:
            if not self._closed:
                self._closables.append(obj)
                return obj
        # Declared while the bus closes (a callback racing close(), such as a latch kept from
        # a subscription): undeclared at once, or it would outlive the bus.
        try:
            obj.close()
        except Exception:
            pass
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
        """`express` skips batching (commands); `block` waits for the network rather than drop
        (recordings, benchmarks). A subscriber too slow for the stream still drops its oldest."""
        self._warn_if_refused(key)
        return self._keep(Publisher(self._declare_publisher(key, express, block), key, msg_type))

    def subscribe(self, key: str, msg_type: type[M], callback: Callable[..., object], *,
                  latest: bool = False, with_key: bool = False, maxsize: int = 0,
                  on_reject: Callable[[str, MessageError], None] | None = None,
                  on_latched: Callable[[list[tuple[str, M]]], None] | None = None) -> Closable:
        """Call `callback(msg)` (or `callback(key, msg)`) on a worker thread for every valid message.

        Invalid messages are counted, logged (once a second) and dropped; `on_reject(key,
        error)` is called too, for services that must answer bad input (a driver sends an
        Event). `latest=True` first delivers the current latched values (`latch`), so a late
        joiner learns the estop state at once. At most `maxsize` (default 1024) messages wait
        for the callback: when it is slower than the stream the oldest waiting one is dropped,
        and nothing else waits for it (not the sender, not the bus's other subscriptions, not
        its calls). `maxsize=1` keeps only the newest (cameras, scans).

        `on_latched(copies)` instead hears every latched copy at once, (key, message) from each
        process that serves one, on the same thread before the first sample: for a follower
        that must not let the newest stamp decide, since a sender chooses its stamp (the
        estop: asibot.safety.estop).
        """

        def deliver(k: str, payload: bytes) -> None:
            try:
                msg = messages.decode(msg_type, payload)
            except MessageError as exc:
                self.reject(k, exc)
                if on_reject is not None:
                    on_reject(k, exc)
                return
            callback(k, msg) if with_key else callback(msg)

        prelude: Prelude | None = (lambda: self._newest_latched(key)) if latest else None
        if on_latched is not None:
            def prelude() -> list[tuple[str, bytes]]:
                on_latched(self._decoded_copies(key, msg_type))
                return []
        return self._keep(self._declare_subscriber(key, deliver, maxsize, prelude))

    def subscribe_raw(self, key: str, callback: Callable[[str, bytes, int], None], *,
                      maxsize: int = 0) -> Closable:
        """Untyped: callback(key, payload, receive_time_ns). For the recorder and tools."""
        return self._keep(self._declare_subscriber(
            key, lambda k, p: callback(k, p, time.time_ns()), maxsize))

    def put_raw(self, key: str, payload: bytes) -> None:
        self._warn_if_refused(key)
        self._put(key, payload)

    def _warn_if_refused(self, key: str) -> None:
        # The router drops refused samples without a word: say it once per key, not per sample.
        why = self.refusal("put", key)
        if why is not None and key not in self._warned:
            self._warned.add(key)
            log.warning("%s", why)

    def latch(self, key: str, msg: Any, *, publish: bool = True) -> None:
        """Publish `msg` and keep answering `subscribe(..., latest=True)` with it.

        The value is served by a queryable of its own on `key` that returns the message
        bytes as they are (not an RPC reply), so a late joiner decodes it like any sample.
        `publish=False` only keeps serving a value someone else published, so that it
        outlives them (the drivers keep the estop state: asibot.safety.estop).
        """
        payload = messages.encode(msg)
        with self._lock:
            first = key not in self._latched
            self._latched[key] = payload
        if first:
            def answer(query_key: str, request: bytes) -> tuple[str, bytes] | None:
                with self._lock:
                    return key, self._latched[key]
            self._keep(self._declare_queryable(key, answer, workers=1))
        if publish:
            self._put(key, payload)

    def _latched_copies(self, key: str) -> list[tuple[str, bytes]]:
        """Every latched value on `key`, as each process that serves one answers."""
        return [answer for answer in self._get(key, b"", timeout=1.0) if answer is not None]

    def _decoded_copies(self, key: str, msg_type: type[M]) -> list[tuple[str, M]]:
        copies = []
        for k, payload in self._latched_copies(key):
            try:
                copies.append((k, messages.decode(msg_type, payload)))
            except MessageError as exc:
                self.reject(k, exc)
        return copies

    def _newest_latched(self, key: str) -> list[tuple[str, bytes]]:
        """Current latched values on `key`: per concrete key, the one with the newest stamp
        (two processes may have latched the same key; the later decision wins)."""
        newest: dict[str, tuple[int, bytes]] = {}
        for k, payload in self._latched_copies(key):
            try:
                stamp = int(messages.unpack(payload).get("stamp", 0))
            except Exception:
                stamp = 0
            if k not in newest or stamp > newest[k][0]:
                newest[k] = (stamp, payload)
        return [(k, p) for k, (_, p) in newest.items()]

    # ------------------------------------------------------------ RPC
    def serve(self, key: str, handler: Callable[[dict], dict | None]) -> Closable:
        """Answer queries on `key` with `handler(request) -> dict` on a worker thread.

        The reply is built here and only here: `{"ok": true, **result}`, or the refusal of
        an RpcError the handler raises. Any other exception becomes an `internal` reply, so
        a bug never leaves a caller hanging. A wildcard `key` answers in the concrete name
        of the query, so a wildcard caller learns who replied.
        """

        def answer(query_key: str, raw: bytes) -> tuple[str, bytes] | None:
            if self._closed:
                return None
            return (query_key if "*" in key else key), self._reply(query_key, raw, handler)

        return self._keep(self._declare_queryable(key, answer, workers=RPC_WORKERS))

    def _reply(self, key: str, raw: bytes, handler: Callable[[dict], dict | None]) -> bytes:
        try:
            if len(raw) > MAX_REQUEST_BYTES:
                raise RpcError("bad_request", f"The request is {len(raw):,} bytes; requests are limited to "
                                              f"{MAX_REQUEST_BYTES:,} bytes.")
            request = messages.unpack(raw) if raw else {}
            if not isinstance(request, dict):
                raise RpcError("bad_request", "The request must be a map of named arguments.")
            result = handler(request) or {}
            if not isinstance(result, dict):
                raise TypeError(f"the handler returned a {type(result).__name__}, not a dict")
            return messages.pack({**result, "ok": True})
        except RpcError as exc:
            return messages.pack(exc.to_reply())
        except MessageError as exc:
            return messages.pack(RpcError("bad_request", str(exc)).to_reply())
        except Exception as exc:
            log.exception("handler for %s failed", key)
            return messages.pack(RpcError(
                "internal", f"{self.name} failed on {key}: {type(exc).__name__}: {exc}").to_reply())

    def call(self, key: str, request: dict | None = None, timeout: float = 2.0) -> dict:
        """Send one request and return the `ok` reply; raise RpcError on refusal.

        Raises `Unavailable` when nobody serves `key` and `Timeout` when the server is too slow.
        """
        if timeout <= 0:
            raise ValueError("timeout must be positive: a caller always bounds its wait")
        why = self.refusal("query", key)
        if why is not None:
            raise NotAllowed(why)   # the router would drop it: "nobody answers" would mislead
        start = time.monotonic()
        answers = self._get(key, messages.pack(request or {}), timeout)
        good = [a[1] for a in answers if a is not None]
        if not good:
            if answers or time.monotonic() - start >= timeout * 0.95:
                raise Timeout(f"No answer from {key} within {timeout:g} s.")
            raise Unavailable(f"Nobody answers on {key}: is the service running? (`asibot status`)")
        try:
            reply = messages.unpack(good[0])
        except MessageError:
            reply = None
        if not isinstance(reply, dict) or "ok" not in reply:
            raise RpcError("internal", f"The reply from {key} is not a valid RPC reply.")
        if not reply["ok"]:
            code = str(reply.get("error", "internal"))
            message = str(reply.get("message", ""))
            if code not in CODES:  # a newer server: keep its sentence, say what we did not know
                code, message = "internal", f"{message} (error code {code!r} from {key})"
            raise RpcError(code, message)
        return reply

    def wait_for(self, key: str, timeout: float = 5.0) -> bool:
        """Wait until some server answers on `key` (declarations take a moment to propagate
        through a router); True if one does within `timeout`."""
        return self._wait_for_queryable(key, timeout)

    # ------------------------------------------------------------ liveliness
    def announce(self, key: str) -> Closable:
        """Declare a liveliness token; it vanishes when this process dies or closes the bus."""
        return self._keep(self._declare_token(key))

    def watch(self, pattern: str, on_change: Callable[[str, bool], None]) -> Closable:
        """Call on_change(key, alive) for tokens matching `pattern`; existing ones first."""
        return self._keep(self._watch_tokens(pattern, on_change))

    def alive(self, pattern: str = keys.ALL_SERVICES, timeout: float = 1.0) -> list[str]:
        """A snapshot of the liveliness tokens matching `pattern`, sorted."""
        return sorted(set(self._tokens(pattern, timeout)))

    # ------------------------------------------------------------ lifetime
    def undeclare(self, obj: Closable) -> None:
        """Close one subscription, publisher or token of this bus now, and forget it: for a
        service that subscribes and unsubscribes as it runs (the web's camera pictures)."""
        with self._lock:
            self._closables = [c for c in self._closables if c is not obj]
        obj.close()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        with self._lock:
            items, self._closables = self._closables[::-1], []
        for obj in items:
            try:
                obj.close()
            except Exception:
                pass
        try:
            self._close_transport()
        except Exception:
            pass

    def __enter__(self) -> "Bus":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _guarded(fn: Callable[..., None], *args: Any) -> None:
    """Run a user callback; a bad callback must not kill the subscription that runs it."""
    try:
        fn(*args)
    except Exception:
        log.exception("callback failed")


def _guarded_list(fn: Callable[[], list]) -> list:
    try:
        return fn()
    except Exception:
        log.exception("could not read the latched values")
        return []


class Drain:
    """Threads that pull items from a channel and hand them to `handle`, until it closes.

    Both backends queue incoming samples and queries and let Python threads pull them,
    so no user code ever runs on a transport's own threads (zenoh-python forbids blocking
    there). Several `workers` may pull from one channel, so one slow request does not hold
    up the next. `recv()` must raise once the channel is closed and drained.
    """

    def __init__(self, name: str, recv: Callable[[], Any], handle: Callable[[Any], None],
                 undeclare: Callable[[], None], workers: int = 1,
                 prelude: Callable[[], list] | None = None) -> None:
        self._recv = recv
        self._handle = handle
        self._undeclare = undeclare
        self._prelude = prelude
        self._name = name
        self._closing = False
        self._threads = []
        for i in range(workers):
            t = threading.Thread(target=self._run, args=(i == 0,), name=name, daemon=True)
            t.start()
            self._threads.append(t)

    def _run(self, first: bool) -> None:
        if first and self._prelude is not None:
            for item in _guarded_list(self._prelude):
                _guarded(self._handle, item)
        recv, handle = self._recv, self._handle
        while True:
            try:
                item = recv()
            except Exception as exc:  # undeclared or session closed: the channel is finished
                if not self._closing:   # nobody closed it: from now on nothing arrives, say so
                    log.warning("%s: its channel ended before close() (%s: %s); nothing more will "
                                "arrive on it", self._name, type(exc).__name__, exc)
                return
            # _guarded, inlined: 80 ns a sample instead of 235 on this machine, 1.5 % of a core at the
            # 100 k samples a second the recorder takes.
            try:
                handle(item)
            except Exception:
                log.exception("callback failed")

    @property
    def running(self) -> bool:
        """Whether a thread still pulls from the channel (diagnostics: it ends only on close)."""
        return any(t.is_alive() for t in self._threads)

    def close(self) -> None:
        self._closing = True
        try:
            self._undeclare()
        except Exception:
            pass
        for t in self._threads:
            if threading.current_thread() is not t:
                t.join(1.0)

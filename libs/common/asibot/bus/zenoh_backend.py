"""The Zenoh backend of the bus: the only module of the stack that talks to Zenoh.

Why a wrapper at all: zenoh-python forbids blocking in its callbacks and needs every Query
finalised, and every service needs the same client configuration (one router, no multicast,
retry until the router exists). Doing that once here keeps services free of Zenoh details.
Samples and queries wait in Zenoh channels (Rust-side queues) that `Drain` threads pull:
no Python callback runs on Zenoh's threads, which also doubles throughput.
"""

from __future__ import annotations

import ctypes
import functools
import json
import logging
import os
import socket
import threading
import time
from pathlib import Path
from typing import Any, Callable

import zenoh

from asibot import access, certificates
from asibot.bus.base import Answer, Bus, Drain, Prelude
from asibot.errors import Unavailable

log = logging.getLogger("asibot.bus")

ROUTER_ENV = "ASIBOT_ROUTER"
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
TLS = "tls/"

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


def client_config(endpoint: str, connect_timeout_ms: int = 1000,
                  login: access.Login | None = None) -> zenoh.Config:
    cfg = _base_config("client")
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    # Explicit, because 1.10.2 clients still fail at once by default (docs/foundation-api.md, Bus).
    cfg.insert_json5("connect/timeout_ms", json.dumps(connect_timeout_ms))
    cfg.insert_json5("connect/exit_on_failure", "true")
    if login is not None:
        cfg.insert_json5("transport/auth/usrpwd",
                         json.dumps({"user": login.user, "password": login.password}))
    if endpoint.startswith(TLS):
        # Only the robot's own CA is trusted, and the router must hold the name dialled.
        cfg.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(trusted_ca())))
        cfg.insert_json5("transport/link/tls/verify_name_on_connect", "true")
    return cfg


def trusted_ca() -> Path:
    """The robot's CA certificate in the credentials folder; a sentence when it is missing."""
    path = access.default_folder() / certificates.CA
    if not path.is_file():
        raise Unavailable(f"A tls/ router needs its CA certificate, and {path} does not exist: copy "
                          f"{certificates.CA} from the robot's credentials folder into {path.parent} "
                          f"(or set {access.ACCESS_ENV} to the folder that has it).")
    return path


def router_config(endpoint: str, credentials: Path | str | None = None,
                  programs: str | None = None) -> zenoh.Config:
    """A router on `endpoint`, and for user programs on `programs` (a socket: by default
    asibot.access.program_endpoint), where a session has the program role's rights only; with
    a credentials folder (asibot.access) it admits only the logins of its dictionary and
    applies the roles' access control, else every other session may do everything."""
    cfg = _base_config("router")
    endpoints = listen_endpoints(endpoint)
    cfg.insert_json5("listen/endpoints", json.dumps(endpoints + [programs or access.program_endpoint(endpoint)]))
    cfg.insert_json5("access_control", json.dumps(access.access_control(logins=credentials is not None)))
    if credentials is not None:
        dictionary = access.router_dictionary(credentials)
        cfg.insert_json5("transport/auth/usrpwd", json.dumps({"dictionary_file": str(dictionary)}))
    if any(e.startswith(TLS) for e in endpoints):
        if credentials is None:
            raise ValueError(f"{endpoint}: a tls/ endpoint is for a router with access control; give it "
                             f"the credentials folder ({access.ACCESS_ENV} or --access), which holds its "
                             "certificate")
        folder = Path(credentials)
        cert, key = folder / certificates.ROUTER, folder / certificates.ROUTER_KEY
        if not (cert.is_file() and key.is_file()):
            raise ValueError(f"{cert} or {key.name} does not exist: make them on the robot with "
                             f"`{access.ACCESS_ENV}={folder} python -m asibot.access`")
        cfg.insert_json5("transport/link/tls/listen_certificate", json.dumps(str(cert)))
        cfg.insert_json5("transport/link/tls/listen_private_key", json.dumps(str(key)))
    return cfg


def listen_endpoints(endpoint: str) -> list[str]:
    """`tcp/127.0.0.1:7447,tls/0.0.0.0:7448` -> both: loopback for the robot's own services,
    TLS for other machines."""
    endpoints = [e.strip() for e in endpoint.split(",") if e.strip()]
    if not endpoints:
        raise ValueError("the router needs an endpoint to listen on, such as tcp/127.0.0.1:7447")
    return endpoints


def _no_router(endpoint: str, login: access.Login | None) -> str:
    """Why no session opened: a router that does not run looks the same as one that refused
    the login, so name both."""
    if login is None:
        return (f"No Zenoh router answers at {endpoint}. Start it with `asibot router` or "
                f"`asibot up`, or set {ROUTER_ENV}; if that router runs with access control, set "
                f"{access.ACCESS_ENV} to its credentials folder.")
    tls = (f", or its certificate is not issued by {access.default_folder() / certificates.CA} for the "
           "name dialled (copy ca.pem again; dial a name the router's certificate holds)"
           if endpoint.startswith(TLS) else "")
    return (f"No Zenoh router at {endpoint} accepted the login {login.user!r} from "
            f"{access.default_folder()}{tls}: start the router (`asibot up`), copy that folder again "
            f"from the robot if the password changed, or unset {access.ACCESS_ENV} if the router "
            "runs without access control.")


def open_client(endpoint: str, *, wait: float | None = None, stop: threading.Event | None = None,
                name: str = "") -> zenoh.Session:
    """Open a client session, retrying every second until the router answers.

    Retrying in Python (instead of Zenoh's endless connect) keeps the process responsive
    to SIGTERM while it waits. `wait=None` waits forever; `stop` aborts the wait. With
    $ASIBOT_ACCESS set, the session logs in with the role of `name` (asibot.access).
    """
    deadline = None if wait is None else time.monotonic() + wait
    login = access.login(name)
    announced = False
    while True:
        try:
            return zenoh.open(client_config(endpoint, login=login))
        except zenoh.ZError as exc:
            if deadline is not None and time.monotonic() >= deadline:
                raise Unavailable(_no_router(endpoint, login)) from exc
            if not announced:
                log.warning("waiting for the router at %s ...", endpoint)
                announced = True
            if stop is not None and stop.wait(0.5):
                raise Unavailable("stopped while waiting for the router") from exc
            if stop is None:
                time.sleep(0.5)


class _Publisher:
    def __init__(self, pub: zenoh.Publisher) -> None:
        self._pub = pub

    def put(self, payload: bytes | bytearray) -> None:
        self._pub.put(payload)

    def matching(self) -> bool:
        # zenoh's stub says bool; the property returns a zenoh.MatchingStatus (eclipse-zenoh 1.x).
        return self._pub.matching_status.matching  # type: ignore[attr-defined]

    def close(self) -> None:
        self._pub.undeclare()


class _Token:
    def __init__(self, token: Any) -> None:
        self._token = token

    def close(self) -> None:
        self._token.undeclare()


def _drain(name: str, declared: Any, handle: Callable[[Any], None], workers: int = 1,
           prelude: Prelude | None = None) -> Drain:
    # Receive from the handler, not the subscriber: a blocked `Subscriber.recv()` holds a
    # borrow that makes `undeclare()` fail, while undeclaring closes the handler's channel
    # and wakes a blocked `handler.recv()` at once, so close() is immediate.
    return Drain(name, declared.handler.recv, handle, declared.undeclare, workers, prelude)


def _ring(size: int) -> zenoh.handlers.RingChannel[Any]:
    """Every channel of the bus is a ring: when full it drops its oldest item, so Zenoh's
    receiving thread never waits. (A full FifoChannel made it wait, and with it every
    subscription and every reply of the session: tests/common/test_bus_slow_subscriber.py.)"""
    return zenoh.handlers.RingChannel(size)


@functools.cache
def _steady_malloc() -> None:
    """Fix glibc's mmap and trim thresholds, once per process.

    Large messages (a depth image is 1.2 MB) otherwise make glibc's dynamic thresholds
    oscillate: in about half of the runs measured, it gave back and re-faulted ~2 MiB of heap
    per message (~550 page faults per round trip instead of ~40), and 1 MiB pub/sub p50 rose
    from ~0.3 ms to ~0.7 ms. Same as GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:
    glibc.malloc.trim_threshold=134217728. Without glibc this does nothing.

    The price is a ceiling, not a leak: a process keeps up to that much heap once large
    messages have passed (a kinematics service fed 4,000 fuzzed requests of up to 8 MB went
    from 97 to 280 MB within the first 1,000, then gained under 1 MB; bench/bench_safety.py).
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 32 << 20)   # M_MMAP_THRESHOLD
        libc.mallopt(-1, 128 << 20)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass


class ZenohBus(Bus):
    """The bus over a Zenoh router, in client mode (`tcp/127.0.0.1:7447` by default)."""

    def __init__(self, name: str, endpoint: str | None = None, *, wait: float | None = None,
                 stop: threading.Event | None = None) -> None:
        _steady_malloc()
        self._open(name, router_endpoint(endpoint))
        self.session = open_client(self.endpoint, wait=wait, stop=stop, name=name)
        self._refusals: dict[tuple[str, str], str | None] = {}

    def refusal(self, message: str, key: str) -> str | None:
        # Asked per call and per publish: the login file is read once per (message, key).
        try:
            return self._refusals[message, key]
        except KeyError:
            why = self._refusals[message, key] = access.refusal(self.name, message, key)
            return why

    def _declare_publisher(self, key: str, express: bool, block: bool) -> _Publisher:
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        return _Publisher(self.session.declare_publisher(key, express=express, congestion_control=cc))

    def _declare_subscriber(self, key: str, deliver: Callable[[str, bytes], None], maxsize: int,
                            prelude: Prelude | None = None) -> Drain:
        def handle(item: Any) -> None:
            if isinstance(item, tuple):  # from the prelude
                deliver(*item)
            else:
                deliver(str(item.key_expr), item.payload.to_bytes())

        return _drain(f"{self.name}-sub", self.session.declare_subscriber(key, _ring(maxsize or 1024)), handle,
                      prelude=prelude)

    def _declare_queryable(self, key: str, answer: Answer, workers: int) -> Drain:
        def run(query: zenoh.Query) -> None:
            try:
                raw = query.payload.to_bytes() if query.payload is not None else b""
                result = answer(str(query.key_expr), raw)
                if result is not None:
                    query.reply(result[0], result[1], express=True)
            finally:
                query.drop()  # finalise: otherwise the caller waits for its full timeout

        # A query the ring drops (256 waiting) is finalised by Zenoh: its caller hears "no answer".
        return _drain(f"{self.name}-rpc", self.session.declare_queryable(key, _ring(256)), run, workers)

    def _get(self, key: str, payload: bytes, timeout: float) -> list[tuple[str, bytes] | None]:
        # No consolidation: several latches on one key must all answer so the newest wins.
        replies = self.session.get(key, payload=payload, timeout=timeout,
                                   consolidation=zenoh.ConsolidationMode.NONE, express=True)
        return [(str(r.ok.key_expr), r.ok.payload.to_bytes()) if r.ok is not None else None
                for r in replies]

    def _put(self, key: str, payload: bytes) -> None:
        self.session.put(key, payload)

    def _wait_for_queryable(self, key: str, timeout: float) -> bool:
        querier = self.session.declare_querier(key)
        try:
            deadline = time.monotonic() + timeout
            # zenoh's stub says bool; the property returns a zenoh.MatchingStatus (eclipse-zenoh 1.x).
            while not querier.matching_status.matching:  # type: ignore[attr-defined]
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.005)
            return True
        finally:
            querier.undeclare()

    def _declare_token(self, key: str) -> _Token:
        return _Token(self.session.liveliness().declare_token(key))

    def _watch_tokens(self, pattern: str, on_change: Callable[[str, bool], None]) -> Drain:
        sub = self.session.liveliness().declare_subscriber(pattern, _ring(1 << 16), history=True)
        return _drain(f"{self.name}-watch", sub,
                      lambda s: on_change(str(s.key_expr), s.kind == zenoh.SampleKind.PUT))

    def _tokens(self, pattern: str, timeout: float) -> list[str]:
        replies = self.session.liveliness().get(pattern, timeout=timeout)
        return [str(r.ok.key_expr) for r in replies if r.ok is not None]

    def _close_transport(self) -> None:
        self.session.close()


def run_router(endpoint: str | None = None, stop: threading.Event | None = None,
               credentials: Path | str | None = None) -> None:
    """Run a Zenoh router in this process until `stop` is set (or forever)."""
    ep = router_endpoint(endpoint)
    session = open_router(ep, credentials)
    log.info("router listening on %s%s", ep, " with access control" if credentials else "")
    try:
        (stop or threading.Event()).wait()
    finally:
        session.close()


def _listened(sock: Path) -> bool:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        try:
            probe.connect(str(sock))
        except OSError:
            return False
    return True


def open_router(endpoint: str, credentials: Path | str | None = None,
                programs: str | None = None) -> zenoh.Session:
    """Open (and return) an in-process router session, for tests and `asibot up`; with a
    credentials folder (asibot.access), only its logins get in, each with its role's rights.
    Programs come in through the socket of `programs` (router_config), which is made here:
    its folder private to this user but for entering it, the socket open to `nobody` (the
    user a root server runs programs as), since whoever comes in there has a program's rights."""
    programs = programs or access.program_endpoint(endpoint)
    sock = access.program_socket(programs)
    sock.parent.mkdir(parents=True, exist_ok=True)
    os.chmod(sock.parent, 0o711)
    if sock.exists() and not _listened(sock):
        sock.unlink()     # left by a router that ended without removing it
    session = zenoh.open(router_config(endpoint, credentials, programs))
    os.chmod(sock, 0o666)
    return session

"""uvicorn serving the bridge's HTTP app on the bridge's own loop.

uvicorn (h11) parses HTTP: chunked bodies, keep-alive, pipelining are its. The bridge binds
the sockets itself, so a port in use is an OSError for its caller (uvicorn, binding, would exit
the process), and adds the bound uvicorn lacks: a request's head must come whole within
`Limits.http_idle_s` of the connection being free (uvicorn closes idle keep-alive connections,
but a client that sends a byte now and then would hold its connection for ever). What h11
cannot read is refused with a sentence that says what a request needs.
"""

from __future__ import annotations

import asyncio
import math
import socket

import uvicorn
from starlette.types import ASGIApp
from uvicorn.protocols.http.h11_impl import H11Protocol

from asibot.asterics_bridge.limits import Limits

#: How long requests in flight may take to finish when the bridge closes (then they are cancelled).
GRACE_S = 1
#: The answer (400) to what h11 cannot read; ASCII, as uvicorn sends it.
UNREADABLE = ("error: that is not an HTTP/1.1 request the bridge can read: it needs a request line such as "
              "'POST /command HTTP/1.1', a Host header, and headers of a few kilobytes at most.\n")


class HttpServer:
    """`app` on host:port (port 0: a free one, which `start` returns)."""

    def __init__(self, app: ASGIApp, host: str, port: int, limits: Limits) -> None:
        self.host, self.port = host, port
        idle_s = math.ceil(limits.http_idle_s)
        self._server = uvicorn.Server(uvicorn.Config(
            app, http=_BridgeH11, ws="none", lifespan="off", log_config=None, log_level="warning",
            access_log=False, server_header=False, proxy_headers=False, timeout_keep_alive=idle_s,
            timeout_graceful_shutdown=GRACE_S,
            # h11 drops (400) a head still unfinished past this; HeadLimit answers 431 to a whole one past the bound
            h11_max_incomplete_event_size=4 * limits.http_header_bytes))
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> int:
        """Serve; the port it listens on. OSError when it cannot."""
        sockets = _listen(self.host, self.port)
        self._task = asyncio.ensure_future(self._server.serve(sockets))
        while not self._server.started:
            if self._task.done():
                self._task.result()         # what ended it
                raise RuntimeError(f"the HTTP server on {self.host}:{self.port} ended as it started")
            await asyncio.sleep(0.005)
        self.port = sockets[0].getsockname()[1]
        return self.port

    async def close(self) -> None:
        """Take no more connections, close idle ones, let requests in flight finish for
        `GRACE_S` (then they are cancelled)."""
        if self._task is None or self._task.done():
            return
        self._server.should_exit = True
        await asyncio.wait([self._task], timeout=GRACE_S + 1.0)


class _BridgeH11(H11Protocol):
    """uvicorn's h11 protocol with a deadline for each request's head, from when the connection
    is free (opened, or its last answer sent): unlike uvicorn's keep-alive timeout, bytes coming
    in do not push it back. The deadline is the config's keep-alive timeout."""

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._deadline = self.loop.call_later(self.timeout_keep_alive, self._late)

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._deadline.cancel()
        if not self.transport.is_closing():
            self._deadline = self.loop.call_later(self.timeout_keep_alive, self._late)

    def connection_lost(self, exc: Exception | None) -> None:
        self._deadline.cancel()
        super().connection_lost(exc)

    def _late(self) -> None:
        if self.cycle is None or self.cycle.response_complete:     # no request is being answered
            self.transport.close()

    def send_400_response(self, msg: str) -> None:
        super().send_400_response(UNREADABLE)


def _listen(host: str, port: int) -> list[socket.socket]:
    """Sockets bound to every address of `host`, as asyncio's own servers bind (a name may have
    an IPv4 and an IPv6 address; "" means all interfaces)."""
    sockets: list[socket.socket] = []
    try:
        for family, kind, proto, _, address in dict.fromkeys(
                socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)):
            sock = socket.socket(family, kind, proto)
            sockets.append(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:      # the IPv4 address has its own socket
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            sock.bind(address)
    except OSError:
        for sock in sockets:
            sock.close()
        raise
    return sockets

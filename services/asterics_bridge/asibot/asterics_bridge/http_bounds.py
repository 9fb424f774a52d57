"""What one HTTP request may take: a head of `Limits.http_header_bytes`, a body of
`Limits.http_body_bytes` that comes within `Limits.http_idle_s`. (How long a head may take is
the server's bound: `http_server`.) An answer to a body left unread closes the connection,
so the bridge never reads a huge body only to throw it away."""

from __future__ import annotations

import asyncio

from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect, Request
from starlette.responses import PlainTextResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from asibot.asterics_bridge.limits import Limits

CLOSE = {"Connection": "close"}


class HeadLimit:
    """ASGI middleware: 431 for a request whose head is larger than `max_bytes`."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app, self.max_bytes = app, max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and head_bytes(scope) > self.max_bytes:
            answer = PlainTextResponse("error: the request's headers are too large.\n", 431, headers=CLOSE)
            await answer(scope, receive, send)
            return
        await self.app(scope, receive, send)


def head_bytes(scope: Scope) -> int:
    """The size of a request's head as it was sent, near enough: its target and header lines."""
    target = len(scope.get("raw_path") or b"") + len(scope.get("query_string") or b"")
    return target + sum(len(name) + len(value) + 4 for name, value in scope["headers"])


async def read_body(request: Request, limits: Limits) -> bytes:
    """The whole body (Content-Length or chunked), or HTTPException: 413 when it is larger than
    the bound (unread, when its Content-Length says so), 408 when it does not come in time."""
    most = limits.http_body_bytes
    declared = request.headers.get("content-length")
    if declared is not None and int(declared) > most:       # the server took only digits
        raise HTTPException(413, f"error: a command is at most {most} bytes; this body has {declared}.\n", CLOSE)
    body = bytearray()

    async def gather() -> None:
        async for chunk in request.stream():
            body.extend(chunk)
            if len(body) > most:
                raise HTTPException(413, f"error: a command is at most {most} bytes; this body has more.\n", CLOSE)

    try:
        await asyncio.wait_for(gather(), limits.http_idle_s)
    except TimeoutError:
        raise HTTPException(408, "error: the body did not come in time.\n", CLOSE) from None
    except ClientDisconnect:
        raise HTTPException(400, "error: the connection closed before the body ended.\n", CLOSE) from None
    return bytes(body)

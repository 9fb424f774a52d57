"""Only the Task Creator's own page may use its server: the checks on every request.

The page is served on 127.0.0.1, which every other web page the user visits can reach too
(asibot.local_http says how). So, before any route runs:
- the Host must be one of the server's own names (no DNS rebinding);
- a request from a browser must come from the page itself (Origin, Fetch Metadata); a link
  from elsewhere may still open the page;
- anything that changes something (every method but GET and HEAD) and the WebSocket must
  carry the page's session token, which the server writes into the page it serves: another
  origin can neither read the page nor guess the token, so it cannot send it.
Programs that are not browsers (tests, scripts) read the token from the page as the page does.
"""

from __future__ import annotations

import hmac
import json
import secrets
from typing import Any

from asibot.local_http import Callers

#: The header that carries the page's session token (the WebSocket: `?session=` in its URL).
HEADER = "x-asibot-session"
#: Where the page finds its token: <meta name=... content=TOKEN> in the served index.html.
META = "asibot-session"
#: Methods that change nothing and need no token.
SAFE_METHODS = ("GET", "HEAD")
#: Pages another site may link to (a top-level navigation), not embed or fetch.
LINKABLE = ("/", "/docs")
#: The WebSocket close code of a refused connection (the page reloads to get a new token).
WS_REFUSED = 4403


def new_session() -> str:
    """A token for the pages this server process serves (a restart makes pages reload)."""
    return secrets.token_urlsafe(24)


class PageGuard:
    """ASGI middleware that refuses, with 400/403 and a sentence, what is not the page's own."""

    def __init__(self, app: Any, callers: Callers, session: str) -> None:
        self.app = app
        self.callers = callers
        self.session = session.encode()

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        refusal = self.refusal(scope)
        if refusal is None:
            return await self.app(scope, receive, send)
        status, code, sentence = refusal
        if scope["type"] == "websocket":
            if code == "session":
                # The page's own origin with an old token: accepted only to say why it is closed,
                # so the page knows to reload (a refused handshake looks like a network fault).
                await receive()
                await send({"type": "websocket.accept"})
            return await send({"type": "websocket.close", "code": WS_REFUSED, "reason": sentence[:120]})
        body = json.dumps({"error": code, "message": sentence}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"application/json"), (b"cache-control", b"no-store")]})
        await send({"type": "http.response.body", "body": body})

    def refusal(self, scope: dict) -> tuple[int, str, str] | None:
        """(status, code, sentence) of the refusal of this request, or None to let it through."""
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers") or []}
        wrong_host = self.callers.host_refusal(headers.get("host"))
        if wrong_host:
            return 400, "bad_host", wrong_host
        scheme = "https" if scope.get("scheme") in ("https", "wss") else "http"
        method = scope.get("method", "GET")
        linkable = method == "GET" and scope.get("path") in LINKABLE
        stranger = self.callers.caller_refusal(headers, scheme, navigation_ok=linkable)
        if stranger:
            return 403, "not_allowed", stranger
        if scope["type"] == "http" and method in SAFE_METHODS:
            return None
        if scope["type"] == "websocket":
            given = _query(scope).get("session", "")
        else:
            given = headers.get(HEADER, "")
        if not hmac.compare_digest(given.encode(), self.session):
            return 403, "session", ("This page's session is not the server's (the server restarted, or the "
                                    "request did not come from the page): reload the page.")
        return None


def _query(scope: dict) -> dict[str, str]:
    query = scope.get("query_string", b"").decode("latin-1")
    return dict(part.partition("=")[::2] for part in query.split("&") if part)

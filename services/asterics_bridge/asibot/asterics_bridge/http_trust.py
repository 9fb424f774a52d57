"""Who may use the bridge's HTTP port, checked once, before any route runs.

Any web page the user visits can reach a port of 127.0.0.1 (asibot.local_http says how), so:
- the Host must be one of the bridge's names (a rebinding page calls it by its own): 400;
- a browser's request must come from an origin the user allowed (AsTeRICS-Grid's): 403, with
  no CORS header, so the page learns nothing (the log tells its user why);
- a preflight of an allowed page gets its permissions (204), and every answer to such a page
  names that origin, never '*';
- every request carries the token (`http_token`) but a stop, which is always safe and may be
  needed by someone without the token at hand. Only POST /command can tell a stop (it reads
  its body), so that route gets tokenless requests marked (`carried_token`) and obeys only a
  stop of them.
"""

from __future__ import annotations

import base64
import hmac
import logging
from collections.abc import Mapping

from starlette.datastructures import MutableHeaders, QueryParams
from starlette.requests import Request
from starlette.responses import PlainTextResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from asibot.local_http import Callers

log = logging.getLogger("asibot.asterics_bridge")

#: What a preflight of an allowed origin is told (Access-Control-Allow-Origin names the origin).
CORS_PREFLIGHT = {"Access-Control-Allow-Methods": "GET, POST, OPTIONS",
                  "Access-Control-Allow-Headers": "content-type, authorization, accept",
                  "Access-Control-Max-Age": "600"}
#: Where the middleware leaves, in the request's state, whether it carried the token.
TOKEN_GIVEN = "asterics_bridge.token_given"
#: The one route that may take a request without the token (a stop).
COMMAND_PATH = "/command"
NEEDS_TOKEN = ("error: this bridge needs its access token: add 'Authorization: Bearer <token>' (or Basic auth "
               "with the token as password, as AsTeRICS-Grid's HTTP action sends it, or ?token=). "
               "`python -m asibot.asterics_bridge.http_token` prints it; a stop needs none.\n")


class Trust:
    """ASGI middleware: the checks above, and the headers of every answer (no caching;
    `Vary: Origin`, since answers differ by page). Counts what it refuses in `counters`."""

    def __init__(self, app: ASGIApp, callers: Callers, token: str | None, counters: dict[str, int]) -> None:
        self.app, self.callers, self.token, self.counters = app, callers, token, counters

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        self.counters["http_requests"] += 1
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        refusal = self._caller_refusal(headers)
        if refusal is not None:
            await refusal(scope, receive, _answering(send, {}))
            return
        origin = headers.get("origin")
        send = _answering(send, {"Access-Control-Allow-Origin": origin} if origin else {})
        if scope["method"] == "OPTIONS":
            await Response(status_code=204, headers=_preflight(headers))(scope, receive, send)
            return
        given = carries_token(self.token, headers, QueryParams(scope["query_string"]))
        scope.setdefault("state", {})[TOKEN_GIVEN] = given
        if not given and not (scope["method"] == "POST" and scope["path"].rstrip("/") == COMMAND_PATH):
            await token_refusal(self.counters)(scope, receive, send)
            return
        await self.app(scope, receive, send)

    def _caller_refusal(self, headers: dict[str, str]) -> Response | None:
        """The answer to a request by a name that is not this bridge's (DNS rebinding) or from
        a page of an origin the user did not allow; None for the bridge's users."""
        wrong_host = self.callers.host_refusal(headers.get("host"))
        if wrong_host is not None:
            self.counters["refused_host"] += 1
            log.warning("refused an HTTP request: %s", wrong_host)
            return PlainTextResponse(f"error: {wrong_host}\n", 400)
        stranger = self.callers.caller_refusal(headers, "http")
        if stranger is not None:
            self.counters["refused_origin"] += 1
            # the page cannot read why (no CORS header): the log is where its user finds out
            log.warning("refused an HTTP request: %s", stranger)
            return PlainTextResponse(f"error: {stranger} Its owner allows an origin with --allow-origin "
                                     "(ASIBOT_ASTERICS_ORIGINS).\n", 403)
        return None


def carries_token(token: str | None, headers: Mapping[str, str], query: Mapping[str, str]) -> bool:
    """Whether a request gives `token` (None: the bridge needs none): Bearer, Basic auth with
    the token as password (what AsTeRICS-Grid's HTTP action sends), or ?token=."""
    if token is None:
        return True
    given = query.get("token", "")
    scheme, _, value = headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer":
        given = value.strip()
    elif scheme.lower() == "basic":
        try:
            given = base64.b64decode(value.strip(), validate=True).decode("utf-8").partition(":")[2]
        except ValueError:
            return False
    return hmac.compare_digest(given.encode(), token.encode())


def carried_token(request: Request) -> bool:
    """Whether `Trust` found the token on this request (False when no `Trust` looked)."""
    return request.scope.get("state", {}).get(TOKEN_GIVEN) is True


def token_refusal(counters: dict[str, int]) -> Response:
    """The 401 of a request without the token, counted (the health shows the attempts)."""
    counters["refused_token"] += 1
    return PlainTextResponse(NEEDS_TOKEN, 401, headers={"WWW-Authenticate": 'Basic realm="asterics_bridge"'})


def _preflight(headers: dict[str, str]) -> dict[str, str]:
    """The permissions of an allowed page's preflight (nothing for a program, which sends no
    Origin); Private Network access only to a page that asks for it."""
    if not headers.get("origin"):
        return {}
    if headers.get("access-control-request-private-network", "").lower() == "true":
        return {**CORS_PREFLIGHT, "Access-Control-Allow-Private-Network": "true"}
    return dict(CORS_PREFLIGHT)


def _answering(send: Send, extra: dict[str, str]) -> Send:
    """`send`, adding to the head of the answer what every answer carries, and `extra`."""
    async def answer(message: Message) -> None:
        if message["type"] == "http.response.start":
            headers = MutableHeaders(scope=message)
            headers["Cache-Control"] = "no-store"
            headers.add_vary_header("Origin")
            headers.update(extra)
        await send(message)
    return answer

"""The bridge's HTTP entry, for AsTeRICS-Grid's HTTP actions and live elements and for scripts:
POST /command, GET /status, GET / (what it serves), as a Starlette app.

Before a route runs: the head's size (`http_bounds.HeadLimit`), then who calls
(`http_trust.Trust`). Commands run on the bridge's thread pool, as TCP clients' do; a stop on
the pool of its own, so it never waits behind a slow command (a grab) of any client.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
from collections.abc import Callable

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import PlainTextResponse, Response
from starlette.routing import Route

from asibot.local_http import Callers

from asibot.asterics_bridge import vocabulary as vocab
from asibot.asterics_bridge.dispatcher import Dispatcher, Reply, Session
from asibot.asterics_bridge.http_bounds import HeadLimit, read_body
from asibot.asterics_bridge.http_command import command_of, json_answer, reply_answer, valid_robot, wants_json
from asibot.asterics_bridge.http_trust import Trust, carried_token, token_refusal
from asibot.asterics_bridge.limits import Limits

NOT_FOUND = "error: the bridge serves POST /command and GET /status.\n"
#: What a request of a route by another method is told.
WRONG_METHOD = {"/status": "error: use GET /status.\n",
                "/command": "error: POST the command to /command (text/plain, or JSON {\"command\": ...}).\n"}


class HttpEntry:
    """The routes and what they share. HTTP is stateless: requests share one dispatcher
    session per `?robot=` (none: the default one, which `robot <id>` switches)."""

    def __init__(self, dispatcher: Dispatcher, *, pool: concurrent.futures.Executor,
                 stop_pool: concurrent.futures.Executor, limits: Limits, counters: dict[str, int],
                 clients: Callable[[], int]) -> None:
        """`pool`: where commands run; `stop_pool`: where stops run; `counters`: the bridge's
        (refusals are counted there); `clients`: how many TCP clients the bridge has."""
        self.dispatcher, self.limits, self.counters, self.clients = dispatcher, limits, counters, clients
        self._pool, self._stop_pool = pool, stop_pool
        self._sessions: dict[str, Session] = {}

    def app(self, token: str | None, callers: Callers) -> Starlette:
        """The app: `token` is what every request but a stop carries (None: nothing);
        `callers` the Host names and foreign origins it answers to."""
        routes = [Route(path + slash, endpoint, methods=[method])
                  for path, endpoint, method in (("/status", self.status, "GET"), ("/command", self.command, "POST"))
                  for slash in ("", "/")]
        routes.append(Route("/", self.index, methods=["GET"]))
        return Starlette(routes=routes, exception_handlers={404: _not_found, 405: _wrong_method}, middleware=[
            Middleware(HeadLimit, max_bytes=self.limits.http_header_bytes),
            Middleware(Trust, callers=callers, token=token, counters=self.counters)])

    async def index(self, request: Request) -> Response:
        return PlainTextResponse("asterics_bridge: POST /command (text/plain or JSON {\"command\": \"forward\"}), "
                                 "GET /status.\n" + vocab.help_text() + "\n")

    async def status(self, request: Request) -> Response:
        """What AsTeRICS-Grid's live elements show: the robot's state, as JSON."""
        robot = request.query_params.get("robot") or self._session("").robot
        if not valid_robot(robot):
            return PlainTextResponse(f"error: {robot[:40]!r} is not a robot id.\n", 400)
        status = self.dispatcher.board.json(robot)
        status["clients"] = self.clients()
        return json_answer(200, status)

    async def command(self, request: Request) -> Response:
        body = await read_body(request, self.limits)
        parsed = command_of(request.query_params, request.headers, body)
        stop = isinstance(parsed, tuple) and vocab.is_stop(parsed[1])
        if not carried_token(request) and not stop:
            return token_refusal(self.counters)
        if isinstance(parsed, Response):
            return parsed
        robot, text = parsed
        if not carried_token(request):      # a stop without the token: it leaves no session behind
            reply = await self._stop_once(robot or self._session("").robot, text)
        else:
            reply = await self._run(self._session(robot), text.strip(), stop)
        return reply_answer(reply, wants_json(request.headers))

    async def _run(self, session: Session, text: str, stop: bool) -> Reply:
        pool = self._stop_pool if stop else self._pool
        return await asyncio.get_running_loop().run_in_executor(pool, self.dispatcher.execute, session, text)

    async def _stop_once(self, robot: str, text: str) -> Reply:
        """A stop of `robot` in a session of its own, closed after it."""
        session = self.dispatcher.open_session(f"http:stop:{robot}")
        session.robot = robot
        try:
            return await self._run(session, text.strip(), stop=True)
        finally:
            await asyncio.get_running_loop().run_in_executor(self._stop_pool, self.dispatcher.close_session, session)

    def _session(self, robot: str) -> Session:
        session = self._sessions.get(robot)
        if session is None:
            session = self._sessions[robot] = self.dispatcher.open_session(f"http:{robot or 'default'}")
            session.authorized = True     # Trust checks the token of every request
            if robot:
                session.robot = robot
        return session


async def _not_found(request: Request, exc: Exception) -> Response:
    return PlainTextResponse(NOT_FOUND, 404)


async def _wrong_method(request: Request, exc: Exception) -> Response:
    """405 with the route's usage; GET is all that / serves, so another method finds nothing there."""
    usage = WRONG_METHOD.get(request.url.path.rstrip("/"))
    return PlainTextResponse(usage, 405) if usage else await _not_found(request, exc)

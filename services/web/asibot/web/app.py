"""The web Task Creator's FastAPI application: the page, its JSON API and its WebSocket.

`create_app(web)` takes everything the routes use (`Web`: the bus-facing parts and the user's
files), so tests build it on the in-memory bus and a temporary folder, and the service builds
it on the real router. The page is static files (static/): index.html, our ES modules in
static/js/ as written, and the npm packages bundled once into static/vendor/ by bootstrap.
"""

from __future__ import annotations
from importlib import resources

import asyncio
import contextlib
import gzip
import json
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fastapi import FastAPI, WebSocket, WebSocketDisconnect
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.datastructures import Headers
from starlette.middleware.gzip import GZipMiddleware
from pydantic import StrictBool

from asibot.errors import RpcError
from asibot.local_http import Callers
from asibot.web import errors, guard, lan, page_messages
from asibot.web.api_files import ICON_LIMIT, IMPORT_LIMIT
from asibot.web.api_files import router as files_router
from asibot.web import api_base, api_favourites
from asibot.web.api_steps import router as steps_router
from asibot.web.api_robots import router as robots_router
from asibot.web.api_world import router as world_router
from asibot.web.cameras import Cameras
from asibot.web.fleet import Fleet
from asibot.web.live import Live
from asibot.web.models import Strict
from asibot.web.motion import Motion
from asibot.web.preload import ModuleGraph
from asibot.web.runner import ProgramRunner
from asibot.web.tasks_bus import TaskDesk
from asibot.web.userdata import UserData
from asibot.web.voice_relay import MicError, VoiceRelay
from asibot.web.world import World

#: The page's files; ASIBOT_WEB_STATIC serves another copy of them (a page being changed, or an
#: older page to compare with: bench/bench_switch.py measures today's page beside the last one).
STATIC = Path(os.environ.get("ASIBOT_WEB_STATIC") or str(resources.files("asibot.web") / "static"))
#: The line of index.html after which the page's session token is written.
CHARSET = '<meta charset="utf-8">'
#: The page's script; the modules it imports are named after it, to be fetched at once.
MAIN_SCRIPT = '<script type="module" src="/static/js/main.js"></script>'
#: Largest request body, bytes; uploads have their own, larger limits.
BODY_LIMIT = 1024 * 1024
UPLOAD_PATHS = {"/api/icons": ICON_LIMIT + 64 * 1024, "/api/import": IMPORT_LIMIT + 64 * 1024}

log = logging.getLogger("asibot.web")


@dataclass
class Web:
    """What the routes work with."""

    fleet: Fleet
    motion: Motion
    data: UserData
    runner: ProgramRunner
    live: Live
    cameras: Cameras
    tasks: TaskDesk
    voice: VoiceRelay
    world: World
    phones: lan.PhoneAccess = field(default_factory=lan.PhoneAccess)
    #: Who may call the server (its Host names), and the token its own pages carry (guard.py).
    callers: Callers = field(default_factory=Callers)
    session: str = field(default_factory=guard.new_session)


class BodyLimit:
    """Refuse a request body over its limit with 413 and a sentence, before it is read whole
    (Content-Length first; a chunked body is counted as it arrives)."""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        limit = UPLOAD_PATHS.get(scope["path"], BODY_LIMIT)
        too_big = JSONResponse({"error": "bad_request",
                                "message": f"The request is larger than {limit // 1024} KiB; nothing was changed."},
                               status_code=413)
        length = dict(scope.get("headers") or []).get(b"content-length")
        if length is not None and length.isdigit() and int(length) > limit:
            return await too_big(scope, receive, send)
        seen = 0

        async def counted() -> dict:
            nonlocal seen
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > limit:
                raise _TooBig()
            return message

        async def answer(message: dict) -> None:
            # A body parser that meets _TooBig answers 400 itself: the answer is 413 all the same.
            if seen <= limit:
                await send(message)
            elif message["type"] == "http.response.start":
                await too_big(scope, receive, send)

        try:
            await self.app(scope, counted, answer)
        except _TooBig:
            await too_big(scope, receive, send)


class VoiceSettings(Strict):
    """Ask "Shall I start <task>? Say yes or no." before a task heard by voice starts."""
    confirm: StrictBool


class _TooBig(Exception):
    pass


def create_app(web: Web) -> guard.PageGuard:
    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        pusher = asyncio.create_task(web.live.pusher())
        try:
            yield
        finally:
            pusher.cancel()

    # The API's page loads Swagger UI from our own /static (FastAPI's default is a CDN: blank offline).
    app = FastAPI(title="ASIBOT Task Creator", lifespan=lifespan, docs_url=None, redoc_url=None)
    app.state.web = web
    errors.install(app)
    app.include_router(robots_router)
    app.include_router(files_router)
    app.include_router(world_router)
    app.include_router(steps_router)
    app.include_router(api_base.router)
    app.include_router(api_favourites.router)

    @app.get("/api/voice", summary="the voice service's settings (ask yes first before a task heard starts)")
    async def voice_settings() -> dict:
        return await asyncio.to_thread(web.voice.settings)

    @app.put("/api/voice", summary="change the voice service's settings")
    async def change_voice_settings(change: VoiceSettings) -> dict:
        return await asyncio.to_thread(web.voice.settings, change.confirm)

    @app.get("/api/phone", summary="how a phone or tablet reaches this page (LAN mode: its address and token)")
    def phone() -> dict:
        return web.phones.json()

    @app.get("/api/phone/qr.png", summary="the QR code of the first LAN address, for a phone's camera",
             response_class=Response)
    def phone_qr() -> Response:
        urls = web.phones.urls
        if not urls:
            raise RpcError("unavailable", "This page is served to this computer only: there is no LAN address "
                                          "to show (start the web service with --lan).")
        return Response(lan.qr_png(urls[0]), media_type="image/png", headers={"Cache-Control": "no-store"})

    @app.get("/api/config", summary="what the page needs to draw its controls")
    def config() -> dict:
        return {"jog": web.motion.settings.as_json(), "base": api_base.config(),
                "pointer": web.motion.pointer.settings.page()}

    @app.websocket("/ws")
    async def feed(socket: WebSocket) -> None:
        await socket.accept()
        page = await web.live.attach(socket)
        sender = asyncio.create_task(web.live.drain(page))
        try:
            while True:
                message = await socket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                if message.get("bytes") is not None:
                    _on_page_sound(web, page, message["bytes"])
                elif message.get("text") is not None:
                    await _on_page_message(web, page, message["text"])
        except WebSocketDisconnect:
            pass
        finally:
            web.live.detach(page)
            sender.cancel()
            _stop_listening(page)
            if page.holding:  # a closed tab must not leave a hold-to-move running
                await asyncio.to_thread(stop_quietly, web.motion, page.holding, "a hold")

    modules = ModuleGraph(STATIC, "/static", "js/main.js")

    @app.get("/", include_in_schema=False)
    def index() -> HTMLResponse:
        # Read each time (edit and reload); it carries the session token, so no cache keeps it.
        preloads = "".join(f'\n  <link rel="modulepreload" href="{url}">' for url in modules.urls())
        page = (STATIC / "index.html").read_text(encoding="utf-8").replace(
            CHARSET, f'{CHARSET}\n  <meta name="{guard.META}" content="{web.session}">', 1).replace(
            MAIN_SCRIPT, MAIN_SCRIPT + preloads, 1)
        return HTMLResponse(page, headers={"Cache-Control": "no-store"})

    @app.get("/docs", include_in_schema=False)
    def api_docs() -> HTMLResponse:
        return get_swagger_ui_html(openapi_url=app.openapi_url or "/openapi.json", title=f"{app.title}: API",
                                   swagger_js_url="/static/vendor/swagger/swagger-ui-bundle.js",
                                   swagger_css_url="/static/vendor/swagger/swagger-ui.css",
                                   swagger_favicon_url="/static/icons/home.svg")

    app.mount("/static", Static(directory=STATIC), name="static")
    return guard.PageGuard(BodyLimit(Compressed(app)), web.callers, web.session)


class Static(StaticFiles):
    """The page's files, asked again at every load (a 304 when unchanged, by their ETag): after an
    upgrade the browser runs the new JavaScript, never a guess at how long the old one stays fresh.
    gzipped for browsers that take it, each version of a file once (three.js took 60 ms to
    compress, at every load of every page), as a web server's precompressed files are."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._gzipped: dict[str, tuple[str, bytes]] = {}    # path -> (its ETag, its gzip)

    def file_response(self, *args: Any, **kwargs: Any) -> Response:
        response = super().file_response(*args, **kwargs)
        response.headers["Cache-Control"] = "no-cache"
        return response

    async def get_response(self, path: str, scope: Any) -> Response:
        response = await super().get_response(path, scope)
        if not (isinstance(response, FileResponse) and response.status_code == 200 and scope["method"] == "GET"
                and wants_gzip(scope) and compressible(response)):
            return response
        full_path, tag = str(response.path), response.headers["etag"]
        cached = self._gzipped.get(full_path)
        if cached is None or cached[0] != tag:
            body = await asyncio.to_thread(lambda: gzip.compress(Path(full_path).read_bytes(), 9, mtime=0))
            cached = self._gzipped[full_path] = (tag, body)
        headers = {k: v for k, v in response.headers.items() if k not in ("content-length", "content-type")}
        return Response(cached[1], media_type=response.media_type,
                        headers={**headers, "Content-Encoding": "gzip", "Vary": "Accept-Encoding"})


def wants_gzip(scope: Any) -> bool:
    return "gzip" in Headers(scope=scope).get("accept-encoding", "") and "range" not in Headers(scope=scope)


def compressible(response: FileResponse) -> bool:
    """Text, scripts, JSON and SVG of 1 KiB or more; pictures are compressed already."""
    kind = response.media_type or ""
    size = int(response.headers.get("content-length", "0"))
    return size >= 1024 and (kind.startswith("text/") or kind in (
        "application/javascript", "text/javascript", "application/json", "image/svg+xml"))


class Compressed:
    """gzip for the API's schema and its page, for browsers that take it (the page's files are
    gzipped by Static, once a version). Only there: a camera's MJPEG stream must go out frame by
    frame, never held in a compressor's buffer."""

    PATHS = ("/openapi.json", "/docs")

    def __init__(self, app: Any) -> None:
        self.app, self.gzip = app, GZipMiddleware(app, minimum_size=1024)

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        wanted = scope["type"] == "http" and scope["path"].startswith(self.PATHS)
        await (self.gzip if wanted else self.app)(scope, receive, send)


def stop_quietly(motion: Motion, robot: str, after: str) -> None:
    """Stop the arm once what moved it has ended (a hold let go, a page closed, a program gone):
    that has ended either way, so a failed stop is logged, never raised into it."""
    try:
        motion.stop(robot)
    except RpcError as exc:     # the controller's own refusal, e.g. while its estop is engaged
        log.info("stop of %s after %s: %s", robot, after, exc)
    except Exception as exc:
        log.warning("could not stop %s after %s: %s", robot, after, exc)


def _stop_listening(page) -> None:
    if page.mic is not None:
        page.mic.close()
    page.mic, page.mic_rate = None, None


def _on_page_sound(web: Web, page, data: bytes) -> None:
    """A frame of the page's microphone: on to the voice service. A bad frame stops the
    listening with the sentence (a broken page must not flood the voice service or itself)."""
    if page.mic_rate is None:
        return    # frames still on their way after the page stopped listening
    try:
        web.voice.chunk(page.id, page.mic_rate, data)
    except MicError as exc:
        _stop_listening(page)
        page.offer(json.dumps({"type": "mic-stopped", "text": str(exc)}))


def _tool_pitch(web: Web, robot: str) -> float | None:
    """The tool's rot(y') now, deg (a gamepad's stick leads it), or None before a Cartesian state."""
    point = web.fleet.point(robot)
    return None if point is None or len(point) < 4 else point[3]


async def _on_page_message(web: Web, page, text: str) -> None:
    """One message of the page (page_messages: checked there, once)."""
    try:
        msg = page_messages.read(text, web.fleet.ids())
    except page_messages.Refused as refused:
        await _on_refused(web, page, refused)
        return
    if isinstance(msg, page_messages.Mic):
        _stop_listening(page)
        if msg.rate is not None:
            page.mic, page.mic_rate = web.voice.start(page.id, msg.rate), msg.rate
    elif isinstance(msg, (page_messages.Hold, page_messages.Point)):
        page.holding = msg.robot
        try:
            if isinstance(msg, page_messages.Hold):
                await asyncio.to_thread(web.motion.hold, msg.robot, msg.space, msg.axis, msg.direction, msg.level)
            else:
                await asyncio.to_thread(web.motion.point, msg.robot, msg.reading, _tool_pitch(web, msg.robot))
        except RpcError as exc:
            page.offer(page_messages.Refused(exc.message, exc.code, robot=msg.robot).json())
    elif isinstance(msg, page_messages.Release):
        robot, page.holding = page.holding, None
        if robot:
            await asyncio.to_thread(stop_quietly, web.motion, robot, "a hold")


async def _on_refused(web: Web, page, refused: page_messages.Refused) -> None:
    """Tell the page, after what its message would have done first: a `mic` stops the listening,
    and a robot's message for a connected robot makes it the one this page moves, so a release
    or a closed tab stops it; a bad pointer reading ends the pointer's stream at once (a device
    that sends NaN mid-stream must not leave the arm moving until the watchdog)."""
    if refused.kind is None:
        await page.socket.send_text(refused.json())
        return
    if refused.kind == "mic":
        _stop_listening(page)
    if refused.robot is not None:
        page.holding = refused.robot
        if refused.moving:
            try:
                await asyncio.to_thread(web.motion.point, refused.robot, page_messages.STILL, None)
            except RpcError as exc:
                refused = page_messages.Refused(exc.message, exc.code, robot=refused.robot)
    page.offer(refused.json())

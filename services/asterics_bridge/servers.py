"""The bridge's sockets: one TCP port for NetConnection and text clients, one HTTP port.

Both run on one asyncio loop in a thread of their own; commands run on a small thread pool
(`Dispatcher.execute` makes blocking RPC calls), one at a time per client, in order, except
`stop`, which never waits behind a slow command. Nothing a client does can block another:
- what goes out to a client is written without waiting; a client whose unsent output passes
  `Limits.send_buffer` bytes (it never reads) is dropped;
- a client with more than `Limits.queued_commands` commands waiting gets "busy" for the extra;
- half frames wait for their rest without blocking anything; bad frames are answered and
  skipped; a client sending `Limits.bad_frames` bad frames is dropped;
- beyond `Limits.max_clients` a new client is told so and closed;
- HTTP headers, bodies and idle keep-alive connections are bounded.
When a client goes away, its command in flight finishes first, then the dispatcher stops a
motion it started (`Dispatcher.close_session`).
"""

from __future__ import annotations

import asyncio
import base64
import concurrent.futures
import hmac
import json
import logging
import socket
import threading
import time
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from asibot import keys
from asibot.asterics_bridge import lines
from asibot.asterics_bridge import netconnection as nc
from asibot.asterics_bridge import vocabulary as vocab
from asibot.asterics_bridge.dispatcher import Dispatcher, Reply, Session
from asibot.asterics_bridge.status import Notice

log = logging.getLogger("asibot.asterics_bridge")

#: NetConnection ports of what the bridge sends: the event phrase (+ an event frame for alarms),
#: the answer to each command, the event's whole sentence.
NOTICE_PORT, REPLY_PORT, SENTENCE_PORT = 1, 2, 3
DEFAULT_TCP_PORT, DEFAULT_HTTP_PORT = 21112, 8090
#: After this long without sending, a NetConnection client gets a keepalive (the plugin's own
#: server side waits about 7.75 s; it ignores them, and a dead peer shows as a failed write).
KEEPALIVE_S = 7.75

HTTP_STATUS = {200: "OK", 204: "No Content", 400: "Bad Request", 401: "Unauthorized", 403: "Forbidden",
               404: "Not Found", 405: "Method Not Allowed", 408: "Request Timeout", 409: "Conflict",
               411: "Length Required", 413: "Content Too Large", 415: "Unsupported Media Type",
               431: "Request Header Fields Too Large", 500: "Internal Server Error",
               503: "Service Unavailable", 504: "Gateway Timeout"}
#: Reply codes -> HTTP status.
_REPLY_STATUS = {"ok": 200, "not_understood": 400, "bad_request": 400, "forbidden": 403, "unavailable": 503,
                 "timeout": 504, "internal": 500}
CORS = {"Access-Control-Allow-Origin": "*",
        "Access-Control-Allow-Methods": "GET, POST, OPTIONS",
        "Access-Control-Allow-Headers": "content-type, authorization, accept",
        "Access-Control-Max-Age": "600"}


@dataclass(frozen=True)
class Limits:
    max_clients: int = 100
    send_buffer: int = 256 * 1024       # bytes waiting for a client that does not read
    queued_commands: int = 16
    bad_frames: int = 50
    keepalive_s: float = KEEPALIVE_S
    http_header_bytes: int = 8 * 1024
    http_body_bytes: int = 4 * 1024
    http_idle_s: float = 30.0
    http_requests: int = 1000           # per keep-alive connection
    sndbuf: int | None = None           # SO_SNDBUF of client sockets (tests make it small)
    workers: int = 8


class _Client:
    """One TCP client: its session, its protocol, and how to talk back to it."""

    def __init__(self, bridge: "Servers", writer: asyncio.StreamWriter, session: Session) -> None:
        self.bridge, self.writer, self.session = bridge, writer, session
        self.protocol: str | None = None
        self.last_sent = time.monotonic()
        self.queue: asyncio.Queue[str] = asyncio.Queue()
        self.in_flight: asyncio.Future | None = None
        self.bad = 0
        self.closed = False

    # --- out ---------------------------------------------------------------------------
    def send(self, data: bytes) -> None:
        if self.closed:
            return
        transport = self.writer.transport
        if transport.get_write_buffer_size() + len(data) > self.bridge.limits.send_buffer:
            log.warning("dropping %s: it does not read what the bridge sends", self.session.peer)
            self.bridge.counters["dropped_slow"] += 1
            self.abort()
            return
        self.writer.write(data)
        self.last_sent = time.monotonic()

    def answer(self, reply: Reply) -> None:
        if self.protocol == lines.NETCONNECTION:
            self.send(nc.encode_string(REPLY_PORT, reply.frame_text()))
        else:
            self.send(lines.encode_line(reply.line()))

    def notice(self, n: Notice) -> None:
        if self.protocol == lines.NETCONNECTION:
            data = nc.encode_string(NOTICE_PORT, n.phrase)
            if n.alarm:
                data += nc.encode_event(NOTICE_PORT)
            self.send(data + nc.encode_string(SENTENCE_PORT, n.text))
        elif self.protocol == lines.TEXT:
            self.send(lines.encode_line(f"{'alarm' if n.alarm else 'event'} {n.phrase}: {n.text}"))

    def abort(self) -> None:
        self.closed = True
        self.writer.transport.abort()


class Servers:
    """The TCP and HTTP servers on their loop thread. `start()` binds (port 0: a free port,
    then `tcp_port`/`http_port` say which) and raises OSError when it cannot."""

    def __init__(self, dispatcher: Dispatcher, *, host: str = "127.0.0.1", tcp_port: int = DEFAULT_TCP_PORT,
                 http_port: int | None = DEFAULT_HTTP_PORT, events: dict[int, str] | None = None,
                 limits: Limits = Limits()) -> None:
        self.dispatcher, self.host, self.limits = dispatcher, host, limits
        self.tcp_port, self.http_port = tcp_port, http_port
        self.events = dict(events or {})
        self.counters = {"connections": 0, "refused_full": 0, "dropped_slow": 0, "dropped_bad": 0,
                         "bad_frames": 0, "http_requests": 0}
        self._clients: set[_Client] = set()
        self._http_sessions: dict[str, Session] = {}
        self._pool = concurrent.futures.ThreadPoolExecutor(limits.workers, thread_name_prefix="asterics-cmd")
        # stops have threads of their own: a pool busy with slow commands (grab) never delays them
        self._stop_pool = concurrent.futures.ThreadPoolExecutor(2, thread_name_prefix="asterics-stop")
        self._loop = asyncio.new_event_loop()
        self._servers: list[asyncio.base_events.Server] = []
        self._thread = threading.Thread(target=self._loop.run_forever, name="asterics-io", daemon=True)
        self._ticker: asyncio.Task | None = None
        self._handlers: set[asyncio.Task] = set()

    # ------------------------------------------------------------------ lifetime
    def start(self) -> "Servers":
        self._thread.start()
        try:
            asyncio.run_coroutine_threadsafe(self._start(), self._loop).result(10)
        except BaseException:
            self.close()
            raise
        return self

    async def _start(self) -> None:
        tcp = await asyncio.start_server(self._serve_tcp, self.host, self.tcp_port, reuse_address=True)
        self._servers.append(tcp)
        self.tcp_port = tcp.sockets[0].getsockname()[1]
        if self.http_port is not None:
            http = await asyncio.start_server(self._serve_http, self.host, self.http_port, reuse_address=True,
                                              limit=self.limits.http_header_bytes)
            self._servers.append(http)
            self.http_port = http.sockets[0].getsockname()[1]
        self._ticker = asyncio.ensure_future(self._tick())

    def close(self) -> None:
        if self._loop.is_closed():
            return

        async def stop() -> None:
            for server in self._servers:
                server.close()
            for client in list(self._clients):
                client.abort()          # their handlers end by themselves, stopping what they started
            if self._ticker is not None:
                self._ticker.cancel()
            if self._handlers:
                await asyncio.wait(self._handlers, timeout=1.0)

        if self._thread.is_alive():
            try:
                asyncio.run_coroutine_threadsafe(stop(), self._loop).result(2)
            except Exception:
                log.exception("closing the servers failed")
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(2)
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._stop_pool.shutdown(wait=False, cancel_futures=True)
        if not self._thread.is_alive():
            self._loop.close()

    def clients(self) -> int:
        return len(self._clients)

    async def _tick(self) -> None:
        """Keepalives to idle NetConnection clients; the dispatcher's longest-motion check."""
        period = min(0.25, self.limits.keepalive_s / 4)
        expiring: asyncio.Future | None = None
        while True:
            await asyncio.sleep(period)
            now = time.monotonic()
            for c in list(self._clients):
                if c.protocol == lines.NETCONNECTION and now - c.last_sent >= self.limits.keepalive_s:
                    c.send(nc.KEEPALIVE_FRAME)
            if expiring is None or expiring.done():
                expiring = self._loop.run_in_executor(self._pool, self.dispatcher.expire)

    async def _execute(self, session: Session, text: str, pool: concurrent.futures.Executor | None = None) -> Reply:
        return await self._loop.run_in_executor(pool or self._pool, self.dispatcher.execute, session, text)

    # ------------------------------------------------------------------ TCP
    async def _serve_tcp(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = "%s:%s" % writer.get_extra_info("peername")[:2]
        sock = writer.get_extra_info("socket")
        if self.limits.sndbuf and sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.limits.sndbuf)
        if len(self._clients) >= self.limits.max_clients:
            self.counters["refused_full"] += 1
            log.warning("refusing %s: %d clients already", peer, len(self._clients))
            # the protocol is not known yet: a line is the one thing both kinds may read
            writer.write(lines.encode_line(f"error: the bridge serves {self.limits.max_clients} clients "
                                           "at most; try again later."))
            writer.close()
            return
        self.counters["connections"] += 1
        handler = asyncio.current_task()
        self._handlers.add(handler)
        handler.add_done_callback(self._handlers.discard)
        session = self.dispatcher.open_session(peer)
        client = _Client(self, writer, session)
        session.notify = lambda n: self._loop.call_soon_threadsafe(client.notice, n)
        self._clients.add(client)
        worker = asyncio.ensure_future(self._work(client))
        try:
            await self._read(reader, client)
        except (ConnectionError, OSError):
            pass
        finally:
            self._clients.discard(client)
            client.closed = True
            worker.cancel()
            if client.in_flight is not None:     # a motion it starts must be known before the stop
                await asyncio.wait([client.in_flight])
            await self._loop.run_in_executor(self._pool, self.dispatcher.close_session, session)
            writer.close()

    async def _read(self, reader: asyncio.StreamReader, client: _Client) -> None:
        head = b""
        while client.protocol is None:
            data = await reader.read(4096)
            if not data:
                return
            head += data
            client.protocol = lines.sniff(head)
        decoder: nc.Decoder | lines.LineDecoder = (nc.Decoder() if client.protocol == lines.NETCONNECTION
                                                   else lines.LineDecoder())
        data = head
        while data and not client.closed:
            for item in decoder.feed(data):
                if client.closed:
                    return
                self._take(client, item)
            data = await reader.read(4096)

    def _take(self, client: _Client, item: object) -> None:
        if isinstance(item, (nc.BadFrame, lines.BadLine)):
            self.counters["bad_frames"] += 1
            client.bad += 1
            client.answer(Reply(False, item.text, "bad_request"))
            if client.bad >= self.limits.bad_frames:
                log.warning("dropping %s: %d bad frames", client.session.peer, client.bad)
                self.counters["dropped_bad"] += 1
                client.abort()
            return
        if isinstance(item, str):
            if item.strip():
                self._command(client, item)
            return
        assert isinstance(item, nc.Frame)
        if item.kind == nc.STRING:
            self._command(client, item.value)
        elif item.kind == nc.EVENT:
            command = self.events.get(item.port)
            if command is None:
                mapped = ", ".join(f"{p}={c}" for p, c in sorted(self.events.items())) or "none"
                client.answer(Reply(False, f"Event port {item.port} has no command (mapped: {mapped}); "
                                           "map it with --events.", "bad_request"))
            else:
                self._command(client, command)
        elif item.kind in (nc.INTEGER, nc.DOUBLE):
            client.answer(Reply(False, f"{item.kind.capitalize()} frames are not commands; send a string such "
                                       "as 'forward', or an event mapped with --events.", "bad_request"))
        # keepalives: nothing to do

    def _command(self, client: _Client, text: str) -> None:
        if _is_stop(text):   # never waits behind a slow command
            asyncio.ensure_future(self._stop(client, text))
        elif client.queue.qsize() >= self.limits.queued_commands:
            client.answer(Reply(False, f"Busy: {client.queue.qsize()} commands are waiting already; this one was "
                                       "dropped. Wait for the answers.", "busy"))
        else:
            client.queue.put_nowait(text)

    async def _stop(self, client: _Client, text: str) -> None:
        client.answer(await self._execute(client.session, text, self._stop_pool))

    async def _work(self, client: _Client) -> None:
        while True:
            text = await client.queue.get()
            client.in_flight = asyncio.ensure_future(self._execute(client.session, text))
            # shielded: a disconnect cancels this worker, not the command (it is awaited, then stopped)
            reply = await asyncio.shield(client.in_flight)
            client.in_flight = None
            client.answer(reply)

    # ------------------------------------------------------------------ HTTP
    async def _serve_http(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            for _ in range(self.limits.http_requests):
                keep = await self._http_request(reader, writer)
                await writer.drain()
                if not keep:
                    break
        except (ConnectionError, OSError, asyncio.IncompleteReadError):
            pass
        finally:
            writer.close()

    async def _http_request(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> bool:
        """One request; whether the connection may serve another."""
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), self.limits.http_idle_s)
        except asyncio.TimeoutError:
            return False
        except asyncio.LimitOverrunError:
            _respond(writer, 431, "error: the request's headers are too large.\n", keep=False)
            return False
        except asyncio.IncompleteReadError:
            return False
        self.counters["http_requests"] += 1
        try:
            request_line, *header_lines = head.decode("latin-1").split("\r\n")
            method, target, version = request_line.split(" ")
            headers = {k.strip().lower(): v.strip() for k, _, v in (h.partition(":") for h in header_lines if h)}
        except ValueError:
            _respond(writer, 400, "error: that is not an HTTP request.\n", keep=False)
            return False
        keep = version == "HTTP/1.1" and headers.get("connection", "").lower() != "close"
        url = urlsplit(target)
        query = {k: v[0] for k, v in parse_qs(url.query).items()}
        if method == "OPTIONS":
            _respond(writer, 204, "", keep=keep, extra={"Access-Control-Allow-Private-Network": "true"})
            return keep
        body = b""
        if "transfer-encoding" in headers:
            _respond(writer, 411, "error: send the body with a Content-Length, not chunked.\n", keep=False)
            return False
        if "content-length" in headers:
            try:
                length = int(headers["content-length"])
                if length < 0:
                    raise ValueError
            except ValueError:
                _respond(writer, 400, "error: Content-Length is not a size.\n", keep=False)
                return False
            if length > self.limits.http_body_bytes:
                _respond(writer, 413, f"error: a command is at most {self.limits.http_body_bytes} bytes; "
                                      f"this body has {length}.\n", keep=False)
                return False
            try:
                body = await asyncio.wait_for(reader.readexactly(length), self.limits.http_idle_s)
            except asyncio.TimeoutError:
                _respond(writer, 408, "error: the body did not come in time.\n", keep=False)
                return False
        if not self._authorized(headers, query):
            _respond(writer, 401, "error: this bridge needs its access token: add 'Authorization: Bearer "
                                  "<token>' (or Basic auth with the token as password, or ?token=).\n",
                     keep=keep, extra={"WWW-Authenticate": 'Basic realm="asterics_bridge"'})
            return keep
        status, content, ctype = await self._route(method, url.path, query, headers, body)
        _respond(writer, status, content, keep=keep, ctype=ctype)
        return keep

    def _authorized(self, headers: dict[str, str], query: dict[str, str]) -> bool:
        token = self.dispatcher.token
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

    async def _route(self, method: str, path: str, query: dict[str, str], headers: dict[str, str],
                     body: bytes) -> tuple[int, str, str]:
        path = path.rstrip("/") or "/"
        if path == "/status":
            if method != "GET":
                return 405, "error: use GET /status.\n", "text/plain"
            robot = query.get("robot") or self._http_session("").robot
            if not _valid_robot(robot):
                return 400, f"error: {robot[:40]!r} is not a robot id.\n", "text/plain"
            status = self.dispatcher.board.json(robot)
            status["clients"] = len(self._clients)
            return 200, json.dumps(status), "application/json"
        if path == "/command":
            if method != "POST":
                return 405, "error: POST the command to /command (text/plain, or JSON {\"command\": ...}).\n", \
                    "text/plain"
            return await self._command_http(query, headers, body)
        if path == "/" and method == "GET":
            return 200, ("asterics_bridge: POST /command (text/plain or JSON {\"command\": \"forward\"}), "
                         "GET /status.\n" + vocab.help_text() + "\n"), "text/plain"
        return 404, "error: the bridge serves POST /command and GET /status.\n", "text/plain"

    async def _command_http(self, query: dict[str, str], headers: dict[str, str],
                            body: bytes) -> tuple[int, str, str]:
        ctype = headers.get("content-type", "text/plain").split(";")[0].strip().lower()
        as_json = ctype == "application/json" or "application/json" in headers.get("accept", "")
        robot = query.get("robot", "")
        if ctype not in ("text/plain", "application/json", "application/x-www-form-urlencoded", ""):
            return 415, f"error: send the command as text/plain or application/json, not {ctype[:40]}.\n", \
                "text/plain"
        try:
            text = body.decode("utf-8")
        except UnicodeDecodeError:
            return _http_reply(Reply(False, "The body is not UTF-8 text; send a command such as 'forward'.",
                                     "bad_request"), as_json)
        if ctype == "application/json":
            try:
                data = json.loads(text)
            except ValueError:
                return _http_reply(Reply(False, "The body is not valid JSON; send {\"command\": \"forward\"}.",
                                         "bad_request"), as_json)
            if isinstance(data, dict):
                robot = data.get("robot") or robot
                data = data.get("command")
            if not isinstance(data, str) or not isinstance(robot, str):
                return _http_reply(Reply(False, "Send JSON {\"command\": \"forward\"} (and optionally "
                                                "\"robot\": \"pioneer-sim\").", "bad_request"), as_json)
            text = data
        if robot and not _valid_robot(robot):
            return _http_reply(Reply(False, f"{robot[:40]!r} is not a robot id.", "bad_request"), as_json)
        pool = self._stop_pool if _is_stop(text) else None
        return _http_reply(await self._execute(self._http_session(robot), text.strip(), pool), as_json)

    def _http_session(self, robot: str) -> Session:
        """HTTP is stateless: requests share one session per `?robot=` (none: the default one,
        which `robot <id>` switches)."""
        session = self._http_sessions.get(robot)
        if session is None:
            session = self._http_sessions[robot] = self.dispatcher.open_session(f"http:{robot or 'default'}")
            session.authorized = True     # the HTTP layer checks the token of every request
            if robot:
                session.robot = robot
        return session


def _is_stop(text: str) -> bool:
    try:
        return vocab.parse(text).word == "stop"
    except vocab.NotUnderstood:
        return False


def _valid_robot(robot: str) -> bool:
    try:
        keys.robot(robot)
        return True
    except ValueError:
        return False


def _http_reply(reply: Reply, as_json: bool) -> tuple[int, str, str]:
    status = _REPLY_STATUS.get(reply.code, 409)
    if as_json:
        data = {"ok": reply.ok, "text": reply.text} if reply.ok else {"ok": False, "error": reply.text,
                                                                      "code": reply.code}
        return status, json.dumps(data), "application/json"
    return status, reply.line() + "\n", "text/plain"


def _respond(writer: asyncio.StreamWriter, status: int, content: str, *, keep: bool, ctype: str = "text/plain",
             extra: dict[str, str] | None = None) -> None:
    body = content.encode("utf-8")
    headers = {"Content-Type": f"{ctype}; charset=utf-8", "Content-Length": str(len(body)),
               "Connection": "keep-alive" if keep else "close", "Cache-Control": "no-store", **CORS,
               **(extra or {})}
    head = f"HTTP/1.1 {status} {HTTP_STATUS.get(status, 'Error')}\r\n" + "".join(
        f"{k}: {v}\r\n" for k, v in headers.items()) + "\r\n"
    writer.write(head.encode("latin-1") + body)


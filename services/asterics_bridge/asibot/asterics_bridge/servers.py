"""The bridge's sockets: one TCP port for NetConnection and text clients, one HTTP port.

Both run on one asyncio loop in a thread of their own; commands run on a small thread pool
(`Dispatcher.execute` makes blocking RPC calls), one at a time per client, in order, except
`stop`, which never waits behind a slow command. Nothing a client does can block another:
- what goes out to a client is written without waiting; a client whose unsent output passes
  `Limits.send_buffer` bytes (it never reads) is dropped;
- a client with more than `Limits.queued_commands` commands waiting gets "busy" for the extra;
- half frames wait for their rest without blocking anything; bad frames are answered and
  skipped; a client sending `Limits.bad_frames` bad frames is dropped;
- a connection must send its first whole frame or line within `Limits.first_item_s`, and
  finish any frame or line it starts within `Limits.partial_s` (a client sending only `@`
  holds nothing for long); a NetConnection plugin sends a keepalive after 9 s of silence;
- beyond `Limits.max_clients`, or `Limits.per_address` from one address, a new client is
  told so and closed, but a `stop` it sends first is obeyed (a full bridge still stops);
- HTTP headers, bodies and idle keep-alive connections are bounded.
When a client goes away, its command in flight finishes first, then the dispatcher stops a
motion it started (`Dispatcher.close_session`).

Only the bridge's own users: the TCP port closes a connection that starts like HTTP (a web
page's fetch or WebSocket) before any line of it runs; the HTTP port answers only to its own
Host names and to callers that are no browser page or an allowed origin
(asibot.local_http, as the web page's server), and needs its token (`http_token`) for all but
`stop`.
"""

from __future__ import annotations

import asyncio
import base64
import concurrent.futures
import hmac
import json
import logging
import re
import socket
import threading
import time
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from asibot import keys
from asibot.local_http import Callers

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
#: What a preflight of an allowed origin is told (Access-Control-Allow-Origin names the origin).
CORS_PREFLIGHT = {"Access-Control-Allow-Methods": "GET, POST, OPTIONS",
                  "Access-Control-Allow-Headers": "content-type, authorization, accept",
                  "Access-Control-Max-Age": "600"}
#: A request line of HTTP/1.x (`POST /command HTTP/1.1`): a browser's fetch, form or WebSocket.
HTTP = "http"      # what a TCP client that starts like HTTP speaks
HTTP_REQUEST_LINE = re.compile(r"[A-Za-z]{1,20} \S+ HTTP/\d(\.\d)?")


@dataclass(frozen=True)
class Limits:
    """What one client may take, so that no client (nor a web page) can take the bridge from
    the others; tests make them small."""
    max_clients: int = 100
    per_address: int = 50               # TCP clients from one address (on loopback: every local one)
    first_item_s: float = 15.0          # to send the first whole frame or line (the plugin: a keepalive after 9 s)
    partial_s: float = 5.0              # to finish a frame or line once started
    refused_waiting: int = 200          # clients over the limits given a moment to send a stop
    refused_wait_s: float = 2.0         # how long such a client may take to send it
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

    def __init__(self, bridge: "Servers", writer: asyncio.StreamWriter, session: Session, address: str) -> None:
        self.bridge, self.writer, self.session, self.address = bridge, writer, session, address
        self.protocol: str | None = None
        self.spoke = False            # a whole frame or line came
        self.last_sent = time.monotonic()
        self.queue: asyncio.Queue[str | None] = asyncio.Queue()     # None: the client went away
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
        self.send(_encode_reply(self.protocol, reply))

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
                 limits: Limits = Limits(), http_token: str | None = None, callers: Callers = Callers()) -> None:
        """`http_token`: what every HTTP request but a stop must carry (None: nothing; the
        service always passes one unless started --no-token); `callers`: the Host names and
        foreign origins the HTTP port answers to (by default loopback names, no foreign page)."""
        self.dispatcher, self.host, self.limits = dispatcher, host, limits
        self.tcp_port, self.http_port = tcp_port, http_port
        self.http_token, self.callers = http_token, callers
        self.events = dict(events or {})
        self.counters = {"connections": 0, "refused_full": 0, "refused_address": 0, "stops_when_full": 0,
                         "closed_idle": 0, "refused_http_like": 0, "refused_bad_first_line": 0, "dropped_slow": 0,
                         "dropped_bad": 0, "bad_frames": 0, "http_requests": 0, "refused_host": 0,
                         "refused_origin": 0, "refused_token": 0}
        self._clients: set[_Client] = set()
        self._waiting = 0              # clients over the limits, given a moment to send a stop
        self._http_sessions: dict[str, Session] = {}
        self._http_writers: set[asyncio.StreamWriter] = set()     # keep-alive connections, closed with the bridge
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
            for writer in list(self._http_writers):
                writer.transport.abort()
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
        host, port = writer.get_extra_info("peername")[:2]
        peer, address = f"{host}:{port}", str(host)
        sock = writer.get_extra_info("socket")
        if self.limits.sndbuf and sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.limits.sndbuf)
        handler = asyncio.current_task()
        if handler is not None:      # always: asyncio's servers run each connection as a task
            self._handlers.add(handler)
            handler.add_done_callback(self._handlers.discard)
        refusal = self._slot_refusal(address)
        if refusal is not None:
            await self._refuse(reader, writer, peer, refusal)
            return
        self.counters["connections"] += 1
        session = self.dispatcher.open_session(peer)
        client = _Client(self, writer, session, address)

        def notify(notice: Notice) -> None:
            self._loop.call_soon_threadsafe(client.notice, notice)

        session.notify = notify
        self._clients.add(client)
        worker = asyncio.ensure_future(self._work(client))
        try:
            await self._read(reader, client)
        except (ConnectionError, OSError):
            pass
        finally:
            self._clients.discard(client)
            client.closed = True
            # what it sent before it went runs, in order (a motion it starts must be known
            # before the stop); then the worker ends
            client.queue.put_nowait(None)
            await asyncio.wait([worker])
            await self._loop.run_in_executor(self._pool, self.dispatcher.close_session, session)
            writer.close()

    def _slot_refusal(self, address: str) -> str | None:
        """Why a new client from `address` gets no slot, or None when it does: the bridge is
        full, or that address holds its share (on loopback every local program is one address)."""
        if len(self._clients) >= self.limits.max_clients:
            self.counters["refused_full"] += 1
            return f"the bridge serves {self.limits.max_clients} clients at most; try again later."
        held = sum(1 for c in self._clients if c.address == address)
        if held >= self.limits.per_address:
            self.counters["refused_address"] += 1
            return (f"{address} holds {held} connections to the bridge already, the most one address may; "
                    "close one of them, or try again later.")
        return None

    async def _refuse(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: str,
                      refusal: str) -> None:
        """Turn a client away, but obey a `stop` it sends at once: whoever needs to stop the
        robot must never find the bridge full. Then the sentence (a line, or a frame once the
        client spoke NetConnection), and close."""
        log.warning("refusing %s: %s", peer, refusal)
        protocol: str | None = None
        if self._waiting < self.limits.refused_waiting:
            self._waiting += 1
            try:
                protocol, item = await asyncio.wait_for(self._first_item(reader), self.limits.refused_wait_s)
            except (asyncio.TimeoutError, ConnectionError, OSError):
                item = None
            finally:
                self._waiting -= 1
            if protocol == HTTP:
                self._refuse_http(writer)
                writer.close()
                return
            text = self._stop_text(item)
            if text is not None:
                self.counters["stops_when_full"] += 1
                session = self.dispatcher.open_session(peer)
                try:
                    writer.write(_encode_reply(protocol, await self._execute(session, text, self._stop_pool)))
                finally:
                    await self._loop.run_in_executor(self._stop_pool, self.dispatcher.close_session, session)
        writer.write(_encode_reply(protocol, Reply(False, refusal, "busy")))
        writer.close()

    async def _first_item(self, reader: asyncio.StreamReader) -> tuple[str | None, object]:
        """The protocol of a refused client and its first frame or line (HTTP for a request
        line of HTTP); (protocol, None) when it closes first."""
        head, protocol = b"", None
        while protocol is None:
            data = await reader.read(4096)
            if not data:
                return None, None
            head += data
            protocol = lines.sniff(head)
        decoder = _decoder(protocol)
        data = head
        while data:
            items = decoder.feed(data)
            if items:
                return (HTTP, items[0]) if _looks_like_http(protocol, items[0]) else (protocol, items[0])
            data = await reader.read(4096)
        return protocol, None

    def _stop_text(self, item: object) -> str | None:
        """The command of `item` when it is a stop (a line, a string frame, an event mapped to stop)."""
        text: object = item
        if isinstance(item, nc.Frame):
            text = {nc.STRING: item.value, nc.EVENT: self.events.get(item.port)}.get(item.kind)
        return text if isinstance(text, str) and _is_stop(text) else None

    def _refuse_http(self, writer: asyncio.StreamWriter) -> None:
        """A connection that starts like HTTP is a web page (fetch, form, WebSocket) or a
        misdirected client: it is answered in HTTP, without CORS, and no line of it runs."""
        self.counters["refused_http_like"] += 1
        log.warning("refused a connection to the TCP port that starts like HTTP (a web page, or a misdirected client)")
        where = f" ({self.http_port})" if self.http_port else ""
        _respond(writer, 400, "error: this is the AsTeRICS bridge's port for NetConnection frames and text lines, "
                              f"not HTTP; HTTP clients use its HTTP port{where}.\n", keep=False)

    async def _read(self, reader: asyncio.StreamReader, client: _Client) -> None:
        started = time.monotonic()
        partial_since: float | None = None     # when the frame or line still unfinished began
        head = b""
        while client.protocol is None:
            data = await self._receive(reader, client, started, started if head else None)
            if not data:
                return
            head += data
            client.protocol = lines.sniff(head)
        decoder = _decoder(client.protocol)
        data = head
        while data and not client.closed:
            items = decoder.feed(data)
            for item in items:
                if client.closed:
                    return
                if not client.spoke:
                    if _looks_like_http(client.protocol, item):
                        client.closed = True
                        self._refuse_http(client.writer)
                        return
                    if isinstance(item, lines.BadLine):
                        # a request line too long to read (a page's long URL) could be HTTP:
                        # none of what follows it may run
                        self.counters["refused_bad_first_line"] += 1
                        client.answer(Reply(False, f"{item.text} A connection must start with a command; "
                                                   "this one is closed.", "bad_request"))
                        client.closed = True
                        return
                    client.spoke = True
                self._take(client, item)
            now = time.monotonic()
            if not decoder.partial():
                partial_since = None
            elif items or partial_since is None:
                partial_since = now
            data = await self._receive(reader, client, started, partial_since)

    async def _receive(self, reader: asyncio.StreamReader, client: _Client, started: float,
                       partial_since: float | None) -> bytes:
        """The next bytes, or b"" (close) once the client is late: its first whole frame or line
        after `Limits.first_item_s`, the rest of one it began after `Limits.partial_s`."""
        deadlines = [] if client.spoke else [(started + self.limits.first_item_s,
                                              f"nothing whole came in {self.limits.first_item_s:g} s")]
        if partial_since is not None:
            deadlines.append((partial_since + self.limits.partial_s,
                              f"a frame or line was begun and not finished in {self.limits.partial_s:g} s"))
        if not deadlines:
            return await reader.read(4096)
        deadline, why = min(deadlines)
        try:
            return await asyncio.wait_for(reader.read(4096), max(0.0, deadline - time.monotonic()))
        except asyncio.TimeoutError:
            self.counters["closed_idle"] += 1
            log.info("closing %s: %s", client.session.peer, why)
            client.answer(Reply(False, f"This connection is closed: {why}. Connect again and send a whole "
                                       "command at once (a line, or a NetConnection frame).", "timeout"))
            client.closed = True
            return b""

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
            if isinstance(item.value, str):      # always, for a string frame
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
            if text is None:
                return
            client.in_flight = asyncio.ensure_future(self._execute(client.session, text))
            # shielded: should the bridge cancel this worker as it closes, the command still finishes
            reply = await asyncio.shield(client.in_flight)
            client.in_flight = None
            client.answer(reply)

    # ------------------------------------------------------------------ HTTP
    async def _serve_http(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        handler = asyncio.current_task()
        if handler is not None:      # always: asyncio's servers run each connection as a task
            self._handlers.add(handler)
            handler.add_done_callback(self._handlers.discard)
        self._http_writers.add(writer)
        try:
            for _ in range(self.limits.http_requests):
                keep = await self._http_request(reader, writer)
                await writer.drain()
                if not keep:
                    break
        except (ConnectionError, OSError, asyncio.IncompleteReadError):
            pass
        finally:
            self._http_writers.discard(writer)
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
        refusal = self._caller_refusal(headers)
        if refusal is not None:     # no CORS headers: the page learns nothing, not even this
            _respond(writer, refusal[0], f"error: {refusal[1]}\n", keep=False)
            return False
        keep = version == "HTTP/1.1" and headers.get("connection", "").lower() != "close"
        cors = self._cors(headers)
        url = urlsplit(target)
        query = {k: v[0] for k, v in parse_qs(url.query).items()}
        if method == "OPTIONS":
            _respond(writer, 204, "", keep=keep, extra=_preflight(cors, headers))
            return keep
        body = b""
        if "transfer-encoding" in headers:
            _respond(writer, 411, "error: send the body with a Content-Length, not chunked.\n", keep=False, extra=cors)
            return False
        if "content-length" in headers:
            try:
                length = int(headers["content-length"])
                if length < 0:
                    raise ValueError
            except ValueError:
                _respond(writer, 400, "error: Content-Length is not a size.\n", keep=False, extra=cors)
                return False
            if length > self.limits.http_body_bytes:
                _respond(writer, 413, f"error: a command is at most {self.limits.http_body_bytes} bytes; "
                                      f"this body has {length}.\n", keep=False, extra=cors)
                return False
            try:
                body = await asyncio.wait_for(reader.readexactly(length), self.limits.http_idle_s)
            except asyncio.TimeoutError:
                _respond(writer, 408, "error: the body did not come in time.\n", keep=False, extra=cors)
                return False
        authorized = self._authorized(headers, query)
        if not authorized and not self._stop_request(method, url.path, query, headers, body):
            self.counters["refused_token"] += 1
            _respond(writer, 401, "error: this bridge needs its access token: add 'Authorization: Bearer <token>' "
                                  "(or Basic auth with the token as password, as AsTeRICS-Grid's HTTP action sends "
                                  "it, or ?token=). `python -m asibot.asterics_bridge.http_token` prints it; "
                                  "a stop needs none.\n",
                     keep=keep, extra={**cors, "WWW-Authenticate": 'Basic realm="asterics_bridge"'})
            return keep
        status, content, ctype = await self._route(method, url.path, query, headers, body, authorized)
        _respond(writer, status, content, keep=keep, ctype=ctype, extra=cors)
        return keep

    def _caller_refusal(self, headers: dict[str, str]) -> tuple[int, str] | None:
        """(status, sentence) for a request by a name that is not this bridge's (DNS rebinding)
        or from a web page of an origin the user did not allow; None for the bridge's users."""
        wrong_host = self.callers.host_refusal(headers.get("host"))
        if wrong_host is not None:
            self.counters["refused_host"] += 1
            log.warning("refused an HTTP request: %s", wrong_host)
            return 400, wrong_host
        stranger = self.callers.caller_refusal(headers, "http")
        if stranger is not None:
            self.counters["refused_origin"] += 1
            # the page cannot read why (no CORS header): the log is where its user finds out
            log.warning("refused an HTTP request: %s", stranger)
            return 403, stranger + " Its owner allows an origin with --allow-origin (ASIBOT_ASTERICS_ORIGINS)."
        return None

    def _cors(self, headers: dict[str, str]) -> dict[str, str]:
        """The CORS header of an answer to an allowed page: its own origin named, never '*'
        (no page of an origin the user did not allow gets this far)."""
        origin = headers.get("origin")
        return {"Access-Control-Allow-Origin": origin} if origin else {}

    def _authorized(self, headers: dict[str, str], query: dict[str, str]) -> bool:
        token = self.http_token
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

    def _stop_request(self, method: str, path: str, query: dict[str, str], headers: dict[str, str],
                      body: bytes) -> bool:
        """Whether this is `POST /command` of a stop: obeyed without the token, since stopping
        is always safe and whoever needs it may not have the token at hand."""
        if method != "POST" or (path.rstrip("/") or "/") != "/command":
            return False
        parsed = _command_of(query, headers, body)
        return isinstance(parsed, tuple) and len(parsed) == 2 and _is_stop(parsed[1])

    async def _route(self, method: str, path: str, query: dict[str, str], headers: dict[str, str],
                     body: bytes, authorized: bool = True) -> tuple[int, str, str]:
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
            return await self._command_http(query, headers, body, authorized)
        if path == "/" and method == "GET":
            return 200, ("asterics_bridge: POST /command (text/plain or JSON {\"command\": \"forward\"}), "
                         "GET /status.\n" + vocab.help_text() + "\n"), "text/plain"
        return 404, "error: the bridge serves POST /command and GET /status.\n", "text/plain"

    async def _command_http(self, query: dict[str, str], headers: dict[str, str], body: bytes,
                            authorized: bool) -> tuple[int, str, str]:
        parsed = _command_of(query, headers, body)
        if len(parsed) == 3:
            return parsed
        robot, text = parsed
        if not authorized:      # a stop without the token: it leaves no session behind
            return _http_reply(await self._stop_once(robot or self._http_session("").robot, text), _wants_json(headers))
        pool = self._stop_pool if _is_stop(text) else None
        return _http_reply(await self._execute(self._http_session(robot), text.strip(), pool), _wants_json(headers))

    async def _stop_once(self, robot: str, text: str) -> Reply:
        """A stop of `robot` in a session of its own, closed after it."""
        session = self.dispatcher.open_session(f"http:stop:{robot}")
        session.robot = robot
        try:
            return await self._execute(session, text.strip(), self._stop_pool)
        finally:
            await self._loop.run_in_executor(self._stop_pool, self.dispatcher.close_session, session)

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


def _decoder(protocol: str) -> nc.Decoder | lines.LineDecoder:
    return nc.Decoder() if protocol == lines.NETCONNECTION else lines.LineDecoder()


def _looks_like_http(protocol: str | None, item: object) -> bool:
    """Whether the first line of a text client is an HTTP request line: a web page's fetch to
    this port would otherwise have its body's lines run as commands."""
    return protocol == lines.TEXT and isinstance(item, str) and HTTP_REQUEST_LINE.fullmatch(item.strip()) is not None


def _encode_reply(protocol: str | None, reply: Reply) -> bytes:
    """A reply as the client reads it: a string frame on the reply port, or a line (also
    before the protocol is known: a line is what both kinds can read)."""
    if protocol == lines.NETCONNECTION:
        return nc.encode_string(REPLY_PORT, reply.frame_text())
    return lines.encode_line(reply.line())


#: The fields of a JSON command.
JSON_FIELDS = ("command", "robot")


def _wants_json(headers: dict[str, str]) -> bool:
    ctype = headers.get("content-type", "text/plain").split(";")[0].strip().lower()
    return ctype == "application/json" or "application/json" in headers.get("accept", "")


def _command_of(query: dict[str, str], headers: dict[str, str], body: bytes) -> tuple[str, str] | tuple[int, str, str]:
    """The (robot, command text) of a POST /command, or the answer (status, content, type)
    to a body that is not one: bad input is refused whole and changes nothing."""
    ctype = headers.get("content-type", "text/plain").split(";")[0].strip().lower()
    as_json = _wants_json(headers)
    robot = query.get("robot", "")
    if ctype not in ("text/plain", "application/json", "application/x-www-form-urlencoded", ""):
        return 415, f"error: send the command as text/plain or application/json, not {ctype[:40]}.\n", "text/plain"
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
        problem = _json_problem(data)
        if problem:
            return _http_reply(Reply(False, problem, "bad_request"), as_json)
        if isinstance(data, dict):
            robot = data.get("robot", robot)
            data = data["command"]
        text = data
    if robot and not _valid_robot(robot):
        return _http_reply(Reply(False, f"{robot[:40]!r} is not a robot id.", "bad_request"), as_json)
    return robot, text


def _json_problem(data: object) -> str | None:
    """What is wrong with a JSON command, or None: a string, or an object with a string
    `command` and optionally a robot id `robot`, nothing else (a boolean is not a name)."""
    usage = "Send JSON {\"command\": \"forward\"} (and optionally \"robot\": \"pioneer-sim\")"
    if isinstance(data, str):
        return None
    if not isinstance(data, dict):
        return f"{usage}, not a JSON {type(data).__name__}."
    unknown = sorted(set(data) - set(JSON_FIELDS))
    if unknown:
        return f"{usage}; {', '.join(repr(k[:30]) for k in unknown)} is not a field of a command."
    if not isinstance(data.get("command"), str):
        return f"{usage}: \"command\" must be text, not {_json_kind(data.get('command'))}."
    if "robot" in data and not (isinstance(data["robot"], str) and data["robot"]):
        return f"{usage}: \"robot\" must be a robot id such as \"pioneer-sim\", not {_json_kind(data['robot'])}."
    return None


def _json_kind(value: object) -> str:
    if value is None:
        return "missing or null"
    return {bool: "a boolean", int: "a number", float: "a number", list: "a list", dict: "an object",
            str: "empty text"}.get(type(value), type(value).__name__)


def _preflight(cors: dict[str, str], headers: dict[str, str]) -> dict[str, str]:
    """The answer to a CORS preflight of an allowed origin (nothing for a program); the
    Private Network permission only to a page that asks and that the user allowed."""
    if not cors:
        return {}
    extra = {**cors, **CORS_PREFLIGHT}
    if headers.get("access-control-request-private-network", "").lower() == "true":
        extra["Access-Control-Allow-Private-Network"] = "true"
    return extra


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
               "Connection": "keep-alive" if keep else "close", "Cache-Control": "no-store", "Vary": "Origin",
               **(extra or {})}
    head = f"HTTP/1.1 {status} {HTTP_STATUS.get(status, 'Error')}\r\n" + "".join(
        f"{k}: {v}\r\n" for k, v in headers.items()) + "\r\n"
    writer.write(head.encode("latin-1") + body)


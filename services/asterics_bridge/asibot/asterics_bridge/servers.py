"""The bridge's sockets: one TCP port for NetConnection and text clients, one HTTP port
(`http_app`, served by uvicorn: `http_server`).

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
  holds nothing for long); once it spoke, it must send something (a line, a frame, a
  keepalive) at least every `Limits.idle_s`; a NetConnection plugin sends a keepalive after 9 s
  of silence;
- beyond `Limits.max_clients`, or `Limits.per_address` from one address that is not this
  machine's, the connection silent the longest makes room for a new client (`slots`); only when
  every one has a command under way is the new client told so and closed, and a `stop` it
  sends first is obeyed then (a full bridge still stops);
- HTTP heads, bodies and idle keep-alive connections are bounded (`http_bounds`, `http_server`).
When a client goes away, its command in flight finishes first, then the dispatcher stops a
motion it started (`Dispatcher.close_session`).

Only the bridge's own users: the TCP port closes a connection that starts like HTTP (a web
page's fetch or WebSocket) before any line of it runs; the HTTP port checks its callers
(`http_trust`).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import re
import socket
import threading
import time

from asibot.local_http import Callers

from asibot.asterics_bridge import lines
from asibot.asterics_bridge import netconnection as nc
from asibot.asterics_bridge import slots
from asibot.asterics_bridge import vocabulary as vocab
from asibot.asterics_bridge.dispatcher import Dispatcher, Reply, Session
from asibot.asterics_bridge.http_app import HttpEntry
from asibot.asterics_bridge.http_server import HttpServer
from asibot.asterics_bridge.limits import Limits
from asibot.asterics_bridge.status import Notice

log = logging.getLogger("asibot.asterics_bridge")

#: NetConnection ports of what the bridge sends: the event phrase (+ an event frame for alarms),
#: the answer to each command, the event's whole sentence.
NOTICE_PORT, REPLY_PORT, SENTENCE_PORT = 1, 2, 3
DEFAULT_TCP_PORT, DEFAULT_HTTP_PORT = 21112, 8090
#: A request line of HTTP/1.x (`POST /command HTTP/1.1`): a browser's fetch, form or WebSocket.
HTTP = "http"      # what a TCP client that starts like HTTP speaks
HTTP_REQUEST_LINE = re.compile(r"[A-Za-z]{1,20} \S+ HTTP/\d(\.\d)?")
#: How long `Servers.close` waits for the loop to wind down (the HTTP server's grace, and some).
CLOSE_S = 3.0


class _Client:
    """One TCP client: its session, its protocol, and how to talk back to it."""

    def __init__(self, bridge: "Servers", writer: asyncio.StreamWriter, session: Session, group: str) -> None:
        """`group`: the address it is counted under (`slots.group_of`)."""
        self.bridge, self.writer, self.session, self.group = bridge, writer, session, group
        self.protocol: str | None = None
        self.spoke = False            # a whole frame or line came
        self.heard = self.last_sent = time.monotonic()     # the last whole frame or line came; the last sent
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

    @property
    def busy(self) -> bool:
        """A command of it waits or runs: its answer is due, so it is not idle."""
        return self.in_flight is not None or not self.queue.empty()

    def abort(self) -> None:
        self.closed = True
        self.writer.transport.abort()

    def close(self) -> None:
        """Close once what was written has gone out; a peer that left output unread is cut off
        (its reader then sees the end, and its handler stops what it started)."""
        self.closed = True
        if self.writer.transport.get_write_buffer_size():
            self.writer.transport.abort()
        else:
            self.writer.transport.close()


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
                         "closed_idle": 0, "closed_for_room": 0, "refused_http_like": 0, "refused_bad_first_line": 0,
                         "dropped_slow": 0, "dropped_bad": 0, "bad_frames": 0, "http_requests": 0, "refused_host": 0,
                         "refused_origin": 0, "refused_token": 0}
        self._clients: set[_Client] = set()
        self._waiting = 0              # clients over the limits, given a moment to send a stop
        self._http: HttpServer | None = None
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
            entry = HttpEntry(self.dispatcher, pool=self._pool, stop_pool=self._stop_pool, limits=self.limits,
                              counters=self.counters, clients=self.clients)
            self._http = HttpServer(entry.app(self.http_token, self.callers), self.host, self.http_port, self.limits)
            self.http_port = await self._http.start()
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
            if self._http is not None:
                await self._http.close()
            if self._handlers:
                await asyncio.wait(self._handlers, timeout=1.0)

        if self._thread.is_alive():
            try:
                asyncio.run_coroutine_threadsafe(stop(), self._loop).result(CLOSE_S)
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
        group = slots.group_of(address)
        room = slots.room_for(group, [c for c in self._clients if not c.closed], self.limits)
        if room.refusal is not None:
            self.counters["refused_address" if room.limit == "address" else "refused_full"] += 1
            await self._refuse(reader, writer, peer, room.refusal)
            return
        if room.victim is not None:
            self._make_room(room.victim, room.limit)
        self.counters["connections"] += 1
        session = self.dispatcher.open_session(peer)
        client = _Client(self, writer, session, group)

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

    def _make_room(self, victim: _Client, limit: str) -> None:
        """Close `victim`, the connection silent the longest, so that a new client gets its slot
        (`slots.room_for`): it is told why, and its handler stops what it started."""
        idle = time.monotonic() - victim.heard
        taken = (f"the bridge's {self.limits.max_clients} slots were all taken" if limit == "full" else
                 f"{victim.group} held the {self.limits.per_address} slots one address may")
        self.counters["closed_for_room"] += 1
        log.info("closing %s, silent for %.0f s, to make room for a new client: %s", victim.session.peer, idle,
                 taken)
        silent = f"had been silent the longest ({idle:.1f} s)" if victim.spoke else f"had sent nothing in {idle:.1f} s"
        victim.answer(Reply(False, f"This connection is closed to make room for a new one: {taken}, and this one "
                                   f"{silent}. Connect again when you need the robot.", "busy"))
        self._clients.discard(victim)
        victim.close()

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
        return text if isinstance(text, str) and vocab.is_stop(text) else None

    def _refuse_http(self, writer: asyncio.StreamWriter) -> None:
        """A connection that starts like HTTP is a web page (fetch, form, WebSocket) or a
        misdirected client: it is answered in HTTP, without CORS, and no line of it runs."""
        self.counters["refused_http_like"] += 1
        log.warning("refused a connection to the TCP port that starts like HTTP (a web page, or a misdirected client)")
        where = f" ({self.http_port})" if self.http_port else ""
        body = ("error: this is the AsTeRICS bridge's port for NetConnection frames and text lines, not HTTP; "
                f"HTTP clients use its HTTP port{where}.\n").encode()
        head = (b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: %d\r\n"
                b"Connection: close\r\nCache-Control: no-store\r\nVary: Origin\r\n\r\n" % len(body))
        writer.write(head + body)

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
            if items:
                client.heard = now
            if not decoder.partial():
                partial_since = None
            elif items or partial_since is None:
                partial_since = now
            data = await self._receive(reader, client, started, partial_since)

    async def _receive(self, reader: asyncio.StreamReader, client: _Client, started: float,
                       partial_since: float | None) -> bytes:
        """The next bytes, or b"" (close) once the client is late: its first whole frame or line
        after `Limits.first_item_s`, the rest of one it began after `Limits.partial_s`, anything
        whole after `Limits.idle_s` of silence once it spoke (a slot is not held by a client
        that spoke once and went quiet)."""
        whole = "Connect again and send a whole command at once (a line, or a NetConnection frame)."
        limits = self.limits
        if client.spoke:
            deadlines = [(client.heard + limits.idle_s, f"nothing came for {limits.idle_s:g} s",
                          "Connect again when you need the robot; a program that keeps its connection sends something "
                          f"(an empty line, or NetConnection's keepalive) at least every {limits.idle_s:g} s.")]
        else:
            deadlines = [(started + limits.first_item_s, f"nothing whole came in {limits.first_item_s:g} s", whole)]
        if partial_since is not None:
            deadlines.append((partial_since + limits.partial_s,
                              f"a frame or line was begun and not finished in {limits.partial_s:g} s", whole))
        deadline, why, advice = min(deadlines)
        try:
            return await asyncio.wait_for(reader.read(4096), max(0.0, deadline - time.monotonic()))
        except asyncio.TimeoutError:
            self.counters["closed_idle"] += 1
            log.info("closing %s: %s", client.session.peer, why)
            client.answer(Reply(False, f"This connection is closed: {why}. {advice}", "timeout"))
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
        if vocab.is_stop(text):   # never waits behind a slow command
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

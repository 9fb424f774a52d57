"""The bridge on the in-memory bus against the doubles, with clients on loopback sockets."""

from __future__ import annotations

import socket
import threading

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.local_http import Callers
from asibot.testing import Inbox, wait_until

from asibot.asterics_bridge import netconnection as nc
from asibot.asterics_bridge.dispatcher import DEFAULT_EVENTS, Dispatcher
from asibot.asterics_bridge.servers import Limits, Servers

from .fakes import FakeArm, FakeNav, FakeTasks

ROBOT = "pioneer-sim"
OTHER = "asibot-sim"
#: The HTTP token of the test bridges (the service makes a random one and keeps it).
HTTP_TOKEN = "grid-s3cret"


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


class Bridge:
    """Doubles of nav (pioneer-sim), two arms (pioneer-sim, asibot-sim) and the tasks, the
    dispatcher, and (`sockets=True`) its servers on free loopback ports. `token`: what TCP
    clients must give (--token); `http_token`: what HTTP requests must carry; `origins`: the
    web pages allowed to call the HTTP port, `hosts` the names it answers to besides loopback."""

    def __init__(self, endpoint: str, *, sockets: bool = True, limits: Limits = Limits(),
                 token: str | None = None, http_token: str | None = HTTP_TOKEN, origins: tuple[str, ...] = (),
                 hosts: tuple[str, ...] = (), longest: float = 60.0, clock=None) -> None:
        self.bus = Bus("test", endpoint)
        self.svc_bus = Bus("asterics_bridge", endpoint)
        self.nav = FakeNav(self.bus, ROBOT)
        self.arm = FakeArm(self.bus, ROBOT)
        self.other_arm = FakeArm(self.bus, OTHER)
        self.tasks = FakeTasks(self.bus)
        self.clock = clock or Clock()
        self.dispatcher = Dispatcher(self.svc_bus, ROBOT, longest=longest, token=token, clock=self.clock)
        self.events = {robot: self.bus.publisher(keys.events(robot), m.Event) for robot in (ROBOT, OTHER)}
        self.cmd_vel = Inbox()
        self.bus.subscribe(keys.base_cmd_vel(ROBOT), m.Twist, self.cmd_vel)
        self.servers = Servers(self.dispatcher, tcp_port=0, http_port=0, events=DEFAULT_EVENTS, limits=limits,
                               http_token=http_token, callers=Callers(hosts, origins)).start() if sockets else None

    def event(self, code: str, text: str, level: str = "warning", robot: str = ROBOT) -> None:
        self.events[robot].put(m.Event(level=level, code=code, text=text))

    def estop(self, engaged: bool, robot: str = ROBOT) -> None:
        self.bus.latch(keys.estop(robot), m.EStop(engaged=engaged, reason="test", by="test"))

    def close(self) -> None:
        if self.servers is not None:
            self.servers.close()
        self.dispatcher.close()
        self.svc_bus.close()
        self.bus.close()


class Client:
    """A TCP client with a reader thread: NetConnection frames or text lines."""

    def __init__(self, port: int, *, rcvbuf: int | None = None, read: bool = True, source: str | None = None) -> None:
        """`source`: the loopback address to connect from (127.0.0.2: another client address)."""
        self.sock = socket.socket()
        if source:
            self.sock.bind((source, 0))
        if rcvbuf:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock.connect(("127.0.0.1", port))
        self.raw = bytearray()
        self.closed = False
        self._lock = threading.Lock()
        if read:
            threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        try:
            while True:
                data = self.sock.recv(65536)
                if not data:
                    break
                with self._lock:
                    self.raw += data
        except OSError:
            pass
        self.closed = True

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def bytes(self) -> bytes:
        with self._lock:
            return bytes(self.raw)

    def frames(self) -> list:
        return nc.Decoder().feed(self.bytes())

    def strings(self, port: int) -> list[str]:
        return [f.value for f in self.frames() if isinstance(f, nc.Frame) and f.kind == "string" and f.port == port]

    def lines(self) -> list[str]:
        return self.bytes().decode("utf-8", "replace").splitlines()

    def wait_string(self, port: int, count: int = 1, timeout: float = 5.0) -> list[str]:
        wait_until(lambda: len(self.strings(port)) >= count, timeout,
                   message=f"fewer than {count} strings on port {port}: {self.frames()}")
        return self.strings(port)

    def wait_lines(self, count: int, timeout: float = 5.0) -> list[str]:
        wait_until(lambda: len(self.lines()) >= count, timeout, message=f"fewer than {count} lines: {self.lines()}")
        return self.lines()

    def close(self) -> None:
        """Disconnect for real: a plain close() while the reader thread sits in recv() leaves
        the connection open on Linux (no FIN is sent until that recv returns)."""
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        try:
            self.sock.close()
        except OSError:
            pass


def command(client: Client, text: str, port: int = 1, timeout: float = 5.0) -> str:
    """Send a NetConnection command and return its answer (port 2)."""
    before = len(client.strings(2))
    client.send(nc.encode_string(port, text))
    return client.wait_string(2, before + 1, timeout)[before]


def say(client: Client, text: str, timeout: float = 5.0) -> str:
    """Send a text command and return its answer line."""
    before = len([ln for ln in client.lines() if ln.startswith(("ok", "error"))])
    client.send(text.encode() + b"\n")
    wait_until(lambda: len([ln for ln in client.lines() if ln.startswith(("ok", "error"))]) > before, timeout,
               message=f"no answer to {text!r}: {client.lines()}")
    return [ln for ln in client.lines() if ln.startswith(("ok", "error"))][before]


class Busy:
    """TCP clients (NetConnection) each with a `grab` under way, held until `release()`: they
    are not idle, so no newcomer takes their slots."""

    def __init__(self, bridge: Bridge, clients: list[Client]) -> None:
        self.gate, self.clients = threading.Event(), clients
        act = bridge.arm._act
        bridge.arm._act = lambda req: (self.gate.wait(10), act(req))[1]
        for c in clients:
            command(c, "status")
            c.send(nc.encode_string(1, "grab"))
        wait_until(lambda: bridge.arm.verbs().count("act") == len(clients), 5,
                   message=lambda: f"not every grab is under way: {bridge.arm.verbs()}")

    def release(self) -> None:
        self.gate.set()

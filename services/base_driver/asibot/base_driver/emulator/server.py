"""Serves one EmulatedP3at in real time on a TCP port (as MobileSim and ser2net do) or a pty.

The cable is the connection: the controller keeps its state (pose, setpoints, watchdog)
when a client disconnects, as a real robot does when its cable is pulled. Line faults
(silence, garbage, dropped bytes, a pulled cable) are injected with methods.
"""

from __future__ import annotations

import logging
import os
import select
import socket
import threading
import time
import tty
from typing import Callable

from asibot.base_driver.emulator.robot import EmulatedP3at

log = logging.getLogger("asibot.base_driver.emulator")

LOOP_PERIOD = 0.005


class ArcosEmulator:
    """Serves one EmulatedP3at in real time on a TCP port and optionally a pty."""

    def __init__(self, robot: EmulatedP3at | None = None, listen: tuple[str, int] = ("127.0.0.1", 0),
                 pty_link: str | None = None, clock: Callable[[], float] = time.monotonic,
                 garbage_every: float = 0.0) -> None:
        self.robot = robot or EmulatedP3at()
        self.clock = clock
        self.lock = threading.RLock()
        self._server = socket.create_server(listen, reuse_port=False)
        self._server.setblocking(False)
        self._conn: socket.socket | None = None
        self._pty_master: int | None = None
        self._pty_link = pty_link
        if pty_link:
            self._open_pty(pty_link)
        self._silent_until = 0.0
        self._unplugged_until = 0.0
        self._drop = 0
        self._garbage = bytearray()
        self._garbage_every = garbage_every
        self._next_garbage = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.connections = 0
        self.bytes_out = 0

    # ------------------------------------------------------------ lifecycle
    @property
    def address(self) -> tuple[str, int]:
        return self._server.getsockname()[:2]

    @property
    def url(self) -> str:
        host, port = self.address
        return f"socket://{host}:{port}"

    def start(self) -> "ArcosEmulator":
        self._thread = threading.Thread(target=self._loop, name="arcos-emulator", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread:
            self._thread.join(timeout=2.0)
        self._drop_connection()
        self._server.close()
        if self._pty_master is not None:
            os.close(self._pty_master)
            self._pty_master = None
        if self._pty_link and os.path.islink(self._pty_link):
            os.unlink(self._pty_link)

    def __enter__(self) -> "ArcosEmulator":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ fault injection
    def go_silent(self, seconds: float) -> None:
        """The controller hangs: no SIPs, no echoes, input ignored, for `seconds`."""
        with self.lock:
            self._silent_until = self.clock() + seconds

    def inject_garbage(self, count: int = 32, data: bytes | None = None) -> None:
        """Put junk on the line (between packets), including stray FA FB headers."""
        junk = data if data is not None else _garbage(count)
        with self.lock:
            self._garbage += junk

    def drop_bytes(self, count: int) -> None:
        """Lose the next `count` bytes the controller sends (a flaky cable)."""
        with self.lock:
            self._drop += max(0, int(count))

    def pull_cable(self, seconds: float) -> None:
        """Disconnect the client now and refuse connections (a pty goes dead) for `seconds`.

        The robot keeps going on its last setpoint until its own watchdog stops it.
        """
        with self.lock:
            self._unplugged_until = self.clock() + seconds
            self._drop_connection()

    def status(self) -> dict:
        with self.lock:
            r = self.robot
            return {"open": r.is_open, "motors_enabled": r.motors_enabled, "vel_mm_s": r.vel,
                    "rot_deg_s": r.rot, "target_vel_mm_s": r.target_vel, "target_rot_deg_s": r.target_rot,
                    "x": r.pose.x, "y": r.pose.y, "theta": r.pose.theta,
                    "watchdog_tripped": r.watchdog_tripped, "stalled": r.stalled,
                    "connected": self._conn is not None, "connections": self.connections}

    # ------------------------------------------------------------ the loop
    def _loop(self) -> None:
        while not self._stop.is_set():
            fds: list = [self._server]
            if self._conn is not None:
                fds.append(self._conn)
            if self._pty_master is not None:
                fds.append(self._pty_master)
            try:
                readable, _, _ = select.select(fds, [], [], LOOP_PERIOD)
            except (OSError, ValueError):
                readable = []
            with self.lock:
                now = self.clock()
                for r in readable:
                    if r is self._server:
                        self._accept(now)
                    else:
                        self._read(r, now)
                self._maybe_garbage(now)
                self._send(self.robot.step(now), now)

    def _accept(self, now: float) -> None:
        try:
            conn, _ = self._server.accept()
        except (BlockingIOError, OSError):
            return
        if now < self._unplugged_until:
            conn.close()        # nothing at the other end of the cable
            return
        self._drop_connection()
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._conn = conn
        self.connections += 1

    def _read(self, src, now: float) -> None:
        try:
            data = os.read(src, 4096) if isinstance(src, int) else src.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            if not isinstance(src, int):
                self._drop_connection()
            return
        if now < self._silent_until or now < self._unplugged_until:
            return
        self._send(self.robot.receive(data, now), now)

    def _maybe_garbage(self, now: float) -> None:
        if self._garbage_every > 0 and now >= self._next_garbage:
            self._next_garbage = now + self._garbage_every
            self._garbage += _garbage(16)

    def _send(self, data: bytes, now: float) -> None:
        if self._garbage:
            data = bytes(self._garbage) + data
            self._garbage.clear()
        if not data or now < self._silent_until or now < self._unplugged_until:
            return
        if self._drop:
            cut = min(self._drop, len(data))
            self._drop -= cut
            data = data[cut:]
            if not data:
                return
        if self._conn is not None:
            try:
                self._conn.sendall(data)
                self.bytes_out += len(data)
            except OSError:
                self._drop_connection()
        if self._pty_master is not None:
            try:
                os.write(self._pty_master, data)
            except OSError:
                pass

    def _drop_connection(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.close()
            except OSError:
                pass
            self.robot.disconnect()

    def _open_pty(self, link: str) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        name = os.ttyname(slave)
        if os.path.islink(link):
            os.unlink(link)
        os.symlink(name, link)
        self._pty_master = master
        self._pty_slave = slave   # kept open so the master never sees a hang-up
        log.info("pty %s -> %s", link, name)


def _garbage(count: int) -> bytes:
    """Random junk salted with fake headers and impossible counts, the worst a line can do."""
    junk = bytearray(os.urandom(max(0, count)))
    for i in range(0, len(junk) - 2, 7):
        junk[i:i + 2] = b"\xfa\xfb"
    return bytes(junk)

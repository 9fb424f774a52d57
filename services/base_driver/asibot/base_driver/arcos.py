"""The ARCOS client: sync handshake, motion commands with state reflection, keepalive.

A plain class over a `Link`; it knows bytes and firmware units, not Zenoh. The sequence is
that of docs/arcos.md "Connection": SYNC0, SYNC1, SYNC2 each sent after its echo, CLOSE and
restart if a SIP shows the robot still open from an earlier session, then OPEN, PULSE,
ENABLE 1, SONAR 1, and an explicit VEL 0 / RVEL 0 so a reconnect never resumes an old
setpoint (ARCOS resumes the last setpoints when commands come back after its watchdog,
docs/arcos.md "Motion and watchdog").
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from typing import Callable

from asibot.base_driver import codec
from asibot.base_driver.codec import Cmd
from asibot.base_driver.link import Link
from asibot.base_driver.params import RobotParams, for_subclass
from asibot.base_driver.sip import is_sip, parse_sync2

log = logging.getLogger(__name__)

#: ARIA waits up to 1000 ms for each sync reply (docs/arcos.md "Connection").
SYNC_REPLY_TIMEOUT = 1.0
SYNC_ATTEMPTS = 5
#: ARIA's myStateReflectionRefreshTime: resend motion, else PULSE, every 500 ms
#: (docs/arcos.md "Motion and watchdog").
REFLECTION_REFRESH = 0.5
#: p2os pauses one cycle after CLOSE before syncing again (docs/arcos.md "Connection").
CLOSE_PAUSE = 0.2


class ArcosError(RuntimeError):
    """The robot did not answer the protocol as ARCOS should."""


@dataclasses.dataclass(frozen=True)
class Identity:
    """What the SYNC2 reply says about the robot."""

    name: str
    klass: str
    subclass: str


class ArcosClient:
    """One open ARCOS session on one link. Thread-safe writes; reads from one thread."""

    def __init__(self, link: Link, params: RobotParams | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 on_write: Callable[[bytes], None] | None = None) -> None:
        self.link = link
        self.forced_params = params
        self.params: RobotParams | None = params
        self.identity: Identity | None = None
        self.deframer = codec.Deframer()
        self._clock = clock
        self._on_write = on_write
        self._write_lock = threading.Lock()
        self._desired = (0, 0)          # mm/s, deg/s
        self._sent: tuple[int, int] | None = None
        self._last_motion_write = 0.0
        self._last_write = 0.0
        self.writes = 0

    # ------------------------------------------------------------ bytes
    def send(self, packet: bytes) -> None:
        with self._write_lock:
            self.link.write(packet)
            self._last_write = self._clock()
            self.writes += 1
        if self._on_write:
            self._on_write(packet)

    def read_payloads(self) -> list[bytes]:
        """Whatever complete, verified packets arrived (waits at most the link's read timeout)."""
        data = self.link.read(1)
        # then drain without waiting (pyserial's socket:// reports in_waiting as 0 or 1)
        while data and len(data) < 4096 and (waiting := self.link.in_waiting):
            data += self.link.read(waiting)
        return list(self.deframer.feed(data)) if data else []

    def _await(self, want: Callable[[bytes], bool], timeout: float) -> bytes | None:
        """Next payload satisfying `want`; a SIP meanwhile means the robot is still open."""
        deadline = self._clock() + timeout
        while self._clock() < deadline:
            for payload in self.read_payloads():
                if want(payload):
                    return payload
                if is_sip(payload):
                    raise _StillOpen()
        return None

    # ------------------------------------------------------------ connection
    def connect(self) -> Identity:
        """Sync, open and enable; raises ArcosError saying what did not answer."""
        last_problem = "no reply"
        for attempt in range(SYNC_ATTEMPTS):
            try:
                identity = self._sync()
            except _StillOpen:
                log.info("robot still open from an earlier session: sending CLOSE and syncing again")
                self.send(codec.command(Cmd.CLOSE))
                time.sleep(CLOSE_PAUSE)
                self.link.reset_input_buffer()
                self.deframer.clear()
                last_problem = "the robot kept streaming SIPs after CLOSE"
                continue
            if identity is None:
                last_problem = "no sync echo"
                continue
            self._open(identity)
            return identity
        raise ArcosError(
            f"the robot did not complete the SYNC0/1/2 handshake in {SYNC_ATTEMPTS} attempts "
            f"({last_problem}); check the cable, the port URL and the baud rate, and that the "
            "robot controller is powered")

    def _sync(self) -> Identity | None:
        for step in (Cmd.SYNC0, Cmd.SYNC1):
            self.send(codec.command(step))
            echo = bytes([step])
            if self._await(lambda p: p == echo, SYNC_REPLY_TIMEOUT) is None:  # _await calls it before the next step
                return None
        self.send(codec.command(Cmd.SYNC2))
        reply = self._await(lambda p: p[:1] == b"\x02" and len(p) > 1, SYNC_REPLY_TIMEOUT)
        if reply is None:
            return None
        try:
            name, klass, subclass = parse_sync2(reply)
        except codec.PacketError as exc:
            raise ArcosError(f"bad SYNC2 reply: {exc}") from None
        return Identity(name, klass, subclass)

    def _open(self, identity: Identity) -> None:
        try:
            self.params = self.forced_params or for_subclass(identity.subclass)
        except ValueError as exc:
            self.send(codec.command(Cmd.CLOSE))
            raise ArcosError(str(exc)) from None
        self.identity = identity
        self.send(codec.command(Cmd.OPEN))
        self.send(codec.command(Cmd.PULSE))
        self.send(codec.command_int(Cmd.ENABLE, 1))
        self.send(codec.command_int(Cmd.SONAR, 1))
        self._sent = None
        self.set_velocity(0, 0)

    def close(self) -> None:
        """Stop, then CLOSE, as p2os shuts down (docs/arcos.md "Connection"); never raises."""
        try:
            self.send(codec.command(Cmd.STOP))
            self.send(codec.command(Cmd.CLOSE))
        except Exception:
            pass
        try:
            self.link.close()
        except Exception:
            pass

    # ------------------------------------------------------------ motion
    @property
    def desired(self) -> tuple[int, int]:
        return self._desired

    def set_velocity(self, vel_mm_s: int, rot_deg_s: int) -> None:
        """Make (VEL, RVEL) the robot's setpoint; sends only what changed (state reflection)."""
        self._desired = (int(vel_mm_s), int(rot_deg_s))
        sent = self._sent
        if sent is None or sent[0] != self._desired[0]:
            self.send(codec.command_int(Cmd.VEL, self._desired[0]))
        if sent is None or sent[1] != self._desired[1]:
            self.send(codec.command_int(Cmd.RVEL, self._desired[1]))
        if sent != self._desired:
            self._last_motion_write = self._clock()
        self._sent = self._desired

    def refresh(self) -> None:
        """Call every cycle: resend a non-zero setpoint every 500 ms, else PULSE (ARIA)."""
        now = self._clock()
        if now - self._last_motion_write >= REFLECTION_REFRESH and self._desired != (0, 0):
            self._sent = None
            self.set_velocity(*self._desired)
        elif now - self._last_write >= REFLECTION_REFRESH:
            self.send(codec.command(Cmd.PULSE))

    def emergency_stop(self) -> None:
        """E_STOP overrides the deceleration limits (docs/arcos.md "Commands"); the setpoint becomes zero."""
        self.send(codec.command(Cmd.E_STOP))
        self._sent = None
        self.set_velocity(0, 0)  # and a zero setpoint, so nothing resumes after it

    def enable_motors(self, on: bool = True) -> None:
        self.send(codec.command_int(Cmd.ENABLE, 1 if on else 0))


class _StillOpen(Exception):
    """A SIP arrived during sync: the controller is still open from an earlier session."""


def to_firmware(vx: float, wz: float) -> tuple[int, int]:
    """cmd_vel in SI to (VEL mm/s, RVEL deg/s), rounded as p2os does (docs/arcos.md "Motion and watchdog")."""
    return int(round(vx * 1000.0)), int(round(math.degrees(wz)))

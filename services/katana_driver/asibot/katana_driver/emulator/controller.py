"""A Katana 300 controller, emulated from the facts of docs/katana.md ("The serial protocol"):
the frames it accepts and answers, its motors moving towards their targets at their speed
limits between mechanical stoppers, and two faults a real one has: a motor that collides
(status MSF_MOTCRASHED until a freeze clears it, when collision detection is on) and a
controller gone silent. It keeps what KNI sets (each motor's PWM limits, gains, crash limits,
acceleration and speed limits; collision detection) for tests to read, and reports a master
and a slave firmware that a test may choose: motor 3's counts per turn are its slave
firmware's (emulator motor 3 of firmware 1.xx turns 94976 counts a turn).

What KNI does not document, the emulator chooses and says so (docs/katana.md, "The emulator").
Time is the caller's clock (`now`, s), so that a test may step it; the line's side is
`serve(fd)` (emulator/line.py).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Callable

from asibot.katana_driver import protocol as p
from asibot.katana_driver.katana import KATANA_300_6M180, MotorParams, UnsupportedController, motors_for

#: The master firmware's (version, revision) the emulator reports; KNI reads a version of 3 or
#: more as a Katana 300's (kmlBase.cpp, checkKatanaType).
FIRMWARE = (4, 0)
#: The slave firmware every motor reports: 2.xx, whose motor 3 turns 81408 counts a turn (the
#: counts of KNI's katana6M180.cfg as shipped). Subversion, revision, type (0: KNI's "position
#: controller", kmlMotBase.cpp init) and subtype are the emulator's choice.
SLAVE_FIRMWARE = p.SlaveFirmware(2, 0, 0, 0, 0)
#: Collision detection after power-on: KNI does not say; the emulator's is off, so that a
#: driver that never switches it on sees no collision.
POWER_ON_COLLISION_DETECTION = p.COLLISION_DETECTION_OFF
#: Speed limit after switching on, counts per 10 ms (KNI's configuration file: maxpspeed_nmp 25).
START_SPEED = 25


@dataclass
class Motor:
    params: MotorParams
    true: float                 # counts in the calibrated frame (where the stoppers are known)
    shift: float = 0.0          # the counter reads true + shift
    target: float = 0.0         # counter frame
    flag: int = p.MCF_OFF
    speed_limit: int = START_SPEED
    crashed: bool = False
    velocity: float = 0.0       # counts per 10 ms, last step
    stops: tuple[int, int] = field(default=(0, 0))
    settings: dict[int, bytes] = field(default_factory=dict)   # 'S' subcommand -> its 3 bytes, last set

    @property
    def counter(self) -> float:
        return self.true + self.shift

    def step(self, dt: float) -> None:
        if self.crashed or self.flag == p.MCF_OFF or dt <= 0:
            self.velocity = 0.0
            return
        lo, hi = self.stops
        want = self.target - self.shift
        top = self.speed_limit * 100.0 * dt
        new = self.true + max(-top, min(top, want - self.true))
        new = min(max(new, lo), hi)          # the mechanical stoppers
        self.velocity = (new - self.true) / dt / 100.0
        self.true = new

    @property
    def status(self) -> int:
        if self.crashed:
            return p.MSF_MOTCRASHED
        if self.flag == p.MCF_OFF:
            return p.MSF_MECHSTOP
        if abs(self.velocity) > 1e-9:
            return p.MSF_NORMOPSTAT
        return p.MSF_DESPOS


class KatanaEmulator:
    """The controller's state and its answers; thread-safe."""

    def __init__(self, positions: list[int] | None = None, *, calibrated: bool = True,
                 address: int = p.ADDRESS, motors: tuple[MotorParams, ...] | None = None,
                 master_firmware: tuple[int, int] = FIRMWARE, slave_firmware: p.SlaveFirmware = SLAVE_FIRMWARE,
                 bare_error_flag: bool = False, clock: Callable[[], float] = time.monotonic) -> None:
        """`positions`: where the motors stand, counts in the calibrated frame (default: where
        calibration leaves them). `calibrated`: the controller was calibrated since it was
        switched on (counters right, motors holding); else it was just switched on: counters 0
        wherever the motors stand, motors off. `motors`: their facts (default: the Katana 300
        6M180's with motor 3's counts per turn of `slave_firmware`, or of 2.xx for a firmware
        KNI gives none for). `bare_error_flag`: refuse with the 3 bytes `C0 <crc>` (which KNI's
        reader takes for an incomplete reply) instead of the error flag at the reply's length."""
        self.address = address
        self.clock = clock
        self.master_firmware = master_firmware
        self.slave_firmware = slave_firmware
        self.bare_error_flag = bare_error_flag
        self.collision_detection = POWER_ON_COLLISION_DETECTION    # (master, slave) of the last 'A'
        if motors is None:
            try:
                motors = motors_for(slave_firmware)
            except UnsupportedController:
                motors = KATANA_300_6M180
        here = positions if positions is not None else [m.position_after for m in motors]
        self.motors = [Motor(m, float(x), stops=m.counts_range) for m, x in zip(motors, here)]
        for m in self.motors:
            if calibrated:
                m.target, m.flag, m.speed_limit = m.true, p.MCF_FREEZE, START_SPEED
            else:
                m.shift = -m.true
        self.silent = False
        self.requests = 0
        self._last_error: tuple[int, int, int, str] = (0, 0, 0, "")
        self._lock = threading.Lock()
        self._t = clock()

    # ------------------------------------------------------------ faults
    def collide(self, motor: int) -> bool:
        """Motor `motor` (1..6) hits something: with collision detection on it stops, status
        MSF_MOTCRASHED, until a freeze; with it off the controller does not notice (False)."""
        with self._lock:
            if not self.collision_detection[1]:
                return False
            self._advance()
            m = self.motors[motor - 1]
            m.crashed, m.velocity = True, 0.0
            m.target = m.counter
            return True

    def go_silent(self, silent: bool = True) -> None:
        """The controller stops answering (its cable pulled, its power gone), or answers again."""
        with self._lock:
            self.silent = silent

    # ------------------------------------------------------------ readings for tests
    def counters(self) -> list[float]:
        with self._lock:
            self._advance()
            return [m.counter for m in self.motors]

    def still(self) -> bool:
        """No motor moves now (each off, at its target, or against a stopper)."""
        with self._lock:
            self._advance()
            return all(m.velocity == 0.0 for m in self.motors)

    def flags(self) -> list[int]:
        with self._lock:
            return [m.flag for m in self.motors]

    def targets(self) -> list[float]:
        with self._lock:
            return [m.target for m in self.motors]

    def settings(self, motor: int) -> dict[int, bytes]:
        """What 'S' last set in motor `motor` (1..6): subcommand -> its three bytes."""
        with self._lock:
            return dict(self.motors[motor - 1].settings)

    # ------------------------------------------------------------ the line
    def answer(self, frame: bytes) -> bytes | None:
        """The bytes the controller sends back for one whole frame it read (a request or the
        error request), or None when it says nothing."""
        with self._lock:
            if self.silent:
                return None
            if frame == p.ERROR_REQUEST:
                return p.encode_error_message(*self._last_error)
            try:
                address, payload = p.decode_request(frame)
            except p.ProtocolError:
                return None                 # a bad frame is not answered; the master tries again
            if address != self.address:
                return None
            self.requests += 1
            self._advance()
            try:
                return p.encode_reply(self._obey(payload))
            except _Refused as exc:
                self._last_error = (payload[0], exc.code, exc.axis, exc.text)
                return p.encode_error_flag() if self.bare_error_flag else p.encode_error_reply(payload[0])

    def _advance(self) -> None:
        now = self.clock()
        dt, self._t = now - self._t, now
        for m in self.motors:
            m.step(dt)

    def _motor(self, number: int) -> Motor:
        if not 1 <= number <= len(self.motors):
            raise _Refused(f"no motor {number}", 1, number)
        return self.motors[number - 1]

    def _obey(self, q: bytes) -> bytes:
        c = q[0]
        if c == ord("B"):
            return bytes([ord("b"), *self.master_firmware])
        if c == ord("Z"):
            return b"z"
        if c == ord("A"):
            self.collision_detection = (q[1], q[2])
            return b"a\x01"
        if c == ord("V"):
            # Byte 2 of 'v' is not read by KNI: the emulator sends the motor number there.
            self._motor(q[1])
            sfw = self.slave_firmware
            payload = bytes([ord("v"), 1, q[1], sfw.version, sfw.subversion, sfw.revision, sfw.type, sfw.subtype])
            return payload.ljust(p.SIZES[c][1], b"\0")
        if c == ord("C"):
            return self._set(q[1], q[2], p.s16(q[3], q[4]))
        if c == ord("D"):
            m = self._motor(q[1])
            pos = round(m.counter)
            vel = round(m.velocity)
            return bytes([ord("d"), 1, m.status]) + _s16(pos) + _s16(vel) + bytes([0])
        if c == ord("N"):
            if q[1] == p.ALL_POSITIONS:
                return b"n" + b"".join(_s16(round(m.counter)) for m in self.motors)
            if q[1] == p.ALL_STATUS:
                return (b"n" + bytes(m.status for m in self.motors)).ljust(p.SIZES[c][1], b"\0")
            raise _Refused(f"'N' subcommand {q[1]} is not emulated", 2, 0)
        if c == ord("S"):
            m = self._motor(q[1])
            m.settings[q[2]] = bytes(q[3:6])
            if q[2] == p.S_SPEED_LIMITS:
                m.speed_limit = min(q[3], q[4])
            return bytes([ord("s"), q[1], q[2], 0, 0, 0])
        raise _Refused(f"command {chr(c & 0x7F)!r} is not emulated", 3, 0)

    def _set(self, which: int, flag: int, value: int) -> bytes:
        actual = bool(which & p.ACTUAL_POSITION)
        number = which & ~p.ACTUAL_POSITION
        if number == 0:
            raise _Refused("calibration of all motors at once is a Katana 400's", 4, 0)
        m = self._motor(number)
        if flag not in (p.MCF_OFF, p.MCF_FREEZE, p.MCF_ON):
            raise _Refused(f"motor flag {flag} is not emulated", 5, number)
        if actual:                          # the counter reads `value` from now on; hold there
            m.shift = value - m.true
            m.target, m.flag = float(value), flag
            return bytes([ord("c"), 1, which])
        if m.crashed and flag != p.MCF_FREEZE:
            return bytes([ord("c"), 0, which])     # a collided motor moves again only after a freeze
        if flag == p.MCF_FREEZE:
            m.crashed = False
        m.target, m.flag = float(value), flag
        return bytes([ord("c"), 1, which])


class _Refused(Exception):
    def __init__(self, text: str, code: int, axis: int) -> None:
        super().__init__(text)
        self.text, self.code, self.axis = text, code, axis


def _s16(value: int) -> bytes:
    return (max(-32768, min(32767, value)) & 0xFFFF).to_bytes(2, "big")

"""The Katana 300 6M180 over a serial port: a plain class, no bus, no threads of its own.

`Katana(port)` speaks `protocol` over anything with pyserial's `read`, `write` and
`reset_input_buffer` (a `serial.Serial` on /dev/ttyUSB0, or on the emulator's pty). One request
at a time, under a lock: write the frame, read the reply within READ_TIMEOUT_S, send again up
to RETRIES times when the reply is short or its CRC wrong (as KNI does), then give up with
`Silent`. The units of the line are encoder counts; `MotorParams` converts them to the
catalogue's radians (docs/katana.md, "Encoders and radians").
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Callable, Protocol

from asibot.katana_driver import protocol as p

#: Encoder counts per 10 ms that the Katana's documentation gives as every joint's top speed.
MAX_SPEED = 180
#: The speed limit of the search for the mechanical stoppers, counts per 10 ms (KNI's).
SEARCH_SPEED = 25
#: How often the search reads the speed, s (KNI's POLLFREQUENCY in kmlExt.cpp).
SEARCH_POLL_S = 0.3
#: Counts from a target that count as there (KNI's default tolerance of mov()).
TOLERANCE = 100


class Port(Protocol):
    """What the Katana needs of a serial line: pyserial's Serial has it."""

    def read(self, size: int = 1) -> bytes: ...
    def write(self, data: bytes, /) -> int | None: ...
    def reset_input_buffer(self) -> None: ...


class Silent(Exception):
    """The controller did not answer (whole and with a right CRC) after every retry."""


class Interrupted(Exception):
    """Calibration was stopped from outside (the estop, a shutdown); the motor that was moving
    was frozen where it stood."""


@dataclass(frozen=True)
class MotorParams:
    """One motor's encoder facts (KNI configfiles300/katana6M180.cfg, [INIT] and [CALIBRATION]),
    and how the ROS description turns KNI's angle into its own (katana/src/KNIConverter.cpp)."""

    motor: int                  # 1..6 on the line
    encoder_offset: int         # counts at the mechanical stopper found by calibration
    angle_offset_deg: float     # KNI's angle there
    encoders_per_cycle: int
    direction: int              # +1 for DIR_POSITIVE, -1 for DIR_NEGATIVE
    angle_range_deg: float
    shift_pi: bool              # motors 1, 3, 4, 5: the URDF angle is KNI's minus pi
    calibration_order: int
    search_positive: bool       # calibration searches the stopper towards +counts
    position_after: int         # where calibration leaves the motor, counts

    def kni_angle(self, counts: float) -> float:
        return math.radians(self.angle_offset_deg) - (counts - self.encoder_offset) * 2 * math.pi / (
            self.encoders_per_cycle * self.direction)

    def counts_of_kni(self, angle: float) -> float:
        return (math.radians(self.angle_offset_deg) - angle) * self.encoders_per_cycle * self.direction / (
            2 * math.pi) + self.encoder_offset

    def to_rad(self, counts: float) -> float:
        """The URDF's angle (rad) at `counts`."""
        return self.kni_angle(counts) - (math.pi if self.shift_pi else 0.0)

    def to_counts(self, rad: float) -> int:
        """The nearest count to the URDF's angle `rad`."""
        return round(self.counts_of_kni(rad + (math.pi if self.shift_pi else 0.0)))

    def speed_to_rad(self, counts_per_s: float) -> float:
        return -counts_per_s * 2 * math.pi / (self.encoders_per_cycle * self.direction)

    @property
    def counts_per_rad(self) -> float:
        return self.encoders_per_cycle / (2 * math.pi)

    @property
    def stop_counts(self) -> int:
        """The counts at the other mechanical stopper (KNI truncates the range to whole counts)."""
        return self.encoder_offset - self.direction * int(self.encoders_per_cycle * self.angle_range_deg / 360.0)

    @property
    def counts_range(self) -> tuple[int, int]:
        return min(self.encoder_offset, self.stop_counts), max(self.encoder_offset, self.stop_counts)


#: The Katana 300 6M180 (KNI configfiles300/katana6M180.cfg, lines 43-363).
KATANA_300_6M180 = (
    MotorParams(1, 31000, 6.65, 51200, +1, 346.7, True, 5, True, 30000),
    MotorParams(2, -31000, 124.25, 94976, +1, -143.0, False, 0, False, -30000),
    MotorParams(3, -31000, 52.7, 81408, -1, 250.0, True, 1, False, -30000),
    MotorParams(4, 31000, 63.5, 51200, +1, 233.0, True, 2, True, 30000),
    MotorParams(5, 31000, 8.5, 51200, +1, 344.0, True, 3, True, 30000),
    MotorParams(6, 31000, -123.2, 51200, +1, 337.0, False, 4, True, 30000),
)

# The gripper: the URDF finger angle is KNI's, scaled (katana/include/katana/katana_constants.h).
GRIPPER_OPEN_ANGLE, GRIPPER_CLOSED_ANGLE = 0.30, -0.44
KNI_GRIPPER_OPEN_ANGLE, KNI_GRIPPER_CLOSED_ANGLE = -2.057443, 0.21652991032554647
KNI_TO_URDF_GRIPPER = (GRIPPER_OPEN_ANGLE - GRIPPER_CLOSED_ANGLE) / (KNI_GRIPPER_OPEN_ANGLE - KNI_GRIPPER_CLOSED_ANGLE)


def gripper_counts(opening: float, max_opening: float, params: MotorParams = KATANA_300_6M180[5]) -> int:
    """Counts of the gripper motor for `opening` (m between the fingers, 0..max_opening): the
    finger angle goes linearly from closed (-0.44 rad) to open (0.30 rad)."""
    f = min(max(opening / max_opening, 0.0), 1.0)
    angle = GRIPPER_CLOSED_ANGLE + f * (GRIPPER_OPEN_ANGLE - GRIPPER_CLOSED_ANGLE)
    kni = (angle - GRIPPER_CLOSED_ANGLE) / KNI_TO_URDF_GRIPPER + KNI_GRIPPER_CLOSED_ANGLE
    return round(params.counts_of_kni(kni))


def gripper_opening(counts: float, max_opening: float, params: MotorParams = KATANA_300_6M180[5]) -> float:
    """The opening (m) of the gripper motor at `counts`, clipped to 0..max_opening."""
    angle = (params.kni_angle(counts) - KNI_GRIPPER_CLOSED_ANGLE) * KNI_TO_URDF_GRIPPER + GRIPPER_CLOSED_ANGLE
    f = (angle - GRIPPER_CLOSED_ANGLE) / (GRIPPER_OPEN_ANGLE - GRIPPER_CLOSED_ANGLE)
    return min(max(f, 0.0), 1.0) * max_opening


Trace = Callable[[str, bytes], None]      # ("tx" | "rx", the bytes of one frame)


class Katana:
    """The arm's controller behind `port`. Every method is one or a few request/reply pairs;
    errors: `Silent` (no answer), `protocol.FirmwareError` (refused, with its reason),
    `protocol.ProtocolError` (an answer that is not one)."""

    def __init__(self, port: Port, *, address: int = p.ADDRESS, timeout: float = p.READ_TIMEOUT_S,
                 retries: int = p.RETRIES, motors: tuple[MotorParams, ...] = KATANA_300_6M180,
                 trace: Trace | None = None) -> None:
        self.port = port
        self.address = address
        self.timeout = timeout
        self.retries = retries
        self.motors = motors
        self.trace = trace
        self._lock = threading.Lock()
        self.requests = 0
        self.retried = 0

    # ------------------------------------------------------------ one exchange
    def transact(self, payload: bytes) -> bytes:
        """Send `payload`, return the reply's payload (checked)."""
        command = payload[0]
        frame = p.encode_request(payload, self.address)
        want = p.reply_length(command)
        with self._lock:
            self.requests += 1
            for attempt in range(self.retries + 1):
                if attempt:
                    self.retried += 1
                self.port.reset_input_buffer()       # a late reply to an earlier request is not this one's
                self._write(frame)
                reply = self._read(want, error_flag=True)
                if reply is None:
                    continue
                if p.is_error_flag(reply):
                    raise self._why()
                try:
                    return p.decode_reply(command, reply)
                except p.ProtocolError:
                    continue
        raise Silent(f"the Katana did not answer {p.describe(command)} ({self.retries + 1} tries, "
                     f"{self.timeout * 1000:.0f} ms each)")

    def _write(self, data: bytes) -> None:
        if self.trace is not None:
            self.trace("tx", data)
        self.port.write(data)

    def _read(self, want: int, error_flag: bool = False) -> bytes | None:
        """`want` bytes within the timeout (or the 3 of an error flag); None if they did not come."""
        buf = b""
        deadline = time.monotonic() + self.timeout
        while len(buf) < want and time.monotonic() < deadline:
            buf += self.port.read(want - len(buf))
            if error_flag and len(buf) >= 3 and buf[0] == p.ERROR_FLAG:
                try:
                    p.check_crc(buf[:3])
                except p.ProtocolError:
                    pass
                else:
                    buf = buf[:3]
                    break
        if self.trace is not None and buf:
            self.trace("rx", buf)
        if len(buf) < want and not p.is_error_flag(buf):
            return None
        return buf

    def _why(self) -> Exception:
        """After an error flag: ask the controller why (one try, as KNI)."""
        self._write(p.ERROR_REQUEST)
        answer = self._read(p.ERROR_REPLY_SIZE + 2)
        if answer is None:
            return p.FirmwareError("it did not say why", 0, 0, 0)
        try:
            return p.decode_error_message(answer)
        except p.ProtocolError as exc:
            return p.FirmwareError(f"its reason was garbled ({exc})", 0, 0, 0)

    # ------------------------------------------------------------ commands
    def firmware(self) -> tuple[int, int]:
        """The master firmware's (version, revision)."""
        return p.parse_firmware(self.transact(p.master_firmware()))

    def echo(self) -> bool:
        return self.transact(p.echo())[0] == ord("z")

    def positions(self) -> list[int]:
        """Every motor's position, counts (one 'N')."""
        return p.parse_positions(self.transact(p.read_all(p.ALL_POSITIONS)), len(self.motors))

    def statuses(self) -> list[int]:
        """Every motor's status flag (one 'N')."""
        return p.parse_statuses(self.transact(p.read_all(p.ALL_STATUS)), len(self.motors))

    def read(self, motor: int) -> p.MotorReading:
        return p.parse_motor(self.transact(p.read_motor(motor)))

    def set_target(self, motor: int, counts: int, flag: int = p.MCF_ON) -> None:
        """Move `motor` to `counts` (MCF_ON), hold it there (MCF_FREEZE) or switch it off (MCF_OFF)."""
        reply = self.transact(p.set_target(motor, flag, counts))
        if not reply[1]:
            raise p.FirmwareError("the target was not accepted", 0, motor, ord("C"))

    def set_actual(self, motor: int, counts: int, flag: int) -> None:
        reply = self.transact(p.set_actual(motor, flag, counts))
        if not reply[1]:
            raise p.FirmwareError("the actual position was not accepted", 0, motor, ord("C"))

    def set_speed_limits(self, motor: int, counts_per_10ms: int) -> None:
        self.transact(p.set_speed_limits(motor, counts_per_10ms, counts_per_10ms))

    def freeze(self, positions: list[int] | None = None) -> list[int]:
        """Hold every motor where it is (MCF_FREEZE at its position, as KNI's freezeRobot); also
        what clears a collision (KNI's unBlock). Returns the positions held."""
        here = positions if positions is not None else self.positions()
        for m, counts in zip(self.motors, here):
            self.set_target(m.motor, counts, p.MCF_FREEZE)
        return here

    def motors_off(self) -> None:
        """Every motor off (MCF_OFF at its position, as KNI's switchRobotOff): the arm goes limp."""
        for m, counts in zip(self.motors, self.positions()):
            self.set_target(m.motor, counts, p.MCF_OFF)

    def start(self, speed: int = MAX_SPEED) -> list[int]:
        """After calibration: speed limits set, every motor switched on holding where it is."""
        for m in self.motors:
            self.set_speed_limits(m.motor, speed)
        return self.freeze()

    # ------------------------------------------------------------ calibration
    def calibrate(self, speed: int = MAX_SPEED, timeout: float = 60.0,
                  stop: threading.Event | None = None) -> None:
        """The Katana 300's calibration (KNI's CKatana::calibrate): every motor switched on at
        counter 0, then one motor at a time, in calibration order, searches its mechanical
        stopper slowly, is told the stopper's counts and goes to its position after
        calibration. Its encoders are incremental: a Katana switched on knows nothing before this."""
        for m in self.motors:
            self.set_actual(m.motor, 0, p.MCF_ON)
        for m in sorted(self.motors, key=lambda m: m.calibration_order):
            self._search_stopper(m, timeout, stop)
            self.set_actual(m.motor, m.encoder_offset, p.MCF_ON)
            self.set_speed_limits(m.motor, speed)
            self.set_target(m.motor, m.position_after)
            self._wait_at(m, m.position_after, timeout, stop)

    def _search_stopper(self, m: MotorParams, timeout: float, stop: threading.Event | None) -> None:
        self.set_speed_limits(m.motor, SEARCH_SPEED)
        self.set_actual(m.motor, -31000 if m.search_positive else 31000, p.MCF_FREEZE)
        self.set_target(m.motor, 32000 if m.search_positive else -32000)
        deadline = time.monotonic() + timeout
        previous = 100
        while True:
            reading = self.read(m.motor)
            if reading.velocity + previous == 0:
                break
            previous = reading.velocity
            if time.monotonic() > deadline:
                self.set_target(m.motor, reading.position, p.MCF_FREEZE)
                raise Silent(f"motor {m.motor} found no mechanical stopper within {timeout:g} s")
            self._pause(m, reading.position, SEARCH_POLL_S, stop)
        self.set_actual(m.motor, 0, p.MCF_FREEZE)

    def _pause(self, m: MotorParams, here: int, seconds: float, stop: threading.Event | None) -> None:
        if stop is None:
            time.sleep(seconds)
        elif stop.wait(seconds):
            self.set_target(m.motor, here, p.MCF_FREEZE)
            raise Interrupted(f"calibration was interrupted while motor {m.motor} moved")

    def _wait_at(self, m: MotorParams, counts: int, timeout: float, stop: threading.Event | None) -> None:
        deadline = time.monotonic() + timeout
        while True:
            r = self.read(m.motor)
            if r.status == p.MSF_MOTCRASHED:
                raise p.FirmwareError("it collided while calibrating", 0, m.motor, ord("D"))
            if abs(r.position - counts) < TOLERANCE:
                return
            if time.monotonic() > deadline:
                self.set_target(m.motor, r.position, p.MCF_FREEZE)
                raise Silent(f"motor {m.motor} did not reach {counts} within {timeout:g} s")
            self._pause(m, r.position, 0.05, stop)

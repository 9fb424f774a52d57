"""The Katana 300 6M180 over a serial port: a plain class, no bus, no threads of its own.

`Katana(port)` speaks `protocol` over anything with pyserial's `read`, `write` and
`reset_input_buffer` (a `serial.Serial` on /dev/ttyUSB0, or on the emulator's pty). One request
at a time, under a lock: write the frame, read the reply within READ_TIMEOUT_S, send again up
to RETRIES times when the reply is short or its CRC wrong (as KNI does; an error flag shorter
than the reply is short too), then give up with `Silent`. The units of the line are encoder
counts; `MotorParams` converts them to the catalogue's radians (docs/katana.md, "Encoders and
radians"). Motor 3's counts per turn depend on its slave firmware: `identify` asks, before
anything is converted. `ControllerLimits` are what KNI sets in each motor's controller around
its stopper search (kmlExt.cpp searchMechStop), from KNI's configuration of the arm.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, replace
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
#: The acceleration limit during the stopper search (kmlExt.cpp searchMechStop, line 202).
SEARCH_ACCELERATION = 1
#: KNI reads a master firmware version below this as a Katana 400's controller, whose commands
#: and calibration differ (K400_OLD_PROTOCOL_THRESHOLD, kmlBase.h; checkKatanaType, kmlBase.cpp).
KATANA_300_MASTER_VERSION = 3
#: Motor 3's encoder counts per turn by its slave firmware's version ("81408 for slave firmware
#: 2.xx, 94976 for slave firmware 1.xx", KNI configfiles300/katana6M180.cfg, [MOT[2]] line 171).
#: KNI itself does not choose: its user edits the configuration file; the driver asks 'V'.
MOTOR3_COUNTS_BY_SLAVE_VERSION = {1: 94976, 2: 81408}
#: The one motor whose counts per turn depend on the slave firmware.
FIRMWARE_DEPENDENT_MOTOR = 3
#: Counts the line can carry: positions are signed 16-bit.
COUNTER_RANGE = (-32768, 32767)


class Port(Protocol):
    """What the Katana needs of a serial line: pyserial's Serial has it."""

    def read(self, size: int = 1) -> bytes: ...
    def write(self, data: bytes, /) -> int | None: ...
    def reset_input_buffer(self) -> None: ...


class Silent(Exception):
    """The controller did not answer (whole and with a right CRC) after every retry."""


class UnsupportedController(Exception):
    """The controller is not one this driver can drive rightly (its master or slave firmware);
    the message is a whole sentence that says what to do."""


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

    def within_counter(self, lower: float, upper: float) -> tuple[float, float]:
        """The part of lower..upper (rad) whose counts a signed 16-bit position can carry: with
        motor 3's 94976 counts per turn (slave firmware 1.xx) the top of its range cannot."""
        ends = sorted((self.to_rad(COUNTER_RANGE[0]), self.to_rad(COUNTER_RANGE[1])))
        return max(lower, ends[0]), min(upper, ends[1])


#: The Katana 300 6M180 (KNI configfiles300/katana6M180.cfg, lines 43-363).
KATANA_300_6M180 = (
    MotorParams(1, 31000, 6.65, 51200, +1, 346.7, True, 5, True, 30000),
    MotorParams(2, -31000, 124.25, 94976, +1, -143.0, False, 0, False, -30000),
    MotorParams(3, -31000, 52.7, 81408, -1, 250.0, True, 1, False, -30000),
    MotorParams(4, 31000, 63.5, 51200, +1, 233.0, True, 2, True, 30000),
    MotorParams(5, 31000, 8.5, 51200, +1, 344.0, True, 3, True, 30000),
    MotorParams(6, 31000, -123.2, 51200, +1, 337.0, False, 4, True, 30000),
)


@dataclass(frozen=True)
class ControllerLimits:
    """What KNI sets in one motor's controller after its stopper search, and, but for the
    acceleration and speed, before it (kmlExt.cpp searchMechStop): the [STATIC] and [DYNAMIC]
    *_nmp values of the arm's configuration file."""

    motor: int
    pwm_positive: int           # maxppwm_nmp, 'S' 2
    pwm_negative: int           # maxnpwm_nmp
    k_speed: int                # kspeed_nmp, 'S' 1
    k_pos: int                  # kpos_nmp
    k_i: int                    # kI_nmp
    crash_limit: int            # crash_limit_nmp, 'S' 5, counts
    crash_limit_linear: int     # crash_limit_lin_nmp, 'S' 6, counts
    acceleration: int           # maxaccel_nmp, 'S' 4
    speed_positive: int         # maxpspeed_nmp, 'S' 3, counts per 10 ms
    speed_negative: int         # maxnspeed_nmp

    def for_search(self) -> ControllerLimits:
        """The limits of the stopper search: acceleration 1 and speed 25 (kmlExt.cpp 202-203)."""
        return replace(self, acceleration=SEARCH_ACCELERATION, speed_positive=SEARCH_SPEED,
                       speed_negative=SEARCH_SPEED)

    def at_speed(self, speed: int) -> ControllerLimits:
        return replace(self, speed_positive=speed, speed_negative=speed)


#: The Katana 300 6M180's (KNI configfiles300/katana6M180.cfg, [STATIC] and [DYNAMIC] of each
#: motor: lines 82-101, 135-153, 187-205, 239-257, 291-309, 343-361). Motor 4's
#: crash_limit_lin_nmp is misspelt there ("crash_limit_lin	_nmp", line 245): KNI's reader,
#: which matches an entry's name by its start and reads on, takes motor 5's 800 (line 297).
KATANA_300_6M180_LIMITS = (
    ControllerLimits(1, 100, 100, 15, 2, 100, 800, 800, 1, 30, 30),
    ControllerLimits(2, 127, 127, 7, 2, 100, 800, 800, 1, 25, 25),
    ControllerLimits(3, 100, 100, 15, 2, 100, 800, 800, 1, 25, 25),
    ControllerLimits(4, 127, 127, 2, 2, 100, 800, 800, 1, 25, 25),
    ControllerLimits(5, 127, 127, 7, 2, 100, 800, 800, 1, 25, 25),
    ControllerLimits(6, 127, 127, 4, 1, 100, 800, 800, 1, 25, 25),
)


def motors_for(slave: p.SlaveFirmware | None, motors: tuple[MotorParams, ...] = KATANA_300_6M180,
               joint: str = "katana_motor3_lift_joint") -> tuple[MotorParams, ...]:
    """`motors` with motor 3's counts per turn those of its slave firmware `slave`;
    UnsupportedController, with what to do, for a firmware KNI gives no counts for."""
    counts = MOTOR3_COUNTS_BY_SLAVE_VERSION.get(slave.version) if slave is not None else None
    if counts is None:
        what = f"is {slave}" if slave is not None else "could not be read (its 'v' reply said not ok)"
        known = " and ".join(f"{v}.xx ({c})" for v, c in sorted(MOTOR3_COUNTS_BY_SLAVE_VERSION.items()))
        raise UnsupportedController(
            f"The slave firmware of the Katana's motor 3 (joint {joint}) {what}, and KNI gives its encoder counts "
            f"per turn only for {known} (katana6M180.cfg): every position of that joint would be wrong, "
            "so the arm was not moved. Find motor 3's counts per turn for this firmware (Neuronics' "
            "configuration file for it) and add them to MOTOR3_COUNTS_BY_SLAVE_VERSION in "
            "asibot/katana_driver/katana.py, or update the slave firmware.")
    return tuple(replace(m, encoders_per_cycle=counts) if m.motor == FIRMWARE_DEPENDENT_MOTOR else m
                 for m in motors)


@dataclass(frozen=True)
class Identity:
    """What the controller says of itself: the master firmware's (version, revision) and each
    motor's slave firmware (None where it could not be read)."""

    master: tuple[int, int]
    slaves: tuple[p.SlaveFirmware | None, ...]


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
                 limits: tuple[ControllerLimits, ...] = KATANA_300_6M180_LIMITS,
                 trace: Trace | None = None) -> None:
        self.port = port
        self.address = address
        self.timeout = timeout
        self.retries = retries
        self.motors = motors            # motor 3's counts per turn are right once `identify` asked
        self.limits = {lim.motor: lim for lim in limits}
        self.slaves: dict[int, p.SlaveFirmware | None] = {}
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
        bare_flags = 0
        with self._lock:
            self.requests += 1
            for attempt in range(self.retries + 1):
                if attempt:
                    self.retried += 1
                self.port.reset_input_buffer()       # a late reply to an earlier request is not this one's
                self._write(frame)
                reply = self._read(want)
                if len(reply) < want:
                    # KNI's reader throws on a short read before it looks for the error flag
                    # (cdlCOM.cpp recv), so a bare `C0 <crc>` is an incomplete reply: sent again.
                    if reply == p.encode_error_flag():
                        bare_flags += 1
                    continue
                if p.is_error_flag(reply):
                    try:
                        p.check_crc(reply)           # over all but the last two bytes (cplSerial.cpp recv)
                    except p.ProtocolError:
                        continue                     # KNI's WrongCRCException: sent again
                    raise self._why()
                try:
                    return p.decode_reply(command, reply)
                except p.ProtocolError:
                    continue
        how = (f"; {bare_flags} of its answers were a bare 3-byte error flag, which KNI reads as an incomplete "
               "reply" if bare_flags else "")
        raise Silent(f"the Katana did not answer {p.describe(command)} ({self.retries + 1} tries, "
                     f"{self.timeout * 1000:.0f} ms each{how})")

    def _write(self, data: bytes) -> None:
        if self.trace is not None:
            self.trace("tx", data)
        self.port.write(data)

    def _read(self, want: int) -> bytes:
        """Up to `want` bytes, what came within the timeout (as KNI's reader: cdlCOM.cpp recv)."""
        buf = b""
        deadline = time.monotonic() + self.timeout
        while len(buf) < want and time.monotonic() < deadline:
            buf += self.port.read(want - len(buf))
        if self.trace is not None and buf:
            self.trace("rx", buf)
        return buf

    def _why(self) -> Exception:
        """After an error reply: ask the controller why (one try, as KNI)."""
        self._write(p.ERROR_REQUEST)
        answer = self._read(p.ERROR_REPLY_SIZE + 2)
        if len(answer) < p.ERROR_REPLY_SIZE + 2:
            return p.FirmwareError("it did not say why", 0, 0, 0)
        try:
            return p.decode_error_message(answer)
        except p.ProtocolError as exc:
            return p.FirmwareError(f"its reason was garbled ({exc})", 0, 0, 0)

    # ------------------------------------------------------------ commands
    def firmware(self) -> tuple[int, int]:
        """The master firmware's (version, revision)."""
        return p.parse_firmware(self.transact(p.master_firmware()))

    def slave_firmware(self, motor: int) -> p.SlaveFirmware | None:
        """`motor`'s slave firmware; None when the motor says it cannot tell."""
        return p.parse_slave_firmware(self.transact(p.slave_firmware(motor)))

    def identify(self, joint: str = "katana_motor3_lift_joint") -> Identity:
        """Ask the master firmware ('B') and every motor's slave firmware ('V'), as KNI does when
        it connects (kmlBase.cpp checkKatanaType, kmlMotBase.cpp init); from then on motor 3's
        counts per turn are its firmware's. UnsupportedController, with what to do, for a
        Katana 400's controller or a motor 3 firmware KNI gives no counts for; `joint` names
        motor 3 in that sentence."""
        master = self.firmware()
        if master[0] < KATANA_300_MASTER_VERSION:
            raise UnsupportedController(
                f"The Katana's master firmware is {master[0]}.{master[1]}, which KNI reads as a Katana 400's "
                f"controller (a version below {KATANA_300_MASTER_VERSION}, kmlBase.cpp checkKatanaType): its "
                "calibration and commands differ from the Katana 300 6M180's this driver speaks, so the arm was "
                "not moved. Check that the serial cable goes to the Pioneer's Katana 300.")
        self.slaves = {m.motor: self.slave_firmware(m.motor) for m in self.motors}
        self.motors = motors_for(self.slaves.get(FIRMWARE_DEPENDENT_MOTOR), self.motors, joint)
        return Identity(master, tuple(self.slaves[m.motor] for m in self.motors))

    def collision_detection(self, on: bool) -> None:
        """Collision detection on (the crash limits stop a motor that lags its set-point) or off."""
        self.transact(p.collision_detection(on))

    def set_limits(self, lim: ControllerLimits) -> None:
        """One motor's PWM limits, gains, crash limits, acceleration and speed, in KNI's order
        (kmlExt.cpp searchMechStop); no PWM limits for a current controller, as KNI."""
        m = lim.motor
        slave = self.slaves.get(m)
        if slave is None or slave.type != p.CURRENT_CONTROLLER:
            self.transact(p.set_pwm_limits(m, lim.pwm_positive, lim.pwm_negative))
        self.transact(p.set_controller_parameters(m, lim.k_speed, lim.k_pos, lim.k_i))
        self.transact(p.set_crash_limit(m, lim.crash_limit))
        self.transact(p.set_crash_limit_linear(m, lim.crash_limit_linear))
        self.transact(p.set_acceleration_limit(m, lim.acceleration))
        self.transact(p.set_speed_limits(m, lim.speed_positive, lim.speed_negative))

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
        """After calibration, or on a controller calibrated since power-on whose limits are
        whatever it last held: every motor's working limits (the configuration's, at `speed`:
        the driver rate-limits its own set-points), collision detection on, every motor
        switched on holding where it is."""
        for m in self.motors:
            self.set_limits(self.limits[m.motor].at_speed(speed))
        self.collision_detection(True)
        return self.freeze()

    # ------------------------------------------------------------ calibration
    def calibrate(self, timeout: float = 60.0, stop: threading.Event | None = None) -> None:
        """The Katana 300's calibration (KNI's CKatana::calibrate), collision detection off, as
        the ROS driver does (katana/src/Katana.cpp calibrate): a motor pushing against its
        stopper lags its set-point. Every motor switched on at counter 0, then one motor at a
        time, in calibration order: the search limits, a slow search of its mechanical stopper,
        the working limits, the stopper's counts, and a move to its position after calibration.
        Its encoders are incremental: a Katana switched on knows nothing before this.
        `start` switches collision detection on again."""
        self.collision_detection(False)
        for m in self.motors:
            self.set_actual(m.motor, 0, p.MCF_ON)
        for m in sorted(self.motors, key=lambda m: m.calibration_order):
            self._search_stopper(m, timeout, stop)
            self.set_actual(m.motor, m.encoder_offset, p.MCF_ON)
            self.set_target(m.motor, m.position_after)
            self._wait_at(m, m.position_after, timeout, stop)

    def _search_stopper(self, m: MotorParams, timeout: float, stop: threading.Event | None) -> None:
        """KNI's searchMechStop (kmlExt.cpp 195-268): the limits of the search, the search, and
        the working limits back."""
        self.set_limits(self.limits[m.motor].for_search())
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
        self.set_limits(self.limits[m.motor])

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

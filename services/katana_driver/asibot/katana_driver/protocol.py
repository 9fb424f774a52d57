"""The Katana's serial protocol, as KNI 4.3.0 documents it: frames, CRC, encode and decode.

Pure functions, no I/O. Every number here is a fact of docs/katana.md, "The serial protocol",
or names its KNI 4.3.0 source file (in uos/katana_driver, kni/KNI_4.3.0/); the code is written
from those facts, not from KNI's.

A request is `01 <address> <n> <payload: n bytes> <crc hi> <crc lo>`; the CRC covers the payload
only. The reply is `<payload: the command's reply size> <crc hi> <crc lo>`, its first byte the
command letter in lower case, the CRC over the reply payload. A controller that refuses a
command answers with the error flag C0 as the first byte instead. KNI's reader (cdlCOM.cpp
recv, cplSerial.cpp recv) reads an error reply only at the command's full reply length: fewer
bytes, a bare `C0 <crc>` among them, are an incomplete reply and the request is sent again; a
wrong CRC is sent again too. Only then is the reason asked, with the 4 raw bytes `00 00 00 C1`,
and it comes back as 57 bytes: `C1 <last command> <error code> <axis> <text, NUL-terminated>`,
55 in all, and the CRC.
"""

from __future__ import annotations

from dataclasses import dataclass

#: The line: 57600 baud, 8 data bits, no parity, 1 stop bit.
BAUD = 57600
BYTESIZE, PARITY, STOPBITS = 8, "N", 1
#: How long a reply may take to arrive whole, s (KNI's "read total timeout", 300 ms).
READ_TIMEOUT_S = 0.3
#: How many times KNI sends a request again when its reply is short or its CRC wrong.
RETRIES = 3
#: The controller's address on the line (its jumpers; "24" in every KNI configuration file).
ADDRESS = 24
#: The first byte of every request header.
HEADER_START = 1
#: A reply that starts with this byte means "refused"; ERROR_FLAG + 1 asks why.
ERROR_FLAG = 192
ERROR_REQUEST = bytes([0, 0, 0, ERROR_FLAG + 1])
ERROR_REPLY_SIZE = 55           # payload of the answer to ERROR_REQUEST, before its CRC

#: Command letter -> (request payload size, reply payload size), bytes, both without header
#: or CRC. 'G' + 128 is a command byte of its own (start a spline movement).
SIZES: dict[int, tuple[int, int]] = {
    ord("B"): (1, 3), ord("X"): (1, 181), ord("Y"): (1, 84), ord("Z"): (1, 1),
    ord("C"): (5, 3), ord("D"): (2, 8), ord("E"): (2, 18), ord("V"): (3, 13),
    ord("N"): (3, 13), ord("G"): (14, 2), ord("G") + 128: (3, 2), ord("H"): (75, 3),
    ord("A"): (3, 2), ord("S"): (6, 6), ord("I"): (2, 3), ord("M"): (5, 4), ord("T"): (5, 2),
}

# Motor command flags ('C', byte 2).
MCF_OFF, MCF_CALIB, MCF_FREEZE, MCF_ON, MCF_CLEAR_MOVEBUFFER = 0, 4, 8, 24, 32
# Motor status flags ('D' byte 2, 'N' subcommand 1).
MSF_MECHSTOP, MSF_MAXPOS, MSF_MINPOS, MSF_DESPOS, MSF_NORMOPSTAT = 1, 2, 4, 8, 16
MSF_MOTCRASHED, MSF_NLINMOV, MSF_LINMOV, MSF_NOTVALID = 40, 88, 152, 128
STATUS_NAMES = {MSF_MECHSTOP: "MSF_MECHSTOP", MSF_MAXPOS: "MSF_MAXPOS", MSF_MINPOS: "MSF_MINPOS",
                MSF_DESPOS: "MSF_DESPOS", MSF_NORMOPSTAT: "MSF_NORMOPSTAT", MSF_MOTCRASHED: "MSF_MOTCRASHED",
                MSF_NLINMOV: "MSF_NLINMOV", MSF_LINMOV: "MSF_LINMOV", MSF_NOTVALID: "MSF_NOTVALID"}
# 'N' subcommands: every motor's status flag, every motor's position.
ALL_STATUS, ALL_POSITIONS = 1, 3
# 'S' subcommands (kmlMotBase.cpp: setControllerParameters, setPwmLimits, setSpeedLimits,
# setAccelerationLimit, setCrashLimit, setCrashLimitLinear).
S_CONTROLLER_PARAMETERS, S_PWM_LIMITS, S_SPEED_LIMITS, S_ACCELERATION_LIMIT = 1, 2, 3, 4
S_CRASH_LIMIT, S_CRASH_LIMIT_LINEAR = 5, 6
#: 'V' with this second byte reads a motor's slave firmware (kmlMotBase.cpp recvSFW).
V_SLAVE_FIRMWARE = 32
#: A slave of this controller type takes no PWM limits: KNI skips 'S' 2 for it ("can not set
#: pwm limit on current controller", kmlMotBase.cpp setPwmLimits).
CURRENT_CONTROLLER = 1
#: 'A' <master> <slave>: collision detection. KNI switches it off with `A 0 0`
#: (kmlBase.cpp disableCrashLimits) and on with `A <motor> 1`, where motor would be 1 on a
#: Katana 300 ("master ON with KatHD300") but is 0 on every Katana: the test that picks it,
#: `if (checkKatanaType(400))`, is true for both of checkKatanaType's answers, 1 and -1
#: (kmlBase.cpp enableCrashLimits, checkKatanaType). `A 0 1` is what the ROS driver has sent
#: to every Katana it calibrated (katana/src/Katana.cpp calibrate), so it is what is sent here.
COLLISION_DETECTION_OFF = (0, 0)
COLLISION_DETECTION_ON = (0, 1)
#: 'C' with motor number + 128 sets the actual position (the counter) instead of the target.
ACTUAL_POSITION = 128
#: Motors of a six-motor Katana (5 joints and the gripper), numbered 1..6 on the line.
MOTORS = 6


class ProtocolError(Exception):
    """A frame that does not follow the protocol (size, CRC, echo); the message says how."""


class FirmwareError(Exception):
    """The controller refused a command (the error flag) and said why."""

    def __init__(self, text: str, code: int, axis: int, command: int) -> None:
        where = f" (axis {axis})" if axis else ""
        super().__init__(f"the Katana refused {describe(command)}: {text or 'no reason given'}{where} "
                         f"(firmware error {code})")
        self.text, self.code, self.axis, self.command = text, code, axis, command


def crc16(data: bytes) -> int:
    """The protocol's CRC: CRC-16 with the reflected polynomial 0xA001 and initial value 0
    (CRC-16/ARC), computed bit by bit. Sent high byte first."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def describe(command: int) -> str:
    if command == ord("G") + 128:
        return "command 'G'+128"
    return f"command {chr(command)!r}" if 32 < command < 127 else f"command byte {command}"


def sizes(command: int) -> tuple[int, int]:
    """(request payload size, reply payload size) of `command`; ProtocolError if unknown."""
    try:
        return SIZES[command]
    except KeyError:
        raise ProtocolError(f"{describe(command)} is not one the Katana knows") from None


def reply_length(command: int) -> int:
    """Bytes on the line for the reply to `command`, CRC included."""
    return sizes(command)[1] + 2


def _with_crc(payload: bytes) -> bytes:
    crc = crc16(payload)
    return payload + bytes([crc >> 8, crc & 0xFF])


# ---------------------------------------------------------------- requests
def encode_request(payload: bytes, address: int = ADDRESS) -> bytes:
    """The frame that sends `payload` (its first byte the command) to the controller."""
    if not payload:
        raise ProtocolError("an empty request has no command")
    size = sizes(payload[0])[0]
    if len(payload) != size:
        raise ProtocolError(f"{describe(payload[0])} takes {size} bytes, not {len(payload)}")
    return bytes([HEADER_START, address, size]) + _with_crc(payload)


def request_length(frame_start: bytes) -> int | None:
    """Length of the whole request that begins with `frame_start` (its 3-byte header), or None
    before the header has arrived."""
    if len(frame_start) < 3:
        return None
    return 3 + frame_start[2] + 2


def decode_request(frame: bytes) -> tuple[int, bytes]:
    """(address, payload) of a whole request; ProtocolError if it is not one."""
    if len(frame) < 6 or frame[0] != HEADER_START:
        raise ProtocolError(f"not a request header: {frame[:3].hex(' ')}")
    n = frame[2]
    if len(frame) != 3 + n + 2:
        raise ProtocolError(f"a request of {n} payload bytes is {n + 5} bytes long, not {len(frame)}")
    payload = frame[3:3 + n]
    if crc16(payload) != (frame[-2] << 8 | frame[-1]):
        raise ProtocolError("wrong CRC in a request")
    size = sizes(payload[0])[0]
    if n != size:
        raise ProtocolError(f"{describe(payload[0])} takes {size} bytes, not {n}")
    return frame[1], payload


# ---------------------------------------------------------------- replies
def encode_reply(payload: bytes) -> bytes:
    """The reply frame for `payload` (the controller's side)."""
    return _with_crc(payload)


def encode_error_flag() -> bytes:
    """The bare 3-byte error flag `C0 <crc>` (what KNI's assert in cplSerial.cpp recv expects,
    and what its reader cannot read for a command whose reply is longer)."""
    return _with_crc(bytes([ERROR_FLAG]))


def encode_error_reply(command: int) -> bytes:
    """The error flag at the length of `command`'s reply: C0, zeros, the CRC over all of them.
    The only form of refusal KNI's reader takes for a command whose reply is longer than 3
    bytes (cdlCOM.cpp recv throws on fewer bytes before the flag is looked at)."""
    return _with_crc(bytes([ERROR_FLAG]).ljust(sizes(command)[1], b"\0"))


def encode_error_message(command: int, code: int, axis: int, text: str) -> bytes:
    """The controller's answer to ERROR_REQUEST: why it refused `command`."""
    raw = text.encode("ascii", "replace")[:ERROR_REPLY_SIZE - 5]
    payload = bytes([ERROR_FLAG + 1, command & 0xFF, code & 0xFF, axis & 0xFF]) + raw
    return _with_crc(payload.ljust(ERROR_REPLY_SIZE, b"\0"))


def check_crc(frame: bytes) -> bytes:
    """The payload of a reply frame whose last two bytes are its CRC; ProtocolError otherwise."""
    payload = frame[:-2]
    if len(frame) < 3 or crc16(payload) != (frame[-2] << 8 | frame[-1]):
        raise ProtocolError("wrong CRC in a reply")
    return payload


def is_error_flag(frame: bytes) -> bool:
    """Whether `frame` starts with the error flag (its length and CRC not checked here)."""
    return len(frame) >= 1 and frame[0] == ERROR_FLAG


def decode_reply(command: int, frame: bytes) -> bytes:
    """The payload of the reply to `command`: size, CRC and the lower-case echo checked."""
    want = reply_length(command)
    if len(frame) != want:
        raise ProtocolError(f"the reply to {describe(command)} is {want} bytes, got {len(frame)}")
    payload = check_crc(frame)
    echo = command & 0x7F
    if 65 <= echo <= 90 and payload[0] != echo + 32:
        raise ProtocolError(f"the reply to {describe(command)} starts with {payload[0]}, not {chr(echo + 32)!r}")
    return payload


def decode_error_message(frame: bytes) -> FirmwareError:
    payload = check_crc(frame)
    if len(payload) != ERROR_REPLY_SIZE or payload[0] != ERROR_FLAG + 1:
        raise ProtocolError("not an answer to the error request")
    text = payload[4:].split(b"\0", 1)[0].decode("ascii", "replace")
    return FirmwareError(text, int.from_bytes(payload[2:3], "big", signed=True), payload[3], payload[1])


# ---------------------------------------------------------------- the commands used here
def _s16(value: int) -> bytes:
    if not -32768 <= value <= 32767:
        raise ProtocolError(f"{value} does not fit the protocol's 16-bit positions")
    return (value & 0xFFFF).to_bytes(2, "big")


def s16(hi: int, lo: int) -> int:
    """A signed 16-bit value sent high byte first."""
    return int.from_bytes(bytes([hi, lo]), "big", signed=True)


def master_firmware() -> bytes:
    """'B': the master firmware's version and revision."""
    return b"B"


def echo() -> bytes:
    """'Z': answered 'z'."""
    return b"Z"


def set_target(motor: int, flag: int, position: int) -> bytes:
    """'C': move `motor` (1..6) to `position` (encoder counts) under `flag` (MCF_ON moves, MCF_FREEZE
    holds there, MCF_OFF switches it off); motor 0 with MCF_CALIB calibrates all (Katana 400)."""
    return bytes([ord("C"), motor, flag]) + _s16(position)


def set_actual(motor: int, flag: int, position: int) -> bytes:
    """'C' with motor + 128: `motor`'s counter now reads `position`."""
    return bytes([ord("C"), motor + ACTUAL_POSITION, flag]) + _s16(position)


def read_motor(motor: int) -> bytes:
    """'D': one motor's status flag, position, speed and PWM."""
    return bytes([ord("D"), motor])


def read_all(subcommand: int) -> bytes:
    """'N': every motor's status flags (ALL_STATUS) or positions (ALL_POSITIONS)."""
    return bytes([ord("N"), subcommand, 0])


def _bytes(what: str, *values: int) -> bytes:
    if not all(0 <= v <= 255 for v in values):
        raise ProtocolError(f"{what} are one byte each (0..255), not {', '.join(map(str, values))}")
    return bytes(values)


def set_speed_limits(motor: int, positive: int, negative: int) -> bytes:
    """'S' 3: `motor`'s speed limits, encoder counts per 10 ms, each 0..255."""
    return bytes([ord("S"), motor, S_SPEED_LIMITS]) + _bytes("speed limits", positive, negative) + b"\0"


def set_controller_parameters(motor: int, k_speed: int, k_pos: int, k_i: int) -> bytes:
    """'S' 1: `motor`'s controller gains: speed, position, integral (kmlMotBase.cpp
    setControllerParameters; the configuration's kspeed_nmp, kpos_nmp, kI_nmp)."""
    return bytes([ord("S"), motor, S_CONTROLLER_PARAMETERS]) + _bytes("controller gains", k_speed, k_pos, k_i)


def set_pwm_limits(motor: int, positive: int, negative: int) -> bytes:
    """'S' 2: `motor`'s largest PWM either way (kmlMotBase.cpp setPwmLimits; maxppwm_nmp, maxnpwm_nmp)."""
    return bytes([ord("S"), motor, S_PWM_LIMITS]) + _bytes("PWM limits", positive, negative) + b"\0"


def set_acceleration_limit(motor: int, acceleration: int) -> bytes:
    """'S' 4: `motor`'s acceleration limit (kmlMotBase.cpp setAccelerationLimit; maxaccel_nmp)."""
    return bytes([ord("S"), motor, S_ACCELERATION_LIMIT]) + _bytes("acceleration limits", acceleration) + b"\0\0"


def _crash_limit(motor: int, subcommand: int, limit: int) -> bytes:
    if not 0 <= limit <= 0xFFFF:
        raise ProtocolError(f"a crash limit is two bytes (0..65535 counts), not {limit}")
    return bytes([ord("S"), motor, subcommand]) + limit.to_bytes(2, "big") + b"\0"


def set_crash_limit(motor: int, limit: int) -> bytes:
    """'S' 5: how far (counts) `motor` may lag its set-point before it reports a collision
    (kmlMotBase.cpp setCrashLimit; crash_limit_nmp), high byte first."""
    return _crash_limit(motor, S_CRASH_LIMIT, limit)


def set_crash_limit_linear(motor: int, limit: int) -> bytes:
    """'S' 6: the same in linear movements (kmlMotBase.cpp setCrashLimitLinear; crash_limit_lin_nmp)."""
    return _crash_limit(motor, S_CRASH_LIMIT_LINEAR, limit)


def collision_detection(on: bool) -> bytes:
    """'A': collision detection on or off, as KNI sends it (COLLISION_DETECTION_ON/OFF)."""
    master, slave = COLLISION_DETECTION_ON if on else COLLISION_DETECTION_OFF
    return bytes([ord("A"), master, slave])


def slave_firmware(motor: int) -> bytes:
    """'V' <motor> 32: `motor`'s slave firmware (kmlMotBase.cpp recvSFW)."""
    return bytes([ord("V"), motor, V_SLAVE_FIRMWARE])


@dataclass(frozen=True)
class MotorReading:
    """What 'D' says of one motor: whether it answered, its status flag, position (counts),
    speed (counts per 10 ms) and PWM."""

    ok: bool
    status: int
    position: int
    velocity: int
    pwm: int


def parse_motor(payload: bytes) -> MotorReading:
    return MotorReading(bool(payload[1]), payload[2], s16(payload[3], payload[4]), s16(payload[5], payload[6]),
                        payload[7])


def parse_positions(payload: bytes, motors: int = MOTORS) -> list[int]:
    return [s16(payload[1 + 2 * i], payload[2 + 2 * i]) for i in range(motors)]


def parse_statuses(payload: bytes, motors: int = MOTORS) -> list[int]:
    return [payload[1 + i] for i in range(motors)]


def parse_firmware(payload: bytes) -> tuple[int, int]:
    """The master firmware's (version, revision) from 'b' (kmlBase.cpp recvMFW)."""
    return payload[1], payload[2]


@dataclass(frozen=True)
class SlaveFirmware:
    """One motor's slave firmware, as 'v' says it (kmlMotBase.h TMotSFW)."""

    version: int
    subversion: int
    revision: int
    type: int           # the controller type; CURRENT_CONTROLLER takes no PWM limits
    subtype: int

    def __str__(self) -> str:
        return f"{self.version}.{self.subversion}.{self.revision}"


def parse_slave_firmware(payload: bytes) -> SlaveFirmware | None:
    """The slave firmware in a 'v' reply: bytes 3..7 (kmlMotBase.cpp recvSFW); None when byte 1,
    the motor's "ok", is 0 (KNI then gives up reading it and takes controller type 0,
    kmlMotBase.cpp init)."""
    if not payload[1]:
        return None
    return SlaveFirmware(*payload[3:8])


def status_name(flag: int) -> str:
    return STATUS_NAMES.get(flag, f"status {flag}")

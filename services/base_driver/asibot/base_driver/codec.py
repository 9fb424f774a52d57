"""ARCOS packet framing: pure functions from values to bytes and back.

Everything here follows docs/arcos.md, "Framing" to "Commands" (ARIA `ArRobotPacket`,
`ArRobotPacketSender`, p2os `packet.cpp`). Nothing does I/O, so every byte is testable.

A packet is `FA FB | COUNT | payload | CHK_hi CHK_lo` with COUNT = len(payload) + 2;
integers in the payload are little-endian, the checksum is big-endian (docs/arcos.md "Framing").
"""

from __future__ import annotations

from typing import Iterator

HEADER = b"\xfa\xfb"

#: ARCOS ignores a command whose COUNT is over 204 (docs/arcos.md "Framing"); P2OS stops at 200.
MAX_COUNT = 204

#: Argument type bytes (docs/arcos.md "Arguments", ARIA ArRobotPacketSender.h).
ARGINT = 0x3B
ARGNINT = 0x1B
ARGSTR = 0x2B

#: The widest integer argument: an unsigned 16-bit magnitude with a sign type byte.
ARG_MAX = 0xFFFF


class Cmd:
    """Client command numbers (docs/arcos.md "Commands", ARIA ArCommands.h)."""

    PULSE = 0
    SYNC0 = 0
    OPEN = 1
    SYNC1 = 1
    CLOSE = 2
    SYNC2 = 2
    POLLING = 3
    ENABLE = 4
    SETA = 5
    SETV = 6
    SETO = 7
    MOVE = 8
    ROTATE = 9
    SETRV = 10
    VEL = 11
    HEAD = 12
    DHEAD = 13
    CONFIG = 18
    RVEL = 21
    SETRA = 23
    SONAR = 28
    STOP = 29
    VEL2 = 32
    BUMPSTALL = 44
    E_STOP = 55


#: Robot-to-client packet types (docs/arcos.md "SIP"): standard SIPs, 0x32 stopped, 0x33 moving.
SIP_TYPES = frozenset({0x30, 0x31, 0x32, 0x33, 0x34})
SIP_STOPPED = 0x32
SIP_MOVING = 0x33


class PacketError(ValueError):
    """Bytes that are not a valid ARCOS packet, or a command that cannot be encoded."""


def checksum(payload: bytes) -> int:
    """ARIA `calcCheckSum`: big-endian 16-bit word sum; an odd last byte is XORed in
    (docs/arcos.md "Framing")."""
    c = 0
    n = len(payload)
    i = 0
    while n > 1:
        c = (c + ((payload[i] << 8) | payload[i + 1])) & 0xFFFF
        n -= 2
        i += 2
    if n > 0:
        c ^= payload[i]
    return c


def frame(payload: bytes) -> bytes:
    """Wrap a payload (command number or packet type first) into a complete packet."""
    if not payload:
        raise PacketError("an ARCOS packet needs at least the command byte")
    count = len(payload) + 2
    if count > MAX_COUNT:
        raise PacketError(f"payload of {len(payload)} bytes is too long: ARCOS ignores COUNT > {MAX_COUNT}")
    c = checksum(payload)
    return HEADER + bytes([count]) + bytes(payload) + bytes([c >> 8, c & 0xFF])


def command(cmd: int) -> bytes:
    """A command without argument, e.g. PULSE = FA FB 03 00 00 00."""
    _check_cmd(cmd)
    return frame(bytes([cmd]))


def command_int(cmd: int, value: int) -> bytes:
    """A command with a signed integer argument: 0x3B |v| or 0x1B |v| (ARIA comInt,
    docs/arcos.md "Arguments")."""
    _check_cmd(cmd)
    if isinstance(value, bool) or not isinstance(value, int):
        raise PacketError(f"command {cmd} needs an integer argument, got {value!r}")
    magnitude = abs(value)
    if magnitude > ARG_MAX:
        raise PacketError(f"argument {value} of command {cmd} does not fit 16 bits (|v| <= {ARG_MAX})")
    kind = ARGNINT if value < 0 else ARGINT
    return frame(bytes([cmd, kind, magnitude & 0xFF, magnitude >> 8]))


def command_str(cmd: int, text: bytes) -> bytes:
    """A command with a string argument: 0x2B, length byte, characters (at most 199)."""
    _check_cmd(cmd)
    if len(text) > 199:
        raise PacketError(f"string argument of {len(text)} bytes is too long: ARCOS takes at most 199")
    return frame(bytes([cmd, ARGSTR, len(text)]) + bytes(text))


def command_2bytes(cmd: int, high: int, low: int) -> bytes:
    """ARIA com2Bytes: the int16 (high<<8 | low), sent as a signed int argument
    (docs/arcos.md "Arguments")."""
    word = ((high & 0xFF) << 8) | (low & 0xFF)
    if word >= 0x8000:
        word -= 0x10000
    return command_int(cmd, word)


def vel2(left_mm_s: int, right_mm_s: int, divisor: int = 20) -> bytes:
    """VEL2: each wheel / Vel2Divisor clamped to a signed byte; high byte = left
    (docs/arcos.md "Motion and watchdog")."""
    def wheel(v: int) -> int:
        return max(-128, min(127, int(round(v / divisor)))) & 0xFF
    return command_2bytes(Cmd.VEL2, wheel(left_mm_s), wheel(right_mm_s))


def _check_cmd(cmd: int) -> None:
    if isinstance(cmd, bool) or not isinstance(cmd, int) or not 0 <= cmd <= 255:
        raise PacketError(f"command number must be 0..255, got {cmd!r}")


# ------------------------------------------------------------------ receiving
def verify(packet: bytes) -> bool:
    """True when `packet` is a well-formed packet whose checksum matches (ARIA verifyCheckSum).

    Deliberately not p2os's `Check()`, which accepts any packet whose last byte is non-zero.
    """
    if len(packet) < 6 or packet[:2] != HEADER or packet[2] != len(packet) - 3:
        return False
    return ((packet[-2] << 8) | packet[-1]) == checksum(packet[3:-2])


def payload_of(packet: bytes) -> bytes:
    """The payload (type byte first) of a verified packet."""
    if not verify(packet):
        raise PacketError(f"not a valid ARCOS packet: {packet.hex(' ')}")
    return packet[3:-2]


class Deframer:
    """Turns a byte stream into verified payloads, skipping garbage (p2os `Receive`, docs/arcos.md "Framing").

    Feed it whatever the line delivered; it keeps partial packets between calls. On a bad
    checksum it drops only the first header byte and searches again, so a packet hidden
    right after a corrupt one is still found.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.dropped_bytes = 0
        self.bad_checksums = 0

    def feed(self, data: bytes) -> Iterator[bytes]:
        """Add bytes; yield each complete, verified payload in order."""
        self._buf += data
        buf = self._buf
        while True:
            start = buf.find(HEADER)
            if start < 0:
                keep = 1 if buf[-1:] == HEADER[:1] else 0
                self.dropped_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
                return
            if start:
                self.dropped_bytes += start
                del buf[:start]
            if len(buf) < 3:
                return
            count = buf[2]
            if count < 3 or count > MAX_COUNT:
                self.dropped_bytes += 1
                del buf[:1]
                continue
            if len(buf) < count + 3:
                return
            packet = bytes(buf[: count + 3])
            if verify(packet):
                del buf[: count + 3]
                yield packet[3:-2]
            else:
                self.bad_checksums += 1
                self.dropped_bytes += 1
                del buf[:1]

    def clear(self) -> None:
        self._buf.clear()

    @property
    def pending(self) -> int:
        return len(self._buf)

"""The standard Server Information Packet (SIP), in raw ARCOS units, both directions.

Layout from docs/arcos.md, "SIP" (ARIA `processMotorPacket`, p2os
`ParseStandard`). Values stay in firmware units here; `params.RobotParams` converts them,
because the conversion depends on which controller (p3at or p3at-sh) answered the sync.
Optional tail fields are read only if bytes remain, as ARIA does.
"""

from __future__ import annotations

import dataclasses
import struct

from asibot.base_driver.codec import SIP_MOVING, SIP_STOPPED, SIP_TYPES, PacketError

_HEAD = struct.Struct("<BHHhhhBHhHBB")  # type .. SONAR_COUNT
_SONAR = struct.Struct("<BH")
#: GRIP_STATE ANPORT ANALOG DIGIN DIGOUT BATTERYX10 CHARGESTATE ROTVEL
_TAIL = struct.Struct("<BBBBBHBh")

#: FLAGS bits (docs/arcos.md "SIP").
FLAG_MOTORS_ENABLED = 1 << 0
FLAG_ESTOP = 1 << 5

#: STALL_BUMPERS bits (docs/arcos.md "SIP"): bit 0 left stall, 1-7 bumpers, 8 right stall, 9-15 rear set.
STALL_LEFT = 1 << 0
STALL_RIGHT = 1 << 8
BUMPER_BITS = 7


@dataclasses.dataclass
class Sip:
    """One SIP in firmware units: positions 15-bit counts, velocities mm/s, battery 0.1 V."""

    moving: bool = False
    xpos: int = 0             # low 15 bits used
    ypos: int = 0
    thpos: int = 0            # AngleConvFactor units (4096 per turn)
    left_vel: int = 0         # x VelConvFactor -> mm/s
    right_vel: int = 0
    battery: int = 0          # volts x 10
    stall_bumpers: int = 0
    control: int = 0
    flags: int = 0
    compass: int = 0
    sonars: dict[int, int] = dataclasses.field(default_factory=dict)  # index -> range units
    battery_x10: int | None = None   # optional tail, more precise than `battery`
    rot_vel_x10: int | None = None   # optional tail, deg/s x 10

    @property
    def motors_enabled(self) -> bool:
        return bool(self.flags & FLAG_MOTORS_ENABLED)

    @property
    def estop_pressed(self) -> bool:
        return bool(self.flags & FLAG_ESTOP)

    @property
    def stall_left(self) -> bool:
        return bool(self.stall_bumpers & STALL_LEFT)

    @property
    def stall_right(self) -> bool:
        return bool(self.stall_bumpers & STALL_RIGHT)

    @property
    def front_bumpers(self) -> list[bool]:
        return [bool(self.stall_bumpers & (1 << (1 + i))) for i in range(BUMPER_BITS)]

    @property
    def rear_bumpers(self) -> list[bool]:
        return [bool(self.stall_bumpers & (1 << (9 + i))) for i in range(BUMPER_BITS)]


def is_sip(payload: bytes) -> bool:
    return bool(payload) and payload[0] in SIP_TYPES


def parse_sip(payload: bytes) -> Sip:
    """Decode a SIP payload (type byte first). Raises PacketError if it is truncated."""
    if not is_sip(payload):
        kind = f"0x{payload[0]:02X}" if payload else "empty"
        raise PacketError(f"packet type {kind} is not a standard SIP (0x30-0x34)")
    if len(payload) < _HEAD.size:
        raise PacketError(f"SIP of {len(payload)} bytes is truncated: the fixed part is {_HEAD.size}")
    (ptype, x, y, th, lv, rv, batt, sb, control, flags, compass, count) = _HEAD.unpack_from(payload)
    off = _HEAD.size
    if len(payload) < off + count * _SONAR.size:
        raise PacketError(f"SIP announces {count} sonar readings but holds fewer")
    sonars = {}
    for _ in range(count):
        idx, rng = _SONAR.unpack_from(payload, off)
        sonars[idx] = rng
        off += _SONAR.size
    sip = Sip(moving=ptype == SIP_MOVING, xpos=x & 0x7FFF, ypos=y & 0x7FFF, thpos=th,
              left_vel=lv, right_vel=rv, battery=batt, stall_bumpers=sb, control=control,
              flags=flags, compass=compass, sonars=sonars)
    if len(payload) >= off + _TAIL.size:
        (_grip, _anport, _analog, _digin, _digout, battx10, _charge, rotvel) = _TAIL.unpack_from(payload, off)
        sip.battery_x10 = battx10
        sip.rot_vel_x10 = rotvel
    return sip


def encode_sip(sip: Sip) -> bytes:
    """The payload ARCOS would send for `sip` (used by the emulator and the tests)."""
    ptype = SIP_MOVING if sip.moving else SIP_STOPPED
    out = bytearray(_HEAD.pack(
        ptype, sip.xpos & 0x7FFF, sip.ypos & 0x7FFF, _i16(sip.thpos), _i16(sip.left_vel),
        _i16(sip.right_vel), max(0, min(255, sip.battery)), sip.stall_bumpers & 0xFFFF,
        _i16(sip.control), sip.flags & 0xFFFF, sip.compass & 0xFF, len(sip.sonars)))
    for idx, rng in sorted(sip.sonars.items()):
        out += _SONAR.pack(idx, max(0, min(0xFFFF, rng)))
    if sip.battery_x10 is not None or sip.rot_vel_x10 is not None:
        out += _TAIL.pack(0, 0, 0, 0, 0, max(0, min(0xFFFF, sip.battery_x10 or 0)), 0,
                          _i16(sip.rot_vel_x10 or 0))
    return bytes(out)


def _i16(v: int) -> int:
    return max(-0x8000, min(0x7FFF, int(v)))


def parse_sync2(payload: bytes) -> tuple[str, str, str]:
    """The SYNC2 reply: command byte 2, then NUL-terminated name, class, subclass
    (docs/arcos.md "Connection")."""
    if not payload or payload[0] != 2:
        raise PacketError("not a SYNC2 reply")
    parts = payload[1:].split(b"\x00")
    if len(parts) < 4:
        raise PacketError("SYNC2 reply must carry three NUL-terminated strings (name, class, subclass)")
    name, klass, subclass = (p.decode("latin-1") for p in parts[:3])
    return name, klass, subclass


def encode_sync2(name: str, klass: str, subclass: str) -> bytes:
    return b"\x02" + b"".join(s.encode("latin-1") + b"\x00" for s in (name, klass, subclass))

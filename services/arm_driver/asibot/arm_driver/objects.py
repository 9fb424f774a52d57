"""The CiA 301/402 and Technosoft iPOS objects this stack reads, writes or maps into PDOs.

One table shared by the master (to encode SDO values and decode PDOs) and the emulator (its
object dictionary), so both sides agree on every object's size and sign by construction.
Indices and meanings: docs/canopen.md, "Objects".
"""

from __future__ import annotations

import struct
from dataclasses import dataclass


@dataclass(frozen=True)
class ObjectType:
    """How an object's value travels: its bit size and whether it is signed."""

    bits: int
    signed: bool

    @property
    def size(self) -> int:
        return self.bits // 8

    @property
    def fmt(self) -> str:
        code = {8: "b", 16: "h", 32: "i"}[self.bits]
        return "<" + (code if self.signed else code.upper())

    def encode(self, value: int) -> bytes:
        lo, hi = self.limits
        if not lo <= value <= hi:
            raise ValueError(f"{value} does not fit in a{' signed' if self.signed else 'n unsigned'} "
                             f"{self.bits}-bit object (range {lo}..{hi})")
        return struct.pack(self.fmt, value)

    def decode(self, data: bytes) -> int:
        return struct.unpack(self.fmt, bytes(data[: self.size]))[0]

    @property
    def limits(self) -> tuple[int, int]:
        if self.signed:
            return -(1 << (self.bits - 1)), (1 << (self.bits - 1)) - 1
        return 0, (1 << self.bits) - 1


U8, I8 = ObjectType(8, False), ObjectType(8, True)
U16, I16 = ObjectType(16, False), ObjectType(16, True)
U32, I32 = ObjectType(32, False), ObjectType(32, True)

# Index -> type, or (index, subindex) -> type where subindices differ.
DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
MANUFACTURER_STATUS = 0x1002      # iPOS: low word = statusword, high word = MSR
HEARTBEAT_CONSUMER = 0x1016      # sub n: (producer node << 16) | time in ms (CiA 301)
HEARTBEAT_PRODUCER = 0x1017
IDENTITY = 0x1018
RPDO_COMM, RPDO_MAP = 0x1400, 0x1600
TPDO_COMM, TPDO_MAP = 0x1800, 0x1A00
MOTION_ERROR = 0x2000             # MER
DETAILED_ERROR = 0x2002           # DER
SET_ACTUAL_POSITION = 0x2081      # iPOS: overwrite the position counter (absolute encoder sync)
ABORT_CONNECTION = 0x6007        # CiA 402 abort connection option code: what a drive does on a lost master
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
MODES = 0x6060
MODES_DISPLAY = 0x6061
POSITION_INTERNAL = 0x6063
POSITION_ACTUAL = 0x6064
VELOCITY_ACTUAL = 0x606C
TORQUE_ACTUAL = 0x6077
TARGET_POSITION = 0x607A
SOFTWARE_LIMITS = 0x607D          # sub1 min, sub2 max
PROFILE_VELOCITY = 0x6081
PROFILE_ACCELERATION = 0x6083
INTERPOLATION_PERIOD = 0x60C2     # sub1 value, sub2 index (10^index s)
SUPPORTED_MODES = 0x6502

_TYPES: dict[int | tuple[int, int], ObjectType] = {
    DEVICE_TYPE: U32, ERROR_REGISTER: U8, MANUFACTURER_STATUS: U32, HEARTBEAT_PRODUCER: U16,
    IDENTITY: U32, MOTION_ERROR: U16, DETAILED_ERROR: U16, CONTROLWORD: U16, STATUSWORD: U16,
    MODES: I8, MODES_DISPLAY: I8, POSITION_INTERNAL: I32, POSITION_ACTUAL: I32,
    VELOCITY_ACTUAL: I32, TORQUE_ACTUAL: I16, TARGET_POSITION: I32, SOFTWARE_LIMITS: I32,
    PROFILE_VELOCITY: U32, PROFILE_ACCELERATION: U32, SET_ACTUAL_POSITION: I32,
    (INTERPOLATION_PERIOD, 1): U8, (INTERPOLATION_PERIOD, 2): I8, SUPPORTED_MODES: U32,
    (IDENTITY, 0): U8, (HEARTBEAT_CONSUMER, 0): U8, HEARTBEAT_CONSUMER: U32, ABORT_CONNECTION: I16,
}
for _n in range(4):
    _TYPES.update({(RPDO_COMM + _n, 1): U32, (RPDO_COMM + _n, 2): U8,
                   (TPDO_COMM + _n, 1): U32, (TPDO_COMM + _n, 2): U8, (TPDO_COMM + _n, 3): U16,
                   (TPDO_COMM + _n, 5): U16, (RPDO_MAP + _n, 0): U8, (TPDO_MAP + _n, 0): U8})
    for _s in range(1, 9):
        _TYPES[(RPDO_MAP + _n, _s)] = U32
        _TYPES[(TPDO_MAP + _n, _s)] = U32


def type_of(index: int, subindex: int = 0) -> ObjectType:
    """The type of object index:subindex; KeyError names it when this stack does not know it."""
    found = _TYPES.get((index, subindex)) or _TYPES.get(index)
    if found is None:
        raise KeyError(f"object 0x{index:04X}:{subindex:02X} is not in the arm driver's object table")
    return found


def known(index: int, subindex: int = 0) -> bool:
    return (index, subindex) in _TYPES or index in _TYPES


# 0x6007 values (CiA 402): 0 no action, 1 fault signal, 2 disable voltage, 3 quick stop.
CONNECTION_LOSS = {"none": 0, "fault": 1, "disable_voltage": 2, "quick_stop": 3}

# Bits of 0x6502 "supported drive modes" (CiA 402): bit 0 profile position, bit 7 CSP.
MODE_PROFILE_POSITION = 1
MODE_CSP = 8
SUPPORTS_PP = 1 << 0
SUPPORTS_CSP = 1 << 7

"""EMCY frames -> one sentence a person can act on.

Codes: Technosoft iPOS (TechnosoftIposEmcy.cpp) and generic CiA 301 ones (EmcyConsumer.cpp),
as listed in docs/canopen.md, "EMCY codes". Frame layout: u16 code, u8 error register,
5 manufacturer bytes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

ERROR_RESET = 0x0000

# code -> (what happened, what to do)
MEANINGS: dict[int, tuple[str, str]] = {
    0x2310: ("continuous over-current", "check the load on the joint and the motor wiring"),
    0x2340: ("a short-circuit", "check the motor cables for a short"),
    0x3210: ("DC-link over-voltage", "check the power supply; braking energy may be too high"),
    0x3220: ("DC-link under-voltage", "check the power supply and its cables"),
    0x4280: ("motor over-temperature", "let the motor cool down and reduce the duty"),
    0x4310: ("drive over-temperature", "let the drive cool down and check its ventilation"),
    0x5441: ("the drive was disabled by its enable input (STO)", "check the enable/STO circuit"),
    0x5442: ("the negative limit switch", "move the joint away from the switch"),
    0x5443: ("the positive limit switch", "move the joint away from the switch"),
    0x6100: ("invalid setup data", "re-flash the drive setup"),
    0x7300: ("a sensor (encoder) error", "check the encoder cable"),
    0x7500: ("a communication error", "check the CAN cable and termination"),
    0x8110: ("a CAN overrun (frames lost)", "lower the bus load or the control rate"),
    0x8120: ("CAN error passive", "check the CAN cable, termination and bit rate"),
    0x8130: ("a heartbeat or life guard error", "check the CAN cable; the drive lost the master"),
    0x8140: ("recovery from CAN bus-off", "check the CAN cable, termination and bit rate"),
    0x8250: ("an RPDO timeout", "the drive stopped receiving set-points; check the bus"),
    0x8331: ("an I2t overload", "reduce the load or the speed on this joint"),
    0x8580: ("a position wraparound", "re-home the joint"),
    0x8611: ("a following (control) error", "check for a collision or a blocked joint"),
    0x9000: ("a command error", "the drive refused a command; check the driver configuration"),
    0xFF01: ("an interpolated-position buffer error", "restart the motion"),
    0xFF02: ("a wrong change-set acknowledge", "restart the motion"),
    0xFF03: ("an unavailable homing method", "check the homing configuration"),
    0xFF04: ("a wrong mode in 0x6060", "the drive setup must close the position loop"),
    0xFF05: ("an unavailable digital I/O line", "check the drive setup"),
    0xFF06: ("its positive software position limit", "move the joint back inside its limits"),
    0xFF07: ("its negative software position limit", "move the joint back inside its limits"),
    0xFF08: ("an enable-circuit hardware error", "service the drive"),
}

# Generic error-register groups for codes not in the table (CiA 301 table 21).
_GROUPS = {0x1: "a generic error", 0x2: "a current error", 0x3: "a voltage error",
           0x4: "a temperature error", 0x5: "a device hardware error", 0x6: "a device software error",
           0x7: "an additional-module error", 0x8: "a monitoring or communication error",
           0x9: "an external error", 0xF: "an additional-function error"}


@dataclass(frozen=True)
class Emcy:
    code: int
    register: int
    data: bytes

    @classmethod
    def decode(cls, payload: bytes) -> "Emcy":
        if len(payload) != 8:
            raise ValueError(f"an EMCY frame has 8 bytes, this one {len(payload)}")
        code, register = struct.unpack_from("<HB", payload)
        return cls(code, register, bytes(payload[3:8]))

    def encode(self) -> bytes:
        return struct.pack("<HB", self.code, self.register) + self.data.ljust(5, b"\0")[:5]

    @property
    def is_reset(self) -> bool:
        return self.code & 0xFF00 == ERROR_RESET


def sentence(emcy: Emcy, node: int, joint: str) -> str:
    """'Drive 3 (joint q3) reports continuous over-current (EMCY 0x2310). The arm was stopped. ...'"""
    what, todo = MEANINGS.get(emcy.code, (None, None))
    if what is None:
        what = _GROUPS.get(emcy.code >> 12, "an unknown error")
        todo = "look the code up in the drive manual"
    extra = ""
    if emcy.code in (0x7300, 0x7500):
        detail = struct.unpack_from("<H", emcy.data, 0)[0]
        extra = f", detail register 0x{detail:04X}"
    return (f"Drive {node} (joint {joint}) reports {what} (EMCY 0x{emcy.code:04X}{extra}). "
            f"The arm was stopped: {todo}, then call reset_fault.")

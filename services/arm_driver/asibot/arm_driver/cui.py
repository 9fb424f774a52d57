"""The ASIBOT's absolute encoders: CUI AMT20 boards behind a UC3M PIC, one CAN id each.

The iPOS drives count incrementally from wherever they were powered on, so after a power
cycle q2..q4 would be believed at 0 deg wherever they really are. The seed read each joint's
absolute encoder at start-up and wrote it into the drive's position counter (0x2081, "Set
actual position"; docs/canopen.md, "Absolute encoders" and "Start-up"). q1 and q5 have no
absolute encoder: the arm must be powered on with them at their zero.

The PIC's protocol, as yarp-devices' CuiAbsolute speaks it (pull mode, as the ASIBOT uses):
  request  id          1 byte  0x03            poll once
  reply    id + 0x180  4 bytes float32 LE      joint angle in degrees
  request  id          2 bytes 0x01, delay     start push mode (ack on id + 0x100,
                                               data on id + 0x80); 0x02 stops it
A reply whose fourth byte is 0xC4 is the PIC's known error code, not an angle.
"""

from __future__ import annotations

import math
import struct

POLL = 0x03
PUSH_START = 0x01
PUSH_STOP = 0x02
REPLY_POLL = 0x180
REPLY_PUSH_DATA = 0x080
REPLY_PUSH_ACK = 0x100
PIC_ERROR = 0xC4
TIMEOUT_S = 0.1          # CuiAbsolute's DEFAULT_TIMEOUT
RETRIES = 5              # and DEFAULT_MAX_RETRIES


class EncoderError(ValueError):
    """A reply that is not an angle."""


def poll_request() -> bytes:
    return bytes([POLL])


def angle_reply(degrees: float) -> bytes:
    """What the PIC answers to a poll (used by the emulator)."""
    return struct.pack("<f", degrees)


def parse_angle(data: bytes, reverse: bool = False) -> float:
    """Degrees in [-180, 180] from a poll reply; EncoderError on an error code or garbage."""
    if len(data) != 4:
        raise EncoderError(f"a reply of {len(data)} bytes instead of 4")
    if data[3] == PIC_ERROR:
        raise EncoderError(f"the encoder board reports an error (bytes {data.hex(' ')})")
    (deg,) = struct.unpack("<f", data)
    if not math.isfinite(deg) or abs(deg) > 360.0:
        raise EncoderError(f"{deg!r} is not an angle (bytes {data.hex(' ')})")
    if reverse:
        deg = -deg
    if deg < -180.0:
        deg += 360.0
    elif deg > 180.0:
        deg -= 360.0
    return deg

"""An emulated absolute encoder board: a CUI AMT20 behind the UC3M PIC, in pull mode.

Pure: a poll in, the reply frame out. The bytes are the real driver's own (`asibot.arm_driver.cui`,
docs/canopen.md "Absolute encoders"): a one-byte poll 0x03 on the board's CAN id is answered on
id + 0x180 with the joint's angle as a little-endian float32 in degrees, quantised to the
encoder's 12-bit steps. A faulty board is 'silent' (no answer) or answers 'error' (the PIC's
error code 0xC4 in the fourth byte).
"""

from __future__ import annotations

import math

from asibot.arm_driver import cui

STEP_DEG = 360.0 / 4096     # the AMT20 is a 12-bit single-turn encoder


def answer(can_id: int, data: bytes, joint_angle: float, reverse: bool,
           fault: str | None = None) -> tuple[int, bytes] | None:
    """The (CAN id, data) the board at `can_id` sends for `data`, whose joint is at `joint_angle`
    rad; None when it stays silent (not a poll, or a 'silent' fault)."""
    if data != cui.poll_request() or fault == "silent":
        return None
    deg = math.degrees(joint_angle) * (-1 if reverse else 1)
    deg = round(deg / STEP_DEG) * STEP_DEG
    reply = bytes([0, 0, 0, cui.PIC_ERROR]) if fault == "error" else cui.angle_reply(deg)
    return can_id + cui.REPLY_POLL, reply

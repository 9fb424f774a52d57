"""How many bits a classic CAN frame occupies on the wire, to turn frame counts into bus load.

A standard (11-bit id) data frame is 47 + 8n bits before stuffing; the transmitter inserts a
complementary bit after five equal ones from SOF to the end of the CRC. `worst_case_bits` is
the usual bound (Davis et al., 2007: floor((34 + 8n - 1) / 4) stuff bits); `exact_bits` stuffs
the actual bit stream, CRC-15 included, for frames seen on a bus.
"""

from __future__ import annotations

FIXED_TAIL = 1 + 1 + 1 + 7 + 3     # CRC delimiter, ACK slot, ACK delimiter, EOF, intermission


def worst_case_bits(data_bytes: int) -> int:
    return 47 + 8 * data_bytes + (34 + 8 * data_bytes - 1) // 4


def _crc15(bits: list[int]) -> int:
    crc = 0
    for b in bits:
        top = ((crc >> 14) & 1) ^ b
        crc = (crc << 1) & 0x7FFF
        if top:
            crc ^= 0x4599
    return crc


def exact_bits(arbitration_id: int, data: bytes) -> int:
    """Bits on the wire for one standard data frame, stuff bits counted exactly."""
    bits = [0] + [(arbitration_id >> i) & 1 for i in range(10, -1, -1)] + [0, 0, 0]   # SOF, id, RTR, IDE, r0
    bits += [(len(data) >> i) & 1 for i in range(3, -1, -1)]
    for byte in data:
        bits += [(byte >> i) & 1 for i in range(7, -1, -1)]
    crc = _crc15(bits)
    bits += [(crc >> i) & 1 for i in range(14, -1, -1)]
    stuffed, run, last = 0, 0, None
    for b in bits:
        run = run + 1 if b == last else 1
        last = b
        if run == 5:
            stuffed += 1
            last, run = 1 - b, 1      # the stuff bit starts a new run
    return len(bits) + stuffed + FIXED_TAIL

"""Frame bit lengths used for the bus-load figures."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from asibot.arm_driver.bitlength import exact_bits, worst_case_bits


def test_worst_case_lengths():
    # 0 bytes: 47 + 8 stuff bits; 8 bytes: 111 + 24 (the classic 135-bit maximum).
    assert worst_case_bits(0) == 55 and worst_case_bits(8) == 135
    assert worst_case_bits(4) == 95 and worst_case_bits(6) == 115


def test_a_frame_of_alternating_bits_needs_no_stuffing_in_its_data():
    # 0x555 = 101 0101 0101 and 0x55 data bytes alternate, so only the CRC may add stuff bits.
    assert 47 + 8 <= exact_bits(0x555, b"\x55") <= 47 + 8 + 4


@given(st.integers(0, 0x7FF), st.binary(min_size=0, max_size=8))
def test_exact_lengths_lie_between_unstuffed_and_worst_case(cob_id, data):
    n = len(data)
    assert 47 + 8 * n <= exact_bits(cob_id, data) <= worst_case_bits(n)

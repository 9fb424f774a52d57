"""ARCOS framing, byte for byte (docs/arcos.md, "Framing" and "Arguments")."""

import pytest
from hypothesis import given, strategies as st

from asibot.base_driver import codec
from asibot.base_driver.codec import Cmd, Deframer, PacketError


def test_sync_packets_are_the_documented_bytes():
    assert codec.command(Cmd.SYNC0) == bytes.fromhex("FA FB 03 00 00 00")
    assert codec.command(Cmd.SYNC1) == bytes.fromhex("FA FB 03 01 00 01")
    assert codec.command(Cmd.SYNC2) == bytes.fromhex("FA FB 03 02 00 02")
    assert codec.command(Cmd.PULSE) == bytes.fromhex("FA FB 03 00 00 00")


def test_vel_plus_300_is_the_documented_packet_with_its_checksum():
    # payload 0B 3B 2C 01 -> words 0x0B3B + 0x2C01 = 0x373C, sent high byte first
    assert codec.command_int(Cmd.VEL, 300) == bytes.fromhex("FA FB 06 0B 3B 2C 01 37 3C")


def test_negative_argument_is_0x1b_and_the_absolute_value():
    # payload 0B 1B 2C 01 -> 0x0B1B + 0x2C01 = 0x371C
    assert codec.command_int(Cmd.VEL, -300) == bytes.fromhex("FA FB 06 0B 1B 2C 01 37 1C")
    assert codec.command_int(Cmd.RVEL, -1)[3:7] == bytes([21, 0x1B, 0x01, 0x00])


def test_zero_argument_is_positive():
    assert codec.command_int(Cmd.ENABLE, 0)[3:7] == bytes([4, 0x3B, 0, 0])


def test_checksum_of_odd_length_payload_xors_the_last_byte():
    assert codec.checksum(bytes([0x01, 0x02, 0x03])) == 0x0102 ^ 0x03
    assert codec.checksum(bytes([0x21])) == 0x0021
    # sum wraps at 16 bits before the XOR
    assert codec.checksum(bytes([0xFF, 0xFF, 0x00, 0x02, 0x80])) == ((0xFFFF + 0x0002) & 0xFFFF) ^ 0x80
    packet = codec.frame(bytes([0x01, 0x02, 0x03]))
    assert packet == bytes.fromhex("FA FB 05 01 02 03 01 01")


def test_string_argument_layout():
    packet = codec.command_str(Cmd.POLLING, b"\x01\x02")
    assert packet[2:-2] == bytes([7, 3, 0x2B, 2, 1, 2])
    with pytest.raises(PacketError, match="199"):
        codec.command_str(Cmd.POLLING, b"x" * 200)


def test_com2bytes_and_vel2_follow_aria():
    # high byte 0x80 makes a negative short: sent as 0x1B with its absolute value
    packet = codec.command_2bytes(Cmd.VEL2, 0x80, 0x00)
    assert packet[3:7] == bytes([32, 0x1B, 0x00, 0x80])
    # left 100 mm/s -> 5, right -40 -> -2 (0xFE): word 0x05FE, right byte first on the wire
    assert codec.vel2(100, -40)[3:7] == bytes([32, 0x3B, 0xFE, 0x05])
    assert codec.vel2(10_000, 0)[3:7] == bytes([32, 0x3B, 0x00, 0x7F])   # clamped to 127 steps


@pytest.mark.parametrize("bad", [70000, -70000, 1.5, True, "3"])
def test_bad_integer_arguments_are_refused(bad):
    with pytest.raises(PacketError):
        codec.command_int(Cmd.VEL, bad)


@pytest.mark.parametrize("bad", [-1, 256, None])
def test_bad_command_numbers_are_refused(bad):
    with pytest.raises(PacketError):
        codec.command(bad)


def test_too_long_payload_is_refused():
    codec.frame(bytes(202))  # COUNT 204 is the largest ARCOS accepts
    with pytest.raises(PacketError, match="204"):
        codec.frame(bytes(203))
    with pytest.raises(PacketError):
        codec.frame(b"")


def test_verify_is_not_the_p2os_bug():
    good = codec.command_int(Cmd.VEL, 300)
    assert codec.verify(good)
    # wrong high checksum byte, non-zero last byte: p2os' Check() would accept this
    bad = good[:-2] + bytes([good[-2] ^ 0x10, good[-1]])
    assert not codec.verify(bad)
    assert not codec.verify(good[:-1])
    assert not codec.verify(b"\xfa\xfc" + good[2:])
    with pytest.raises(PacketError):
        codec.payload_of(bad)
    assert codec.payload_of(good) == bytes([0x0B, 0x3B, 0x2C, 0x01])


def test_deframer_skips_garbage_and_handles_split_packets():
    a = codec.command_int(Cmd.VEL, 300)
    b = codec.command(Cmd.PULSE)
    stream = b"\x00\x13junk\xfa" + a + b"\xfa\xfb\xff\x01" + b
    d = Deframer()
    got = []
    for i in range(len(stream)):          # one byte at a time
        got += list(d.feed(stream[i:i + 1]))
    assert got == [a[3:-2], b[3:-2]]
    assert d.dropped_bytes > 0


def test_deframer_recovers_a_packet_hidden_after_a_corrupt_header():
    good = codec.command_int(Cmd.RVEL, -20)
    corrupt = bytes.fromhex("FA FB 06 0B 3B 2C 01 00 00")  # bad checksum
    d = Deframer()
    # the corrupt packet's COUNT swallows the first bytes of the good one only if not resynced
    assert list(d.feed(corrupt[:4] + good)) == [good[3:-2]]
    assert d.bad_checksums >= 1


def test_deframer_rejects_impossible_counts():
    d = Deframer()
    assert list(d.feed(b"\xfa\xfb\x02\x00\x00" + codec.command(Cmd.SYNC1))) == [b"\x01"]
    assert list(d.feed(b"\xfa\xfb\xff" + codec.command(Cmd.SYNC2))) == [b"\x02"]


payloads = st.binary(min_size=1, max_size=202)


@given(payloads)
def test_frame_then_deframe_roundtrips(payload):
    packet = codec.frame(payload)
    assert len(packet) == packet[2] + 3
    assert codec.verify(packet)
    assert list(Deframer().feed(packet)) == [payload]


@given(st.binary(max_size=64).map(lambda b: b.replace(b"\xfa", b"")), payloads, st.integers(1, 16))
def test_any_header_free_garbage_before_a_packet_is_skipped(garbage, payload, chunk):
    stream = garbage + codec.frame(payload)
    d = Deframer()
    got = []
    for i in range(0, len(stream), chunk):
        got += list(d.feed(stream[i:i + chunk]))
    assert got == [payload]


@given(payloads, st.integers(0, 400), st.integers(1, 255))
def test_any_single_byte_corruption_after_the_count_is_detected(payload, pos, flip):
    packet = bytearray(codec.frame(payload))
    i = 3 + pos % (len(packet) - 3)      # a payload or checksum byte
    packet[i] ^= flip
    assert not codec.verify(bytes(packet))
    assert bytes(packet[3:-2]) not in list(Deframer().feed(bytes(packet)))

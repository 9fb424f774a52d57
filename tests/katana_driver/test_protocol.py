"""The serial protocol's frames, CRC and units against the facts of docs/katana.md."""

from __future__ import annotations

import math

import pytest

from asibot import robots
from asibot.katana_driver import protocol as p
from asibot.katana_driver.katana import (KATANA_300_6M180, MAX_SPEED, gripper_counts, gripper_opening)


@pytest.mark.parametrize("data, crc", [
    (b"123456789", 0xBB3D),     # CRC-16/ARC's check value
    (b"\x01", 0xC0C1),          # KNI CRC.cpp: CRChi_ARRAY[1] = 0xc0, CRClo_ARRAY[1] = 0xc1
    (b"\xff", 0x4040),          # KNI CRC.cpp: CRChi_ARRAY[255] = 0x40, CRClo_ARRAY[255] = 0x40
    (b"", 0x0000),
])
def test_the_crc_is_kni_s(data, crc):
    assert p.crc16(data) == crc


def test_the_crc_of_one_byte_is_kni_s_table_entry():
    """For one byte b, KNI's CRC is CRChi_ARRAY[b] << 8 | CRClo_ARRAY[b]; the first row of each
    table (CRC.cpp lines 26 and 63)."""
    hi = [0x00, 0xC0, 0xC1, 0x01, 0xC3, 0x03, 0x02, 0xC2]
    lo = [0x00, 0xC1, 0x81, 0x40, 0x01, 0xC0, 0x80, 0x41]
    assert [p.crc16(bytes([b])) for b in range(8)] == [h << 8 | l for h, l in zip(hi, lo)]


def test_a_request_frame_is_header_payload_crc():
    frame = p.encode_request(p.read_motor(3))
    crc = p.crc16(b"D\x03")
    assert frame == bytes([1, 24, 2, ord("D"), 3, crc >> 8, crc & 0xFF])
    assert p.decode_request(frame) == (24, b"D\x03")
    assert p.request_length(frame[:3]) == len(frame)


@pytest.mark.parametrize("payload", [
    p.master_firmware(), p.echo(), p.read_all(p.ALL_POSITIONS), p.read_all(p.ALL_STATUS),
    p.set_target(2, p.MCF_ON, -30000), p.set_target(6, p.MCF_FREEZE, 32767), p.set_actual(1, p.MCF_FREEZE, -31000),
    p.set_speed_limits(4, 180, 180), p.read_motor(6),
])
def test_every_request_round_trips_with_kni_s_sizes(payload):
    frame = p.encode_request(payload)
    assert frame[2] == p.SIZES[payload[0]][0] == len(payload)
    assert p.decode_request(frame) == (p.ADDRESS, payload)


def test_positions_are_signed_16_bit_high_byte_first():
    assert p.set_target(1, p.MCF_ON, -2) == b"C\x01\x18\xff\xfe"
    assert p.s16(0xFF, 0xFE) == -2 and p.s16(0x79, 0x18) == 31000
    with pytest.raises(p.ProtocolError, match="16-bit"):
        p.set_target(1, p.MCF_ON, 40000)


def test_a_reply_is_checked_for_size_crc_and_echo():
    reply = p.encode_reply(b"d\x01\x08\x79\x18\x00\x00\x00")
    reading = p.parse_motor(p.decode_reply(ord("D"), reply))
    assert reading == p.MotorReading(True, p.MSF_DESPOS, 31000, 0, 0)
    with pytest.raises(p.ProtocolError, match="10 bytes"):
        p.decode_reply(ord("D"), reply[:-1])
    with pytest.raises(p.ProtocolError, match="CRC"):
        p.decode_reply(ord("D"), reply[:-1] + bytes([reply[-1] ^ 1]))
    with pytest.raises(p.ProtocolError, match="not 'd'"):
        p.decode_reply(ord("D"), p.encode_reply(b"x\x01\x08\x79\x18\x00\x00\x00"))


def test_the_error_flag_and_its_reason_round_trip():
    flag = p.encode_error_flag()
    assert len(flag) == 3 and p.is_error_flag(flag)
    answer = p.encode_error_message(ord("C"), 7, 3, "position out of range")
    assert len(answer) == 57 and p.ERROR_REQUEST == b"\x00\x00\x00\xc1"
    err = p.decode_error_message(answer)
    assert (err.text, err.code, err.axis, err.command) == ("position out of range", 7, 3, ord("C"))
    assert str(err) == "the Katana refused command 'C': position out of range (axis 3) (firmware error 7)"


def test_an_unknown_command_or_a_wrong_size_is_refused():
    with pytest.raises(p.ProtocolError, match="not one the Katana knows"):
        p.encode_request(b"Q")
    with pytest.raises(p.ProtocolError, match="takes 2 bytes, not 3"):
        p.encode_request(b"D\x01\x02")


# ---------------------------------------------------------------- encoders and radians
SPEC = robots.get("pioneer")


def test_the_stopper_counts_are_the_catalogue_s_limits():
    """The URDF's limits were computed from the KNI encoder ranges: each calibrated stopper
    (encoderOffset) lands exactly on one of them."""
    at_stopper = [m.to_rad(m.encoder_offset) for m in KATANA_300_6M180[:5]]
    assert at_stopper[0] == pytest.approx(SPEC.lower[0], abs=1e-6)
    assert at_stopper[1] == pytest.approx(SPEC.upper[1], abs=1e-6)
    assert at_stopper[2:] == pytest.approx(SPEC.lower[2:], abs=1e-6)


def test_the_catalogue_s_limits_lie_within_the_counts_between_the_stoppers():
    for m, lo, hi in zip(KATANA_300_6M180, SPEC.lower, SPEC.upper):
        a, b = sorted((m.to_counts(lo), m.to_counts(hi)))
        low, high = m.counts_range
        assert low <= a and b <= high, f"motor {m.motor}"


@pytest.mark.parametrize("m", KATANA_300_6M180[:5], ids=lambda m: f"motor{m.motor}")
def test_counts_and_radians_round_trip(m):
    for rad in (-1.0, 0.0, 0.5, 1.2):
        assert m.to_rad(m.to_counts(rad)) == pytest.approx(rad, abs=1.0 / m.counts_per_rad)


def test_the_top_speed_is_the_catalogue_s():
    """vel_enc2rad(180): 180 counts per 10 ms (motor 3 is measured at half, the URDF says)."""
    speeds = [abs(m.speed_to_rad(MAX_SPEED * 100)) for m in KATANA_300_6M180[:5]]
    assert [speeds[0], speeds[1], speeds[3], speeds[4]] == pytest.approx(
        [SPEC.max_velocity[i] for i in (0, 1, 3, 4)], abs=1e-6)


def test_the_gripper_opens_and_closes_within_its_angles():
    top = SPEC.gripper_max_opening
    assert gripper_opening(gripper_counts(top, top), top) == pytest.approx(top, abs=1e-4)
    assert gripper_opening(gripper_counts(0.0, top), top) == pytest.approx(0.0, abs=1e-4)
    assert gripper_opening(gripper_counts(0.03, top), top) == pytest.approx(0.03, abs=1e-4)
    assert math.isclose(gripper_counts(top, top), 30244, abs_tol=2)   # KNI_GRIPPER_OPEN_ANGLE's counts


# ---------------------------------------------------------------- what KNI sets around the stopper search
@pytest.mark.parametrize("payload, kni", [
    # kmlMotBase.cpp: setControllerParameters 'S' <motor> 1 <kspeed> <kpos> <kI>
    (p.set_controller_parameters(2, 7, 2, 100), bytes([ord("S"), 2, 1, 7, 2, 100])),
    # setPwmLimits 'S' <motor> 2 <maxppwm> <maxnpwm> 0
    (p.set_pwm_limits(1, 100, 100), bytes([ord("S"), 1, 2, 100, 100, 0])),
    # setSpeedLimits 'S' <motor> 3 <positive> <negative> 0
    (p.set_speed_limits(3, 25, 25), bytes([ord("S"), 3, 3, 25, 25, 0])),
    # setAccelerationLimit 'S' <motor> 4 <acceleration> 0 0
    (p.set_acceleration_limit(4, 1), bytes([ord("S"), 4, 4, 1, 0, 0])),
    # setCrashLimit 'S' <motor> 5 <limit hi> <limit lo> 0; 800 = 0x0320
    (p.set_crash_limit(5, 800), bytes([ord("S"), 5, 5, 0x03, 0x20, 0])),
    # setCrashLimitLinear 'S' <motor> 6 <limit hi> <limit lo> 0
    (p.set_crash_limit_linear(6, 800), bytes([ord("S"), 6, 6, 0x03, 0x20, 0])),
    # kmlBase.cpp disableCrashLimits 'A' 0 0; enableCrashLimits 'A' 0 1 on every Katana
    (p.collision_detection(False), b"A\x00\x00"),
    (p.collision_detection(True), b"A\x00\x01"),
    # recvSFW 'V' <motor> 32
    (p.slave_firmware(3), b"V\x03\x20"),
])
def test_the_new_commands_are_kni_s_bytes_and_sizes(payload, kni):
    assert payload == kni
    assert p.decode_request(p.encode_request(payload)) == (p.ADDRESS, kni)


def test_limits_that_do_not_fit_their_bytes_are_refused():
    with pytest.raises(p.ProtocolError, match=r"PWM limits are one byte each \(0..255\), not 300, 100"):
        p.set_pwm_limits(1, 300, 100)
    with pytest.raises(p.ProtocolError, match="a crash limit is two bytes"):
        p.set_crash_limit(1, 70000)


def test_the_slave_firmware_is_bytes_3_to_7_of_v():
    reply = b"v\x01\x03\x01\x05\x09\x00\x02" + bytes(5)
    assert p.parse_slave_firmware(reply) == p.SlaveFirmware(1, 5, 9, 0, 2)
    assert str(p.parse_slave_firmware(reply)) == "1.5.9"
    assert p.parse_slave_firmware(b"v\x00" + bytes(11)) is None     # the motor said "not ok"


def test_the_error_reply_is_the_flag_at_the_command_s_reply_length():
    frame = p.encode_error_reply(ord("N"))
    assert len(frame) == p.reply_length(ord("N")) == 15 and p.check_crc(frame) == b"\xc0" + bytes(12)
    assert p.encode_error_reply(ord("Z")) == p.encode_error_flag()      # 'z' is 1 byte: the same 3 bytes

"""SIP layout (docs/arcos.md "SIP"), unit conversions ("P3-AT parameters") and the 15-bit position wrap."""

import math
import struct

import pytest
from hypothesis import given, strategies as st

from asibot.base_driver import params, sip as sipmod
from asibot.base_driver.codec import PacketError
from asibot.base_driver.sip import Sip, encode_sip, parse_sip, parse_sync2, encode_sync2
from asibot.base_driver.state import StateTracker, signed15, wrapped_delta


def crafted_sip(*, ptype=0x33, x=0x7FF0, y=0x0005, th=1024, lv=250, rv=350, batt=125,
                sb=0x0102, control=0, flags=0x0001, compass=45, sonars=((3, 1200), (12, 4335)),
                tail=True, battx10=127, rotvel=170) -> bytes:
    """Built by hand from the table in docs/arcos.md "SIP", independently of encode_sip."""
    b = bytes([ptype]) + struct.pack("<HHhhhBHhHB", x, y, th, lv, rv, batt, sb, control, flags, compass)
    b += bytes([len(sonars)])
    for idx, rng in sonars:
        b += bytes([idx]) + struct.pack("<H", rng)
    if tail:
        b += bytes([0, 0, 0, 0, 0]) + struct.pack("<H", battx10) + bytes([0]) + struct.pack("<h", rotvel)
    return b


def test_parse_a_crafted_sip():
    s = parse_sip(crafted_sip())
    assert s.moving
    assert (s.xpos, s.ypos, s.thpos) == (0x7FF0, 5, 1024)
    assert (s.left_vel, s.right_vel, s.battery) == (250, 350, 125)
    assert s.stall_right and not s.stall_left                 # 0x0102: bits 8 and 1
    assert s.front_bumpers == [True, False, False, False, False, False, False]
    assert s.rear_bumpers == [False] * 7
    assert s.motors_enabled and not s.estop_pressed
    assert s.sonars == {3: 1200, 12: 4335}
    assert (s.battery_x10, s.rot_vel_x10) == (127, 170)


def test_bits_of_stall_bumpers_and_flags():
    s = parse_sip(crafted_sip(sb=(1 << 8) | (1 << 2) | (1 << 15), flags=1 << 5))
    assert s.stall_right and not s.stall_left
    assert s.front_bumpers == [False, True, False, False, False, False, False]
    assert s.rear_bumpers == [False] * 6 + [True]
    assert s.estop_pressed and not s.motors_enabled


def test_the_16th_position_bit_is_ignored():
    s = parse_sip(crafted_sip(x=0x8000 | 0x0012, y=0xFFFF))
    assert (s.xpos, s.ypos) == (0x12, 0x7FFF)


def test_optional_tail_is_read_only_if_present():
    s = parse_sip(crafted_sip(ptype=0x32, tail=False, sonars=()))
    assert not s.moving and s.battery_x10 is None and s.rot_vel_x10 is None and s.sonars == {}


def test_truncated_and_foreign_packets_are_refused():
    with pytest.raises(PacketError, match="truncated"):
        parse_sip(crafted_sip()[:10])
    with pytest.raises(PacketError, match="sonar"):
        parse_sip(crafted_sip(tail=False)[:-2])
    with pytest.raises(PacketError, match="0x20"):
        parse_sip(b"\x20" + bytes(30))


@given(st.builds(Sip, moving=st.booleans(), xpos=st.integers(0, 0x7FFF), ypos=st.integers(0, 0x7FFF),
                 thpos=st.integers(-2048, 2047), left_vel=st.integers(-1200, 1200),
                 right_vel=st.integers(-1200, 1200), battery=st.integers(0, 255),
                 stall_bumpers=st.integers(0, 0xFFFF), flags=st.integers(0, 0xFFFF),
                 sonars=st.dictionaries(st.integers(0, 15), st.integers(0, 5000), max_size=16),
                 battery_x10=st.integers(0, 300), rot_vel_x10=st.integers(-3000, 3000)))
def test_encode_parse_roundtrip(s):
    assert parse_sip(encode_sip(s)) == s


def test_sync2_reply_strings():
    payload = encode_sync2("bob", "Pioneer", "p3at-sh")
    assert payload == b"\x02bob\x00Pioneer\x00p3at-sh\x00"
    assert parse_sync2(payload) == ("bob", "Pioneer", "p3at-sh")
    with pytest.raises(PacketError):
        parse_sync2(b"\x02only\x00two\x00")


# ------------------------------------------------------------------ 15-bit wrap
@pytest.mark.parametrize("new,old,delta", [(0x0010, 0x7FF0, 0x20), (0x7FF0, 0x0010, -0x20),
                                           (100, 40, 60), (40, 100, -60), (0, 0, 0)])
def test_wrapped_delta(new, old, delta):
    assert wrapped_delta(new, old) == delta


def test_signed15():
    assert signed15(0x7FFB) == -5 and signed15(5) == 5


def test_odometry_unwraps_across_the_15_bit_boundary():
    t = StateTracker(params.P3AT_SH)
    first = t.update(parse_sip(crafted_sip(x=0x7F00, y=0)))
    assert first.x == pytest.approx(-0x100 / 1000)         # starts as a signed position
    xs = [t.update(parse_sip(crafted_sip(x=v & 0x7FFF, y=0))).x for v in range(0x7F00, 0x8200, 0x80)]
    assert xs == pytest.approx([(-0x100 + i * 0x80) / 1000 for i in range(len(xs))])
    assert xs[-1] > 0.3   # went straight through the wrap


def test_p3at_and_p3at_sh_distance_factors_differ():
    for p, factor in ((params.P3AT, 0.465), (params.P3AT_SH, 1.0)):
        t = StateTracker(p)
        t.update(parse_sip(crafted_sip(x=0, y=0)))
        s = t.update(parse_sip(crafted_sip(x=1000, y=2000)))
        assert (s.x, s.y) == pytest.approx((factor * 1.0, factor * 2.0))


def test_velocities_heading_battery_and_sonar_conversions():
    t = StateTracker(params.P3AT_SH)
    s = t.update(parse_sip(crafted_sip(th=1024, lv=250, rv=350, rotvel=170, battx10=127)))
    assert s.theta == pytest.approx(math.pi / 2, abs=1e-3)       # 1024 of 4096 units
    assert s.vx == pytest.approx(0.3)
    assert s.wz == pytest.approx(math.radians(17.0))             # ROTVEL deg/s x 10 wins
    assert s.volts == pytest.approx(12.7)
    assert s.sonar_ranges[3] == pytest.approx(1.2) and s.sonar_ranges[12] == pytest.approx(4.335)
    assert s.sonar_ranges[0] == pytest.approx(4.335) and s.sonar_fresh
    # without the tail: rot vel from the wheels and DiffConvFactor, battery from BATTERY
    s = t.update(parse_sip(crafted_sip(lv=-294, rv=294, tail=False, batt=118, sonars=())))
    assert s.wz == pytest.approx(294 * 0.0034) and s.volts == pytest.approx(11.8)
    assert s.sonar_ranges[3] == pytest.approx(1.2) and not s.sonar_fresh   # kept from before


def test_heading_is_normalised():
    t = StateTracker(params.P3AT_SH)
    assert t.update(parse_sip(crafted_sip(th=3072))).theta == pytest.approx(-math.pi / 2, abs=1e-3)


@pytest.mark.parametrize("name,dist", [("p3at", 0.465), ("p3at-sh", 1.0), ("P3AT-SH", 1.0), ("p3dx-sh", 1.0)])
def test_parameters_are_chosen_from_the_subclass(name, dist):
    assert params.for_subclass(name).dist_conv == dist


def test_unknown_subclass_is_refused_with_a_way_out():
    with pytest.raises(ValueError, match="--params"):
        params.for_subclass("amigo")


def test_track_and_sonar_angles():
    assert params.P3AT_SH.track_mm == pytest.approx(588.2, abs=0.1)
    angles = params.P3AT_SH.sonar_angles()
    assert len(angles) == 16 and angles[0] == pytest.approx(math.pi / 2) and angles[11] == pytest.approx(math.radians(-170))
    assert sipmod.BUMPER_BITS == 7

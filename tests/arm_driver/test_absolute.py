"""Absolute encoders: after power-on the drives' counters are set from the CUI boards."""

from __future__ import annotations

import math
import struct

import pytest

from asibot import robots
from asibot.arm_driver import config, cui, objects
from asibot.testing import wait_until

from .conftest import COLD_ANGLES

STEP = math.radians(360 / 4096)         # one step of the 12-bit AMT20


def test_the_pic_protocol_bytes():
    assert cui.poll_request() == b"\x03"
    assert cui.angle_reply(30.0) == struct.pack("<f", 30.0) == bytes.fromhex("0000f041")
    assert cui.parse_angle(bytes.fromhex("0000f041")) == 30.0
    assert cui.parse_angle(bytes.fromhex("0000f041"), reverse=True) == -30.0
    assert cui.parse_angle(struct.pack("<f", 190.0)) == -170.0        # wrapped to [-180, 180]
    for bad, why in [(bytes([0, 0, 0, 0xC4]), "reports an error"), (b"\x00\x00", "2 bytes"),
                     (struct.pack("<f", math.nan), "not an angle"), (struct.pack("<f", 1e6), "not an angle")]:
        with pytest.raises(cui.EncoderError, match=why):
            cui.parse_angle(bad)


def test_the_asibot_configuration_names_its_three_absolute_encoders(cfg):
    assert {j.name: j.absolute.can_id for j in cfg.joints if j.absolute} == {"q2": 102, "q3": 103, "q4": 104}


@pytest.mark.parametrize("absolute, why", [
    ({"can_id": 0}, "can_id 1..1663"), ({"can_id": "102"}, "can_id"), ({"can_id": 2}, "must differ")])
def test_bad_absolute_encoder_settings_are_refused(absolute, why):
    raw = config.yaml.safe_load(config.path_for("asibot").read_text())
    raw["joints"][1]["absolute"] = absolute
    with pytest.raises(config.ConfigError, match=why):
        config.parse(raw, robots.get("asibot"))


def up(rig):
    d = rig.start_driver()
    wait_until(lambda: rig.states and rig.last.mode in ("idle", "fault"), 10)
    return d


def test_after_power_on_the_joints_report_where_they_really_are(cold_rig):
    rig = cold_rig
    assert all(p == 0.0 for p in rig.emu.positions().values())          # the counters know nothing
    d = up(rig)
    assert rig.last.mode == "idle", rig.last.fault
    assert rig.last.positions == pytest.approx([COLD_ANGLES[n] for n in range(1, 6)], abs=STEP)
    # On the wire: a poll to each board, its answer, and the counter written by SDO (0x2081).
    seen = rig.sniffer.seen()
    for can_id, node in ((102, 2), (103, 3), (104, 4)):
        assert (can_id, b"\x03") in [(c, d_) for c, d_, _ in seen]
        answer = next(d_ for c, d_, _ in seen if c == can_id + 0x180)
        counts = rig.cfg.joints[node - 1].units.to_counts(math.radians(cui.parse_angle(answer)))
        expedited_write = bytes([0x23]) + struct.pack("<HB", objects.SET_ACTUAL_POSITION, 0) + struct.pack("<i", counts)
        assert (0x600 + node, expedited_write) in [(c, d_) for c, d_, _ in seen]
    # Counter and joint now agree: a commanded angle is where the joint really goes.
    goal = [0.0, 0.45, -0.35, 0.25, 0.0]
    assert d.command("position", goal)
    wait_until(lambda: all(abs(p - g) < 1e-4 for p, g in zip(rig.last.positions, goal)), 5)
    real = rig.emu.joint_angles()
    assert [real[n] for n in range(1, 6)] == pytest.approx(goal, abs=STEP)


@pytest.mark.parametrize("fault, why", [("silent", "no answer within 0.1 s"),
                                        ("error", "the encoder board reports an error")])
def test_an_encoder_that_gives_no_angle_keeps_the_arm_off_until_it_does(cold_rig, fault, why):
    rig = cold_rig
    rig.emu.encoder_fault(103, fault)
    d = up(rig)
    assert rig.last.mode == "fault"
    assert rig.last.fault.startswith("The absolute encoder of joint q3 (CAN id 103) gave no position after 5 tries")
    assert why in rig.last.fault and "the arm stays off" in rig.last.fault
    assert "operation enabled" not in set(rig.emu.states().values())
    assert not d.command("position", [0.0] * 5)
    rig.emu.encoder_fault(103, None)
    d.reset_fault()
    wait_until(lambda: rig.last.mode == "idle", 5)
    assert rig.last.positions == pytest.approx([COLD_ANGLES[n] for n in range(1, 6)], abs=STEP)

"""The driver's Katana class and the emulator on the two ends of a pty: every frame one side
sent is the frame the other read, byte for byte, both ways, and each follows the protocol."""

from __future__ import annotations

import pytest

from asibot.katana_driver import protocol as p
from asibot.katana_driver.katana import KATANA_300_6M180, Katana, Silent
from asibot.testing import wait_until

from .conftest import wire


def exchange(w) -> None:
    k = w.katana
    assert k.firmware() == (4, 0)
    assert k.echo()
    k.start()
    k.set_target(1, 20000)
    k.set_target(6, 12000, p.MCF_ON)
    k.read(1)
    k.statuses()
    k.positions()
    k.set_target(2, -25000, p.MCF_FREEZE)
    k.motors_off()


def test_the_driver_and_the_emulator_agree_frame_by_frame(line):
    exchange(line)
    wait_until(lambda: len(line.emulator_side.sent()) == len(line.driver_side.received()), 2)
    requests, replies = line.driver_side.sent(), line.emulator_side.sent()
    assert requests == line.emulator_side.received()        # what the driver sent, the emulator read
    assert replies == line.driver_side.received()           # and the other way
    assert len(requests) == len(replies) == line.katana.requests
    for q, a in zip(requests, replies):
        address, payload = p.decode_request(q)
        assert q[:3] == bytes([1, 24, len(payload)]) and address == 24
        assert len(a) == p.reply_length(payload[0])
        assert p.decode_reply(payload[0], a)[0] == (payload[0] | 0x20)   # the lower-case echo
    commands = [chr(p.decode_request(q)[1][0]) for q in requests]
    assert commands[:3] == ["B", "Z", "S"] and "C" in commands and "D" in commands and "N" in commands


def test_a_refusal_is_the_error_flag_then_the_reason(line):
    with pytest.raises(p.FirmwareError, match=r"refused command 'D': no motor 9 \(axis 9\)"):
        line.katana.read(9)
    assert line.driver_side.sent()[-1] == p.ERROR_REQUEST == line.emulator_side.received()[-1]
    assert line.emulator_side.sent()[-2] == p.encode_error_flag() == line.driver_side.received()[-2]
    assert len(line.driver_side.received()[-1]) == 57
    assert line.katana.echo()               # the line goes on


def test_a_silent_controller_is_tried_again_then_given_up(line):
    line.emulator.go_silent()
    with pytest.raises(Silent, match=r"did not answer command 'N' \(2 tries, 100 ms each\)"):
        line.katana.positions()
    assert [chr(p.decode_request(q)[1][0]) for q in line.driver_side.sent()[-2:]] == ["N", "N"]
    line.emulator.go_silent(False)
    assert line.katana.positions() == [m.position_after for m in KATANA_300_6M180]


def test_a_motor_moves_to_its_target_at_its_speed_limit_and_a_collision_stops_it(line):
    k = line.katana
    k.start(speed=50)
    k.set_target(1, -15000)                 # 9 s away at 50 counts per 10 ms
    wait_until(lambda: k.read(1).status == p.MSF_NORMOPSTAT, 5)
    assert k.read(1).velocity == -50
    stop_at = k.read(1).position - 500
    k.set_target(1, stop_at)
    wait_until(lambda: abs(k.read(1).position - stop_at) < 1 and k.read(1).status == p.MSF_DESPOS, 5)
    k.set_target(1, 28000)
    line.emulator.collide(1)
    assert k.statuses()[0] == p.MSF_MOTCRASHED
    with pytest.raises(p.FirmwareError, match="not accepted"):
        k.set_target(1, 29000)
    k.freeze()                               # KNI's unBlock: a freeze clears the collision
    assert k.statuses()[0] == p.MSF_DESPOS


@pytest.mark.slow
def test_calibration_finds_the_stoppers_as_kni_does():
    """Switched on near its stoppers with the counters at 0: the calibration leaves every
    counter right (the emulator's calibrated frame) at the position after calibration."""
    w = wire(calibrated=False, positions=[m.position_after + (400 if m.search_positive else -400)
                                          for m in KATANA_300_6M180])
    try:
        assert w.katana.positions() == [0] * 6
        w.katana.calibrate(timeout=20)
        want = [m.position_after for m in KATANA_300_6M180]
        assert w.katana.positions() == pytest.approx(want, abs=100)
        assert [e.shift for e in w.emulator.motors] == pytest.approx([0.0] * 6, abs=1)
    finally:
        w.line.close()


def test_katana_refuses_a_request_it_cannot_frame():
    class NoLine:
        def read(self, size=1): return b""
        def write(self, data): return len(data)
        def reset_input_buffer(self): pass
    with pytest.raises(p.ProtocolError):
        Katana(NoLine()).transact(b"Q")

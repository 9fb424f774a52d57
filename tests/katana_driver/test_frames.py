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
    # The error flag at the length of 'd' (8 bytes and the CRC): what KNI's reader takes.
    flag = line.emulator_side.sent()[-2]
    assert flag == p.encode_error_reply(ord("D")) == line.driver_side.received()[-2]
    assert len(flag) == 10 and flag[0] == 0xC0 and p.check_crc(flag) == b"\xc0" + bytes(7)
    assert len(line.driver_side.received()[-1]) == 57
    assert line.katana.echo()               # the line goes on


class ScriptedPort:
    """A serial line whose controller answers each request with the next of `answers`."""

    def __init__(self, answers: list[bytes]) -> None:
        self.answers, self.written, self._pending = list(answers), [], b""

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        if data != p.ERROR_REQUEST and self.answers:
            self._pending = self.answers.pop(0)
        elif data == p.ERROR_REQUEST:
            self._pending = p.encode_error_message(ord("D"), 3, 2, "not now")
        return len(data)

    def read(self, size: int = 1) -> bytes:
        out, self._pending = self._pending[:size], self._pending[size:]
        return out

    def reset_input_buffer(self) -> None:
        self._pending = b""


def test_a_bare_3_byte_error_flag_is_an_incomplete_reply_as_kni_reads_it():
    """KNI's reader (cdlCOM.cpp recv) wants the whole reply before it looks at the first byte:
    `C0 <crc>` to a command whose reply is longer is too short, so the request is sent again,
    and after the retries the controller did not answer; the reason is never asked."""
    w = wire(bare_error_flag=True)
    try:
        with pytest.raises(Silent, match=r"did not answer command 'D' \(2 tries, 100 ms each; 2 of its answers "
                                         r"were a bare 3-byte error flag, which KNI reads as an incomplete reply\)"):
            w.katana.read(9)
        assert w.driver_side.sent()[-2:] == [p.encode_request(p.read_motor(9))] * 2
        assert p.ERROR_REQUEST not in w.emulator_side.received()
        assert w.driver_side.received()[-1] == p.encode_error_flag()
    finally:
        w.line.close()


def test_a_bare_error_flag_is_sent_again_and_never_asked_about():
    """The same with the controller's side scripted: 'D' answered `C0 <crc>` twice."""
    port = ScriptedPort([p.encode_error_flag()] * 2)
    with pytest.raises(Silent, match="2 of its answers were a bare 3-byte error flag"):
        Katana(port, timeout=0.05, retries=1).read(3)
    assert port.written == [p.encode_request(p.read_motor(3))] * 2


def test_an_error_reply_with_a_wrong_crc_is_sent_again_not_asked_about():
    """KNI checks the CRC of an error reply before it asks why (cplSerial.cpp recv): a wrong one
    is a WrongCRCException, and the request goes again."""
    flag = bytes([0xC0]) + bytes(7)                     # the error flag at the length of 'd'
    crc = p.crc16(flag) ^ 0x0101
    bad = flag + bytes([crc >> 8, crc & 0xFF])
    good = p.encode_reply(b"d\x01\x08\x79\x18\x00\x00\x00")
    port = ScriptedPort([bytes(bad), good])
    k = Katana(port, timeout=0.05, retries=1)
    assert k.read(3) == p.MotorReading(True, p.MSF_DESPOS, 31000, 0, 0)
    assert port.written == [p.encode_request(p.read_motor(3))] * 2 and k.retried == 1


def test_an_error_flag_to_a_3_byte_reply_is_the_refusal():
    """'Z' is answered in 3 bytes: there the bare error flag is the whole reply, and KNI asks why."""
    port = ScriptedPort([p.encode_error_flag()])
    with pytest.raises(p.FirmwareError, match=r"refused command 'D': not now \(axis 2\) \(firmware error 3\)"):
        Katana(port, timeout=0.05, retries=1).echo()
    assert port.written == [p.encode_request(p.echo()), p.ERROR_REQUEST]


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

"""The Katana's bring-up as KNI does it, read off the wire at the emulator: the firmware asked
('B', then 'V' of every motor), motor 3's counts per turn taken from its slave firmware, an
unknown firmware refused with a sentence; the calibration with collision detection off and
each motor's limits set before and after its stopper search; the working limits and collision
detection on before the arm is driven.

The expected values are KNI 4.3.0's, written out here from its sources (not from the driver):
kni/KNI_4.3.0/configfiles300/katana6M180.cfg and src/Base/kmlExt.cpp searchMechStop."""

from __future__ import annotations

import math

import pytest

from asibot import robots
from asibot.katana_driver import protocol as p
from asibot.katana_driver.driver import KatanaDriver
from asibot.katana_driver.katana import KATANA_300_6M180
from asibot.testing import wait_until

from .conftest import R, wire

SPEC = robots.get(R)

# katana6M180.cfg per motor: maxppwm_nmp = maxnpwm_nmp, kspeed_nmp, kpos_nmp, kI_nmp,
# crash_limit_nmp = crash_limit_lin_nmp, maxaccel_nmp, maxpspeed_nmp = maxnspeed_nmp.
KNI_CFG = {1: (100, 15, 2, 100, 800, 1, 30), 2: (127, 7, 2, 100, 800, 1, 25), 3: (100, 15, 2, 100, 800, 1, 25),
           4: (127, 2, 2, 100, 800, 1, 25), 5: (127, 7, 2, 100, 800, 1, 25), 6: (127, 4, 1, 100, 800, 1, 25)}
# [CALIBRATION] order, direction (+1 DIR_POSITIVE), encoderOffset, encoderPositionAfter.
KNI_CALIBRATION = {1: (5, +1, 31000, 30000), 2: (0, -1, -31000, -30000), 3: (1, -1, -31000, -30000),
                   4: (2, +1, 31000, 30000), 5: (3, +1, 31000, 30000), 6: (4, +1, 31000, 30000)}


def limits(motor: int, acceleration: int, speed: int) -> list[bytes]:
    """What KNI's searchMechStop sends to set one motor's limits, in its order (kmlExt.cpp 198-203)."""
    pwm, ks, kp, ki, crash, _, _ = KNI_CFG[motor]
    return [bytes([ord("S"), motor, 2, pwm, pwm, 0]), bytes([ord("S"), motor, 1, ks, kp, ki]),
            bytes([ord("S"), motor, 5, crash >> 8, crash & 0xFF, 0]),
            bytes([ord("S"), motor, 6, crash >> 8, crash & 0xFF, 0]),
            bytes([ord("S"), motor, 4, acceleration, 0, 0]), bytes([ord("S"), motor, 3, speed, speed, 0])]


def c(motor: int, flag: int, counts: int) -> bytes:
    return bytes([ord("C"), motor, flag]) + (counts & 0xFFFF).to_bytes(2, "big")


def payloads(w) -> list[bytes]:
    """Every request the emulator read, in order, without its header and CRC."""
    return [p.decode_request(f)[1] for f in w.emulator_side.received() if f != p.ERROR_REQUEST]


def identify() -> list[bytes]:
    return [b"B"] + [bytes([ord("V"), m, 32]) for m in range(1, 7)]


def working() -> list[bytes]:
    """The driver's start: every motor's working limits at the driver's speed 180, collision
    detection on (KNI's enableCrashLimits: 'A' 0 1), every motor frozen where it stands."""
    out = [q for m in range(1, 7) for q in limits(m, KNI_CFG[m][5], 180)]
    return out + [b"A\x00\x01", b"N\x03\x00"]


class Driven:
    def __init__(self, calibrate: bool, **emulator_options) -> None:
        if "slave_firmware" in emulator_options:     # (version, subversion, revision, type, subtype)
            emulator_options["slave_firmware"] = p.SlaveFirmware(*emulator_options["slave_firmware"])
        self.w = wire(**emulator_options)
        self.events: list[tuple[str, str, str]] = []
        self.states = []
        self.driver = KatanaDriver(self.w.katana, SPEC, lambda a, g: self.states.append(a),
                                   lambda *e: self.events.append(e), calibrate=calibrate)
        self.driver.start()

    def wait(self, mode: str, timeout: float) -> None:
        wait_until(lambda: self.driver.status()["mode"] == mode, timeout,
                   message=lambda: f"the driver is {self.driver.status()['mode']}: {self.driver.status()['fault']}")

    def close(self) -> None:
        self.driver.close()
        self.w.line.close()


@pytest.fixture
def driven():
    made: list[Driven] = []

    def make(calibrate: bool = False, **emulator_options) -> Driven:
        made.append(Driven(calibrate, **emulator_options))
        return made[-1]
    yield make
    for d in made:
        d.close()


def test_a_calibrated_katana_gets_its_working_limits_and_collision_detection_before_it_is_driven(driven):
    d = driven(calibrate=False)
    d.wait("idle", 10)
    sent = payloads(d.w)
    here = sent[:len(identify()) + len(working())]
    assert here == identify() + working()
    after = sent[len(here):len(here) + 6]
    assert [q[:3] for q in after] == [bytes([ord("C"), m, p.MCF_FREEZE]) for m in range(1, 7)]
    emu = d.w.emulator
    assert emu.collision_detection == (0, 1)
    assert emu.settings(2) == {1: bytes([7, 2, 100]), 2: bytes([127, 127, 0]), 3: bytes([180, 180, 0]),
                               4: bytes([1, 0, 0]), 5: bytes([3, 32, 0]), 6: bytes([3, 32, 0])}


@pytest.mark.slow
def test_the_calibration_sends_kni_s_limits_around_each_stopper_search_with_collision_detection_off(driven):
    """Switched on at its stoppers (a short search): the calibration's requests, the speed
    readings of the search ('D') left out, are KNI's, in KNI's order."""
    at_stoppers = [KNI_CALIBRATION[m][2] for m in range(1, 7)]
    d = driven(calibrate=True, calibrated=False, positions=at_stoppers)
    d.wait("idle", 40)
    sent = [q for q in payloads(d.w) if q[0] != ord("D")]
    want = identify() + [b"A\x00\x00"] + [c(m + 128, p.MCF_ON, 0) for m in range(1, 7)]
    for m in sorted(KNI_CALIBRATION, key=lambda m: KNI_CALIBRATION[m][0]):
        _, direction, offset, after = KNI_CALIBRATION[m]
        want += limits(m, 1, 25)                                    # kmlExt.cpp 198-203
        want += [c(m + 128, p.MCF_FREEZE, -31000 * direction), c(m, p.MCF_ON, 32000 * direction)]
        want += [c(m + 128, p.MCF_FREEZE, 0)]                       # the stopper found
        want += limits(m, KNI_CFG[m][5], KNI_CFG[m][6])             # kmlExt.cpp 261-266
        want += [c(m + 128, p.MCF_ON, offset), c(m, p.MCF_ON, after)]
    want += working()
    assert sent[:len(want)] == want
    assert d.w.emulator.collision_detection == (0, 1)
    assert d.w.katana.positions() == pytest.approx([KNI_CALIBRATION[m][3] for m in range(1, 7)], abs=100)


def motor3_counts(rad: float, counts_per_turn: int) -> int:
    """KNI's counts of motor 3 at the URDF angle `rad` (katana6M180.cfg [MOT[2]] [INIT]: offset
    -31000 counts at 52.7 degrees, DIR_NEGATIVE; the URDF's angle is KNI's minus pi)."""
    return round((math.radians(52.7) - (rad + math.pi)) * counts_per_turn * -1 / (2 * math.pi) - 31000)


@pytest.mark.parametrize("version, counts_per_turn", [(1, 94976), (2, 81408)])
def test_motor_3_s_counts_per_turn_are_its_slave_firmware_s(driven, version, counts_per_turn):
    """katana6M180.cfg line 171: "81408 for slave firmware 2.xx, 94976 for slave firmware 1.xx"."""
    positions = [m.position_after for m in KATANA_300_6M180]
    positions[2] = motor3_counts(0.8, counts_per_turn)
    d = driven(slave_firmware=(version, 3, 1, 0, 0), positions=positions)
    d.wait("idle", 10)
    wait_until(lambda: d.states, 5)
    assert d.states[-1].positions[2] == pytest.approx(0.8, abs=1e-4)
    # and a joint target goes out in that firmware's counts
    assert d.driver.command("position", [*d.states[-1].positions[:2], 1.2, *d.states[-1].positions[3:]])
    wait_until(lambda: abs(d.w.emulator.counters()[2] - motor3_counts(1.2, counts_per_turn)) <= 1, 10,
               message=lambda: f"motor 3 stands at {d.w.emulator.counters()[2]} counts")


def test_with_slave_firmware_1_joint_3_is_driven_within_what_16_bit_counts_carry(driven):
    d = driven(slave_firmware=(1, 0, 0, 0, 0))
    d.wait("idle", 10)
    top = d.driver.status()["upper"][2]
    # 32767 counts at 94976 a turn: the catalogue's 2.054 rad would be 33637 counts.
    assert top == pytest.approx(math.radians(52.7) + (32767 + 31000) * 2 * math.pi / 94976 - math.pi, abs=1e-9)
    assert top < SPEC.upper[2]


@pytest.mark.parametrize("options, says", [
    ({"slave_firmware": (3, 0, 0, 0, 0)},
     "The slave firmware of the Katana's motor 3 (joint katana_motor3_lift_joint) is 3.0.0, and KNI gives its "
     "encoder counts per turn only for 1.xx (94976) and 2.xx (81408) (katana6M180.cfg): every position of that "
     "joint would be wrong, so the arm was not moved. Find motor 3's counts per turn for this firmware "
     "(Neuronics' configuration file for it) and add them to MOTOR3_COUNTS_BY_SLAVE_VERSION in "
     "asibot/katana_driver/katana.py, or update the slave firmware."),
    ({"master_firmware": (2, 9)},
     "The Katana's master firmware is 2.9, which KNI reads as a Katana 400's controller (a version below 3, "
     "kmlBase.cpp checkKatanaType): its calibration and commands differ from the Katana 300 6M180's this driver "
     "speaks, so the arm was not moved. Check that the serial cable goes to the Pioneer's Katana 300."),
])
def test_an_unknown_firmware_is_refused_with_a_sentence_and_nothing_moves(driven, options, says):
    d = driven(calibrate=True, **options)
    wait_until(lambda: d.events, 10, message="the driver raised no fault")     # "starting" is a fault already
    assert d.driver.status()["fault"] == says
    assert ("error", "startup", says) in d.events
    assert {chr(q[0]) for q in payloads(d.w)} <= {"B", "V"}        # no limit, no target, no calibration

"""The sim base's rules (asibot.safety.guarded_base on the sim's clock) and odometry, without physics."""

import math
import re

import pytest

from asibot.safety.arming import NotReady
from asibot.safety.events import CommandRefused
from asibot.sim.base import ACC_X, MAX_VX, MAX_WZ, SPEED_TOLERANCE, BaseDrive, Odometer

DT = 0.002


def test_speed_ramps_up_and_is_capped():
    b = BaseDrive()
    five = MAX_VX * (1 + SPEED_TOLERANCE / 2)   # a hair over the max: noise, clamped
    b.command(five, 0.0, now=0.0)
    t = 0.0
    for _ in range(50):
        t += DT
        vx, _ = b.step(DT, t)
    assert vx == pytest.approx(ACC_X * 0.1)
    for _ in range(550):
        b.command(five, 0.0, now=t)
        t += DT
        vx, _ = b.step(DT, t)
    assert vx == pytest.approx(MAX_VX)


def test_watchdog_stops_the_base_and_notifies():
    events = []
    b = BaseDrive(lambda *event: events.append(event))
    b.command(0.3, 0.2, now=0.0)
    t = 0.0
    for _ in range(int(1.0 / DT)):
        t += DT
        vx, wz = b.step(DT, t)
    assert (vx, wz) == (0.0, 0.0)
    assert events == [("warning", "watchdog", "No drive command for 200 ms: the base stopped.")]


def test_estop_stops_at_once_ignores_commands_and_only_a_new_stream_moves_after_the_release():
    events = []
    b = BaseDrive(lambda *event: events.append(event))
    b.command(0.5, 0.0, now=0.0)
    for k in range(100):
        b.command(0.5, 0.0, now=k * DT)
        b.step(DT, k * DT)
    b.set_estop(True, "a test", "the tester")
    assert (b.vx, b.wz) == (0.0, 0.0)
    assert b.command(0.5, 0.0, now=0.2) is False and b.step(DT, 0.2) == (0.0, 0.0)
    b.set_estop(False)
    assert [code for _, code, _ in events] == ["estop", "estop_released", "ready"]
    assert events[0][2] == ("Emergency stop engaged by the tester (a test): the base is stopped and ignores motion "
                            "commands until the stop is released.")
    with pytest.raises(NotReady):          # the stream from before the release goes on: not obeyed
        b.command(0.5, 0.0, now=0.3)
    assert b.step(DT, 0.3) == (0.0, 0.0)
    assert b.command(0.5, 0.0, now=0.8) is True            # a new stream, after a pause
    assert b.step(DT, 0.8)[0] > 0.0


def test_a_change_of_controller_stops_a_moving_base_as_it_brakes_and_arms_it_for_the_new_one():
    events = []
    b = BaseDrive(lambda *event: events.append(event))
    t = 0.0
    for _ in range(100):
        b.command(0.5, 0.0, "nav", now=t)
        t += DT
        b.step(DT, t)
    moving = b.vx
    b.set_controller("joystick")
    assert [code for _, code, _ in events] == ["controller_lost", "ready"]
    assert 0.0 < b.step(DT, t)[0] < moving                  # braking, not a jump to zero
    for _ in range(200):
        t += DT
        b.step(DT, t)
    assert (b.vx, b.wz) == (0.0, 0.0)
    b.set_controller(None)
    assert [code for _, code, _ in events] == ["controller_lost", "ready"]    # not moving: nothing to say


def test_non_finite_command_is_rejected():
    b = BaseDrive()
    with pytest.raises(CommandRefused, match="vx is inf, not a finite number"):
        b.command(math.inf, 0.0, now=0.0)


@pytest.mark.parametrize("vx, wz, says", [
    (1e300, 0.0, "vx 1e+300 m/s is beyond the P3-AT's max speed 1.2 m/s"),
    (-1.3, 0.0, "vx -1.3 m/s is beyond the P3-AT's max speed 1.2 m/s"),
    (0.0, 6.0, "wz 6 rad/s is beyond the P3-AT's max turn rate 5.24 rad/s"),
])
def test_speeds_beyond_the_p3at_are_refused_not_clamped(vx, wz, says):
    b = BaseDrive()
    b.command(0.3, 0.1, now=0.0)
    with pytest.raises(CommandRefused, match=re.escape(says)):
        b.command(vx, wz, now=0.1)
    t = 0.0
    for _ in range(50):
        t += DT
        b.step(DT, t)
    assert (b.vx, b.wz) == pytest.approx((min(0.3, ACC_X * 0.1), 0.1))   # the previous command goes on
    assert MAX_WZ < 6.0


def test_exact_odometry_integrates_a_circle():
    o = Odometer(noise=(0.0, 0.0))
    for _ in range(1000):            # 0.5 m/s, 0.5 rad/s for 4*pi seconds: one full circle
        o.update(0.5, 0.5, 4 * math.pi / 1000)
    assert (o.x, o.y) == (pytest.approx(0.0, abs=1e-5), pytest.approx(0.0, abs=1e-5))
    assert o.theta == pytest.approx(0.0, abs=1e-9)


def test_noisy_odometry_drifts_but_stays_close():
    o = Odometer(noise=(0.02, 0.05), seed=1)
    for _ in range(100):
        o.update(0.3, 0.0, 0.02)
    assert o.x == pytest.approx(0.6, rel=0.05) and o.x != pytest.approx(0.6, abs=1e-12)


def test_negative_noise_is_refused():
    with pytest.raises(ValueError, match=">= 0"):
        Odometer(noise=(-0.1, 0.0))

"""The base's driver rules and odometry, without physics."""

import math
import re

import pytest

from asibot.sim.arm import BadCommand, CommandRejected
from asibot.sim.base import ACC_X, MAX_VX, MAX_WZ, SPEED_TOLERANCE, BaseDrive, Odometer

DT = 0.002


def test_speed_ramps_up_and_is_capped():
    b = BaseDrive()
    five = MAX_VX * (1 + SPEED_TOLERANCE / 2)   # a hair over the max: noise, clamped
    b.command(five, 0.0, 0.0)
    t = 0.0
    for _ in range(50):
        t += DT
        vx, _ = b.step(DT, t)
    assert vx == pytest.approx(ACC_X * 0.1)
    for _ in range(50):
        b.command(five, 0.0, t)
        t += DT
        vx, _ = b.step(DT, t)
    for _ in range(500):
        b.command(five, 0.0, t)
        t += DT
        vx, _ = b.step(DT, t)
    assert vx == pytest.approx(MAX_VX)


def test_watchdog_stops_the_base_and_notifies():
    notices = []
    b = BaseDrive(notify=notices.append)
    b.command(0.3, 0.2, 0.0)
    t = 0.0
    for _ in range(int(1.0 / DT)):
        t += DT
        vx, wz = b.step(DT, t)
    assert (vx, wz) == (0.0, 0.0)
    assert [n.code for n in notices] == ["watchdog"]


def test_estop_stops_at_once_and_refuses_commands_until_released():
    b = BaseDrive()
    b.command(0.5, 0.0, 0.0)
    for k in range(100):
        b.step(DT, k * DT)
    b.set_estop(True)
    assert (b.vx, b.wz) == (0.0, 0.0)
    with pytest.raises(CommandRejected, match="emergency stop"):
        b.command(0.5, 0.0, 0.2)
    b.set_estop(False)
    b.command(0.5, 0.0, 0.2)


def test_non_finite_command_is_rejected():
    b = BaseDrive()
    with pytest.raises(CommandRejected, match="vx is inf, not a finite number"):
        b.command(math.inf, 0.0, 0.0)


@pytest.mark.parametrize("vx, wz, says", [
    (1e300, 0.0, "vx 1e+300 m/s is beyond the P3-AT's max speed 1.2 m/s"),
    (-1.3, 0.0, "vx -1.3 m/s is beyond the P3-AT's max speed 1.2 m/s"),
    (0.0, 6.0, "wz 6 rad/s is beyond the P3-AT's max turn rate 5.24 rad/s"),
])
def test_speeds_beyond_the_p3at_are_refused_not_clamped(vx, wz, says):
    b = BaseDrive()
    b.command(0.3, 0.1, 0.0)
    with pytest.raises(BadCommand, match=re.escape(says)):
        b.command(vx, wz, 0.1)
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

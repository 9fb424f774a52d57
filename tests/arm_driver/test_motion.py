"""The set-point stream: limits, speeds, watchdog, hold; bad input changes nothing."""

from __future__ import annotations

import math

import pytest

from asibot.arm_driver.motion import JointReference

V = math.radians(25)


def ref():
    r = JointReference([-1.0, -1.0], [1.0, 1.0], [V, V], 0.01)
    r.reset([0.0, 0.0])
    return r


def test_position_goal_is_reached_at_max_speed_and_clamped_to_limits():
    r = ref()
    r.position([5.0, -0.1], None, now=0.0)
    steps = [r.step(0.01 * i) for i in range(1, 600)]
    deltas = [abs(b[0] - a[0]) for a, b in zip(steps, steps[1:])]
    assert max(deltas) <= V * 0.01 + 1e-12
    assert steps[-1] == pytest.approx([1.0, -0.1])                     # 5.0 clamped to the limit


def test_velocity_integrates_and_the_watchdog_stops_it():
    r = ref()
    r.velocity([10.0, -0.1], now=0.0)                                   # 10 rad/s clamped to 25 deg/s
    r.step(0.01)
    assert r.rate == pytest.approx([V, -0.1])
    assert not r.watchdog_expired(0.19)
    assert r.watchdog_expired(0.21)
    r.hold()
    before = r.target
    assert r.step(0.22) == before and not r.moving


def test_a_joint_outside_its_limits_may_only_move_back():
    r = JointReference([-1.0], [1.0], [V], 0.01)
    r.reset([1.2])
    r.velocity([0.2], now=0.0)
    assert r.step(0.01) == [1.2]
    r.velocity([-0.2], now=0.01)
    assert r.step(0.02)[0] < 1.2


def test_feed_forward_extrapolates_a_little():
    r = ref()
    r.position([0.0, 0.0], [0.1, 0.0], now=0.0)
    for i in range(1, 6):
        out = r.step(0.01 * i)
    assert out[0] == pytest.approx(0.005)                               # 0.1 rad/s x 50 ms ahead
    for i in range(5):
        out = r.step(1.0 + 0.01 * i)
    assert out[0] == pytest.approx(0.01)                                # but never beyond 100 ms


@pytest.mark.parametrize("values", [[0.1], [0.1, float("nan")], [0.1, 0.2, 0.3]])
def test_bad_commands_change_nothing(values):
    r = ref()
    r.position([0.3, 0.3], None, 0.0)
    with pytest.raises(ValueError):
        r.position(values, None, 0.1)
    with pytest.raises(ValueError):
        r.velocity(values, 0.1)
    assert r.mode == "position"
    assert r.step(0.01)[0] > 0

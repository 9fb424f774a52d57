"""The set-point stream: limits, speeds, watchdog, hold; bad input changes nothing."""

from __future__ import annotations

import math
import re

import pytest

from asibot.safety.joint_reference import POSITION_TOLERANCE_RAD, VELOCITY_TOLERANCE, JointReference
from asibot.safety.events import CommandRefused

V = math.radians(25)


def ref():
    r = JointReference([-1.0, -1.0], [1.0, 1.0], [V, V], 0.01)
    r.reset([0.0, 0.0])
    return r


def test_position_goal_is_reached_at_max_speed_and_stays_within_the_limits():
    r = ref()
    r.position([1.0, -0.1], None, now=0.0)                              # exactly at the limit
    steps = [r.step(0.01 * i) for i in range(1, 600)]
    deltas = [abs(b[0] - a[0]) for a, b in zip(steps, steps[1:])]
    assert max(deltas) <= V * 0.01 + 1e-12
    assert steps[-1] == pytest.approx([1.0, -0.1])
    assert max(s[0] for s in steps) <= 1.0


@pytest.mark.parametrize("values, ff, says", [
    ([1e300, 0.0], None, "joint q1 position 1e+300 rad is beyond its upper limit 1 rad"),
    ([0.0, -1.01], None, "joint q2 position -1.01 rad is beyond its lower limit -1 rad"),
    ([1.0 + 2 * POSITION_TOLERANCE_RAD, 0.0], None, "joint q1 position 1.0002 rad is beyond its upper limit 1 rad"),
    ([0.0, 0.0], [0.0, -1e300], "joint q2 velocity feed-forward -1e+300 rad/s is beyond its max speed 0.436 rad/s"),
    ([math.inf, 0.0], None, "joint q1 got inf, not a finite number"),
    ([0.0, 0.0], [0.0, math.nan], "joint q2 got nan, not a finite number"),     # abs(nan) > max is false
])
def test_positions_past_a_limit_are_refused_not_clipped(values, ff, says):
    r = ref()
    r.position([0.3, 0.3], None, 0.0)
    with pytest.raises(CommandRefused, match=re.escape(says)):
        r.position(values, ff, 0.1)
    # nothing changed: the previous goal still drives the set-point
    assert r.mode == "position" and r.step(0.11)[0] > 0 and r.step(0.12)[1] > 0


def test_noise_at_a_limit_is_tolerated_and_clamped():
    """The kinematics planner stays within 1e-9 rad of a limit and a hold at a measured
    position is within half an encoder count (5 urad): neither is refused; neither passes."""
    r = ref()
    r.position([1.0 + 5e-6, -1.0 - 1e-9], [V * (1 + VELOCITY_TOLERANCE / 2), 0.0], 0.0)
    steps = [r.step(0.01 * i) for i in range(1, 600)]
    assert max(s[0] for s in steps) <= 1.0 and min(s[1] for s in steps) >= -1.0
    assert steps[-1] == pytest.approx([1.0, -1.0])


def test_a_joint_found_outside_may_be_held_where_it_is_but_not_sent_further():
    r = JointReference([-1.0], [1.0], [V], 0.01)
    r.reset([1.2])
    r.position([1.2], None, 0.0)                          # stay (the kinematics' hold): accepted
    r.position([1.25], None, 0.0, measured=[1.25])        # measured further out than the set-point
    with pytest.raises(CommandRefused, match="upper limit"):
        r.position([1.3], None, 0.0, measured=[1.25])
    assert r.step(0.01)[0] < 1.2                          # and it still only goes back


@pytest.mark.parametrize("speed", [10.0, -V * 1.01, math.nan])
def test_velocities_beyond_the_max_speed_are_refused(speed):
    r = ref()
    r.velocity([0.1, 0.0], now=0.0)
    with pytest.raises(CommandRefused, match="joint q2 (velocity|got)"):
        r.velocity([0.0, speed], now=0.05)
    r.step(0.01)
    assert r.rate == pytest.approx([0.1, 0.0])            # the previous velocity goes on


def test_velocity_integrates_and_the_watchdog_stops_it():
    """The stream's watchdog fires after a quiet period (GuardedArm._watch asks it), then a hold stops it."""
    r = ref()
    r.velocity([V * (1 + VELOCITY_TOLERANCE / 2), -0.1], now=0.0)      # a hair over: clamped to 25 deg/s
    r.step(0.01)
    assert r.rate == pytest.approx([V, -0.1])
    assert not r.watchdog.fires(0.19, r.streaming)
    assert r.watchdog.fires(0.21, r.streaming)
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

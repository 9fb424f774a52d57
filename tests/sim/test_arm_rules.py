"""The driver's arm rules, without physics: limits, speeds, watchdog, estop, faults."""

import math
import re

import numpy as np
import pytest

from asibot.messages import ArmCommand
from asibot.messages import COMMAND_WATCHDOG_S
from asibot.sim.arm import (POSITION_TOLERANCE_RAD, VELOCITY_TOLERANCE, BadCommand, CommandRejected, JointLimits,
                            JointTracker)

DT = 0.002


def tracker(notices=None):
    limits = JointLimits.of(["a", "b"], [-1.0, -2.0], [1.0, 2.0], [0.5, 1.0])
    return JointTracker(limits, np.zeros(2), notify=(notices.append if notices is not None else lambda n: None))


def run(t, seconds, start=0.0, follow=True):
    now = start
    for _ in range(int(round(seconds / DT))):
        now += DT
        t.step(t.q_ref if follow else np.zeros(2), DT, now)
    return now


def test_position_is_reached_at_the_max_speed_and_stays_within_limits():
    t = tracker()
    t.command(ArmCommand(mode="position", values=[1.0 + POSITION_TOLERANCE_RAD / 2, -0.5]), 0.0)
    run(t, 0.5)
    assert t.q_ref[0] == pytest.approx(0.25, abs=1e-9)    # 0.5 rad/s for 0.5 s
    assert t.q_ref[1] == pytest.approx(-0.5, abs=1e-9)    # reached
    run(t, 5.0, 0.5)
    assert t.q_ref[0] == 1.0                               # noise past the limit: clamped to it


@pytest.mark.parametrize("mode, values, ff, says", [
    ("position", [1e300, 0.0], None, "joint a position 1e+300 rad is beyond its upper limit 1 rad"),
    ("position", [0.0, -2.01], None, "joint b position -2.01 rad is beyond its lower limit -2 rad"),
    ("position", [1.001, 0.0], None, "joint a position 1.001 rad is beyond its upper limit 1 rad"),
    ("position", [0.0, 0.0], [0.0, 1.5], "joint b velocity feed-forward 1.5 rad/s is beyond its max speed 1 rad/s"),
    ("velocity", [9.0, 0.0], None, "joint a velocity 9 rad/s is beyond its max speed 0.5 rad/s"),
    ("velocity", [0.0, -1e300], None, "joint b velocity -1e+300 rad/s is beyond its max speed 1 rad/s"),
    ("position", [0.0, math.nan], None, "joint b got nan, not a finite number"),
])
def test_values_past_a_limit_are_refused_not_clipped(mode, values, ff, says):
    t = tracker()
    t.command(ArmCommand(mode="position", values=[0.5, 0.5]), 0.0)
    cmd = ArmCommand(mode=mode, values=[0.0, 0.0], velocities=[0.0, 0.0] if ff else [])
    cmd.values, cmd.velocities = values, ff or []   # bypass the message's own checks (NaN)
    with pytest.raises(BadCommand, match=re.escape(says)):
        t.command(cmd, 0.1)
    run(t, 2.0, 0.1)
    assert t.mode == "position" and t.q_ref == pytest.approx([0.5, 0.5])   # the previous goal


def test_a_joint_measured_past_a_limit_may_be_held_there():
    """MuJoCo's servos overshoot a limit by a few mrad as they arrive; the kinematics service
    holds where it measured the arm: not refused, and the reference stays within the limits."""
    t = tracker()
    t.command(ArmCommand(mode="position", values=[1.008, 0.0]), 0.0, q_measured=[1.008, 0.0])
    with pytest.raises(BadCommand, match="upper limit"):
        t.command(ArmCommand(mode="position", values=[1.02, 0.0]), 0.0, q_measured=[1.008, 0.0])
    run(t, 3.0)
    assert t.q_ref[0] == 1.0


def test_wrong_joint_count_is_rejected_and_changes_nothing():
    t = tracker()
    with pytest.raises(CommandRejected, match="2 joints"):
        t.command(ArmCommand(mode="position", values=[0.1, 0.2, 0.3]), 0.0)
    cmd = ArmCommand(mode="position", values=[0.1, 0.2])
    cmd.velocities = [0.1]  # bypass the message's own check
    with pytest.raises(CommandRejected, match="feed-forward"):
        t.command(cmd, 0.0)
    assert t.mode == "idle"


def test_non_finite_values_are_rejected():
    t = tracker()
    cmd = ArmCommand(mode="velocity", values=[0.1, 0.1])
    cmd.values = [math.nan, 0.0]  # bypass the message's own check, as a buggy decoder might
    with pytest.raises(CommandRejected, match="joint a got nan, not a finite number"):
        t.command(cmd, 0.0)
    assert t.mode == "idle"


def test_velocity_mode_stops_after_the_watchdog_and_says_so():
    notices = []
    t = tracker(notices)
    t.command(ArmCommand(mode="velocity", values=[0.4, 0.0]), 0.0)
    run(t, 1.0)
    assert t.q_ref[0] == pytest.approx(0.4 * COMMAND_WATCHDOG_S, abs=2 * DT)
    assert [n.code for n in notices] == ["watchdog"]


def test_velocity_noise_over_the_max_speed_is_clamped():
    t = tracker()
    over = 1 + VELOCITY_TOLERANCE / 2
    for k in range(50):  # keep the watchdog fed for 0.1 s
        t.command(ArmCommand(mode="velocity", values=[0.5 * over, -1.0 * over]), k * DT)
        t.step(t.q_ref, DT, (k + 1) * DT)
    assert t.q_ref[0] == pytest.approx(0.5 * 0.1, rel=1e-6)
    assert t.q_ref[1] == pytest.approx(-1.0 * 0.1, rel=1e-6)


def test_estop_is_latched_ignores_commands_and_notifies_once():
    notices = []
    t = tracker(notices)
    t.command(ArmCommand(mode="velocity", values=[0.4, 0.0]), 0.0)
    run(t, 0.1)
    t.set_estop(True, "button")
    t.set_estop(True, "button")
    held = t.q_ref.copy()
    with pytest.raises(CommandRejected, match="emergency stop"):
        t.command(ArmCommand(mode="velocity", values=[0.4, 0.0]), 0.1)
    run(t, 0.5, 0.1)
    assert np.allclose(t.q_ref, held)
    assert [n.code for n in notices] == ["estop"]
    t.set_estop(False)
    t.command(ArmCommand(mode="position", values=[0.0, 1.0]), 0.6)
    run(t, 2.0, 0.6)
    assert t.q_ref[1] == pytest.approx(1.0)


def test_a_blocked_joint_faults_and_needs_a_reset():
    notices = []
    t = tracker(notices)
    t.command(ArmCommand(mode="position", values=[0.9, 0.0]), 0.0)
    run(t, 2.0, follow=False)  # the measured position never moves: blocked
    assert t.mode == "fault" and "cannot follow" in t.fault
    assert notices[-1].code == "following_error"
    with pytest.raises(CommandRejected, match="reset_fault"):
        t.command(ArmCommand(mode="position", values=[0.0, 0.0]), 2.0)
    t.reset_fault([0.0, 0.0])
    t.command(ArmCommand(mode="position", values=[0.1, 0.0]), 2.0)
    assert t.mode == "position" and t.fault == ""


def test_feedforward_extrapolates_a_little_but_never_past_limits():
    t = tracker()
    t.q_ref[:] = [0.95, 0.0]
    t.command(ArmCommand(mode="position", values=[0.95, 0.0], velocities=[0.5, 0.5]), 0.0)
    run(t, 0.5)
    assert t.q_ref[0] == pytest.approx(0.975)          # at most FEEDFORWARD_HORIZON (50 ms) ahead
    assert t.q_ref[1] == pytest.approx(0.5 * 0.05)
    t.command(ArmCommand(mode="position", values=[0.99, 0.0], velocities=[0.5, 0.0]), 0.5)
    run(t, 0.5, 0.5)
    assert t.q_ref[0] == pytest.approx(1.0)            # never past the limit

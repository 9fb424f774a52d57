"""The sim's arm rules, without physics: limits, speeds, watchdog, estop, faults, as a driver's.

The rules themselves are GuardedArm's and JointReference's (tests/common/test_guarded_arm.py,
test_joint_reference.py); these check that the sim's arm keeps them on its own clock and lock,
and what is its own: the servos follow the set-point, a blocked joint faults."""

import math
import re
import threading

import numpy as np
import pytest

from asibot.messages import COMMAND_WATCHDOG_S
from asibot.safety.events import CommandRefused
from asibot.safety.joint_reference import POSITION_TOLERANCE_RAD, VELOCITY_TOLERANCE
from asibot.sim.arm import JointLimits, SimArm

DT = 0.002


class Arm:
    """A SimArm on a hand-turned clock; `follow`: the joints are where the set-point is."""

    def __init__(self) -> None:
        self.now = 0.0
        self.events: list[tuple[str, str, str]] = []
        self.stuck = False
        self.at: list[float] | None = None     # where the joints are measured, if not at the set-point
        limits = JointLimits.of(["a", "b"], [-1.0, -2.0], [1.0, 2.0], [0.5, 1.0])
        self.arm = SimArm(limits, [0.0, 0.0], DT, lambda *e: self.events.append(e), clock=lambda: self.now,
                          lock=threading.RLock(), measured=self.measured, max_opening=0.08)

    def measured(self) -> list[float]:
        if self.at is not None:
            return self.at
        return [0.0, 0.0] if self.stuck else self.arm.q_ref.tolist()

    def command(self, mode: str, values: list[float], velocities: list[float] | None = None) -> bool:
        return self.arm.command(mode, values, velocities or [], "kinematics")

    def run(self, seconds: float) -> None:
        for _ in range(int(round(seconds / DT))):
            self.now += DT
            self.arm.step(self.measured(), self.now)

    def codes(self) -> list[str]:
        return [code for _, code, _ in self.events]


def test_position_is_reached_at_the_max_speed_and_stays_within_limits():
    t = Arm()
    t.command("position", [1.0 + POSITION_TOLERANCE_RAD / 2, -0.5])
    t.run(0.5)
    assert t.arm.q_ref[0] == pytest.approx(0.25, abs=1e-9)    # 0.5 rad/s for 0.5 s
    assert t.arm.q_ref[1] == pytest.approx(-0.5, abs=1e-9)    # reached
    t.run(5.0)
    assert t.arm.q_ref[0] == 1.0                               # noise past the limit: clamped to it


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
    t = Arm()
    t.command("position", [0.5, 0.5])
    with pytest.raises(CommandRefused, match=re.escape(says)):
        t.command(mode, values, ff)
    t.run(2.0)
    assert t.arm.mode == "position" and t.arm.q_ref == pytest.approx([0.5, 0.5])   # the previous goal
    assert t.arm.counters["rejected_commands"] == 1


def test_a_joint_measured_past_a_limit_may_be_held_there():
    """MuJoCo's servos overshoot a limit by a few mrad as they arrive; the kinematics service
    holds where it measured the arm: not refused, and the set-point stays within the limits."""
    t = Arm()
    t.at = [1.008, 0.0]
    t.command("position", [1.008, 0.0])
    with pytest.raises(CommandRefused, match="upper limit"):
        t.command("position", [1.02, 0.0])
    t.run(3.0)
    assert t.arm.q_ref[0] == 1.0


def test_wrong_joint_count_is_refused_with_the_drivers_sentence_and_changes_nothing():
    t = Arm()
    with pytest.raises(ValueError, match=re.escape("the arm has 2 joints (a, b); the command has 3 values")):
        t.command("position", [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="velocities must be empty or have 2 values"):
        t.command("position", [0.1, 0.2], [0.1])
    assert t.arm.mode == "idle"


def test_velocity_mode_stops_after_the_watchdog_and_says_so():
    t = Arm()
    t.command("velocity", [0.4, 0.0])
    t.run(1.0)
    assert t.arm.q_ref[0] == pytest.approx(0.4 * COMMAND_WATCHDOG_S, abs=2 * DT)
    assert t.codes() == ["watchdog"]
    assert t.events[0][2] == "No velocity command for 200 ms: the arm stopped and holds its position."


def test_velocity_noise_over_the_max_speed_is_clamped():
    t = Arm()
    over = 1 + VELOCITY_TOLERANCE / 2
    for _ in range(50):  # keep the watchdog fed for 0.1 s
        t.command("velocity", [0.5 * over, -1.0 * over])
        t.run(DT)
    assert t.arm.q_ref[0] == pytest.approx(0.5 * 0.1, rel=1e-6)
    assert t.arm.q_ref[1] == pytest.approx(-1.0 * 0.1, rel=1e-6)


def test_the_estop_holds_the_arm_ignores_commands_and_arms_it_again_for_a_new_stream():
    t = Arm()
    t.command("velocity", [0.4, 0.0])
    t.run(0.1)
    t.arm.set_estop(True, "button")
    t.arm.set_estop(True, "button")
    held = t.arm.q_ref.copy()
    assert t.command("velocity", [0.4, 0.0]) is False          # ignored, never queued
    t.run(0.5)
    assert np.allclose(t.arm.q_ref, held)
    assert t.codes() == ["estop"] and t.arm.counters["ignored_commands"] == 1
    t.arm.set_estop(False)
    assert t.codes() == ["estop", "estop_released", "ready"]
    t.command("position", [0.0, 1.0])                         # a new stream: its sender paused 0.5 s
    t.run(2.0)
    assert t.arm.q_ref[1] == pytest.approx(1.0)


def test_a_blocked_joint_faults_and_is_ignored_until_a_reset_served_at_once():
    t = Arm()
    t.command("position", [0.9, 0.0])
    t.stuck = True                    # the measured position never moves: blocked
    t.run(2.0)
    assert t.arm.mode == "fault" and "cannot follow" in t.arm.fault
    assert t.codes()[-1] == "following_error" and t.arm.counters["faults"] == 1
    assert t.arm.q_ref == pytest.approx([0.0, 0.0])            # it holds where it is stuck
    assert t.command("position", [0.0, 0.0]) is False
    t.stuck = False
    assert t.arm.reset_fault() == {}                           # no control thread to wait for
    assert t.codes()[-2:] == ["fault_reset", "ready"]
    t.now += COMMAND_WATCHDOG_S + DT                           # a new stream (asibot.safety.arming)
    assert t.command("position", [0.1, 0.0]) is True
    assert t.arm.mode == "position" and t.arm.fault == ""


def test_feedforward_extrapolates_a_little_but_never_past_limits():
    t = Arm()
    t.arm.restart([0.95, 0.0])
    t.command("position", [0.95, 0.0], [0.5, 0.5])
    t.run(0.5)
    assert t.arm.q_ref[0] == pytest.approx(1.0)          # at most the horizon ahead, and never past the limit
    assert t.arm.q_ref[1] == pytest.approx(0.5 * 0.1)    # FEED_FORWARD_HORIZON_S (100 ms) ahead


@pytest.mark.parametrize("opening, says", [
    (0.09, "gripper opening 0.09 m is outside 0..0.08 m"),
    (-0.01, "gripper opening -0.01 m is outside 0..0.08 m"),
    (math.nan, "gripper opening nan is not a finite number"),
])
def test_a_gripper_opening_out_of_range_is_refused_as_the_katanas_is(opening, says):
    t = Arm()
    with pytest.raises(CommandRefused, match=re.escape(says)):
        t.arm.command_gripper(opening, "kinematics")
    assert t.arm.gripper_goal == 0.08                              # nothing changed: open


def test_the_gripper_obeys_the_arms_rules_and_a_fault_reset_keeps_what_it_holds():
    t = Arm()
    assert t.arm.command_gripper(0.0, "kinematics") is True and t.arm.gripper_goal == 0.0
    t.arm.set_estop(True, "button")
    assert t.arm.command_gripper(0.08, "kinematics") is False     # ignored, as the joints are
    assert t.arm.gripper_goal == 0.0
    t.arm.set_estop(False)
    t.now += COMMAND_WATCHDOG_S + DT                               # a new stream (asibot.safety.arming)
    t.command("position", [0.9, 0.0])
    t.stuck = True
    t.run(2.0)
    assert t.arm.mode == "fault"
    t.stuck = False
    t.arm.reset_fault()
    assert t.arm.gripper_goal == 0.0                               # still closed: nothing held drops

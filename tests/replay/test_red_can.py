"""Replay tests: today's kinematics against a committed "Give me the red can" session.

The fixture (recordings/fixtures/red_can.mcap, made by record_red_can.py) holds what the
simulated kitchen and the kinematics service said while the example program picked up the
can. These tests recompute the recorded outputs from the recorded inputs, so a change to
the conventions, the tool frame or the trajectories shows up as a difference from a real
session, not only from numbers someone typed into a test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asibot import keys, messages as m, robots
from asibot.kinematics.model import solver_for
from asibot.recorder.reader import iter_messages, summarize

ROBOT = "asibot-sim"
FIXTURE = Path(__file__).resolve().parents[2] / "recordings" / "fixtures" / "red_can.mcap"
TYPES = {keys.arm_state(ROBOT): m.ArmState, keys.arm_command(ROBOT): m.ArmCommand,
         keys.cart_state(ROBOT): m.CartState, keys.gripper_state(ROBOT): m.GripperState,
         keys.gripper_command(ROBOT): m.GripperCommand}


@pytest.fixture(scope="module")
def session() -> list[tuple[str, int, object]]:
    """(key, log time ns, decoded message) in recorded order; every payload must decode."""
    return [(r.key, r.log_time, m.decode(TYPES[r.key], r.payload)) for r in iter_messages(FIXTURE)]


@pytest.fixture(scope="module")
def model():
    return solver_for(robots.get(ROBOT))


def of(session, key):
    return [msg for k, _, msg in session if k == key]


def test_the_fixture_is_a_whole_session():
    s = summarize(FIXTURE)
    assert s.complete and set(s.counts) == set(TYPES)
    assert s.duration > 5 and s.counts[keys.arm_state(ROBOT)] > 200


def test_every_recorded_cartesian_pose_is_the_forward_kinematics_of_its_joints(session, model):
    states = of(session, keys.cart_state(ROBOT))
    assert len(states) > 100
    for st in states:
        assert model.fwd(st.joints) == pytest.approx(st.pose, abs=1e-9), st


def test_the_reported_joints_are_the_arm_states_the_driver_sent(session):
    sent = {tuple(s.positions) for s in of(session, keys.arm_state(ROBOT))}
    assert all(tuple(c.joints) in sent for c in of(session, keys.cart_state(ROBOT)))


def movl_segments(session) -> list[list[np.ndarray]]:
    """The position references sent while the controller said `movl`, one list per movl."""
    segments, current, state = [], None, ""
    for key, _, msg in session:
        if key == keys.cart_state(ROBOT):
            if msg.state == "movl" and state != "movl":
                current = []
                segments.append(current)
            state = msg.state
        elif key == keys.arm_command(ROBOT) and state == "movl" and msg.mode == "position":
            current.append(np.asarray(msg.values))
    return [s for s in segments if len(s) > 20]


def test_every_recorded_movl_is_a_straight_line_with_interpolated_orientation(session, model):
    segments = movl_segments(session)
    assert len(segments) == 2                    # reach down to the can, lift it
    for refs in segments:
        poses = np.array([model.fwd(q) for q in refs])
        start, end = poses[0, :3], poses[-1, :3]
        direction = (end - start) / np.linalg.norm(end - start)
        off_line = [np.linalg.norm((p - start) - np.dot(p - start, direction) * direction) for p in poses[:, :3]]
        assert max(off_line) < 1e-4                           # within 0.1 mm of the line
        assert abs(direction[2]) > 0.999                      # straight down, then straight up
        # The orientation goes from the measured start to the goal in step with the position.
        along = [np.dot(p - start, direction) / np.linalg.norm(end - start) for p in poses[:, :3]]
        expected = poses[0, 3:] + np.outer(along, poses[-1, 3:] - poses[0, 3:])
        assert poses[:, 3:] == pytest.approx(expected, abs=1e-6)


def test_the_gripper_closed_on_the_can_and_held_it(session):
    grips = of(session, keys.gripper_state(ROBOT))
    assert any(g.holding for g in grips)
    assert grips[-1].holding and 0.0 < grips[-1].opening < 0.08

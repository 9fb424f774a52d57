"""Issue 10, finding 1 and 4, for the sim (it keeps the driver contract): only the controller
that holds a part moves it (asibot.safety.ownership); a stream that keeps coming through an estop
moves nothing after the release until it pauses (asibot.safety.arming); the estop outlives whoever
engaged it (asibot.safety.estop).

The sim service in this process (real time, no cameras) on the in-memory bus."""

from __future__ import annotations

import time

import pytest

from asibot import keys
from asibot.safety import ownership
from asibot import messages as m
from asibot.bus import Bus
from asibot.testing import Inbox, Stream, wait_until, release, release_counts_only_signed

from .conftest import ROBOT


def stays_still(sim, seconds: float, arm_tolerance: float = 1e-3) -> None:
    """The arm, the fingers and the base stay where they are, sampled throughout `seconds`."""
    here, x0 = list(sim.arm.last().positions), sim.svc.sim.truth()[0]
    opening = sim.svc.sim.arm.gripper_goal
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        assert sim.arm.last().positions == pytest.approx(here, abs=arm_tolerance), "the arm moved"
        assert sim.svc.sim.truth()[0] == pytest.approx(x0, abs=1e-4), "the base moved"
        assert sim.svc.sim.arm.gripper_goal == opening, "the fingers were commanded"
        time.sleep(0.02)


def events(sim, code: str) -> list:
    return [e for e in sim.events.all() if e.code == code]


def test_commands_from_anyone_but_the_holder_move_nothing(sim):
    other = Bus("another-controller")
    try:
        second = ownership.announce(other, ROBOT, "arm", "kinematics")
        wait_until(lambda: second.id in sim.svc.holders["arm"].alive, 5)
        here = list(sim.arm.last().positions)
        goal = [here[0] + 0.3] + here[1:]
        def signed(controller, msg):
            return controller.sign(msg) if controller else msg
        for controller in (None, second, sim.base_controller):    # anonymous, the second one, the base's
            sim.user.publisher(keys.arm_command(ROBOT), m.ArmCommand).put(
                signed(controller, m.ArmCommand(mode="position", values=goal)))
            sim.user.publisher(keys.gripper_command(ROBOT), m.GripperCommand).put(
                signed(controller, m.GripperCommand(opening=0.0)))
        for controller in (None, sim.arm_controller):              # the arm's controller does not hold the base
            sim.user.publisher(keys.base_cmd_vel(ROBOT), m.Twist).put(signed(controller, m.Twist(vx=0.5, wz=0.0)))
        wait_until(lambda: len(events(sim, "not_holder")) >= 3, 5, message="a not_holder event per topic")
        stays_still(sim, 0.4)
        texts = " ".join(e.text for e in events(sim, "not_holder"))
        assert "Arm command refused" in texts and "Gripper command refused" in texts and "Base command refused" in texts
        assert f"controller {sim.base_controller.id!r} holds the base of {ROBOT}" in texts
        # The holders' ids, read from their liveliness tokens, borrowed by another process.
        sim.user.publisher(keys.arm_command(ROBOT), m.ArmCommand).put(
            m.ArmCommand(mode="position", values=goal, controller=sim.arm_controller.id))
        sim.user.publisher(keys.base_cmd_vel(ROBOT), m.Twist).put(
            m.Twist(vx=0.5, wz=0.0, controller=sim.base_controller.id))
        wait_until(lambda: len(events(sim, "not_signed")) >= 1, 5, message="no not_signed event")
        stays_still(sim, 0.4)
        sim.arm_controller.put(sim.user.publisher(keys.arm_command(ROBOT), m.ArmCommand),
                               m.ArmCommand(mode="position", values=goal))
        wait_until(lambda: abs(sim.arm.last().positions[0] - goal[0]) < 0.01, 10, message="the holder's command")
    finally:
        other.close()


@pytest.mark.parametrize("part", ["arm", "base"])
def test_a_stream_through_an_estop_moves_nothing_after_the_release_until_it_pauses(sim, part):
    if part == "arm":
        pub, msg, me = sim.user.publisher(keys.arm_command(ROBOT), m.ArmCommand), m.ArmCommand(
            mode="velocity", values=[0.2, 0, 0, 0, 0]), sim.arm_controller

        def moving() -> bool:
            return sim.arm.last().velocities[0] > 0.1
    else:
        pub, msg, me = sim.user.publisher(keys.base_cmd_vel(ROBOT), m.Twist), m.Twist(
            vx=0.3, wz=0.0), sim.base_controller

        def moving() -> bool:
            return sim.odom.last().vx > 0.1
    stream = Stream(lambda: me.put(pub, msg))
    try:
        wait_until(moving, 5, message="the stream did not move the robot")
        sim.user.latch(keys.estop(ROBOT), m.EStop(engaged=True, reason="test"))
        wait_until(lambda: events(sim, "estop"), 5)
        wait_until(lambda: max(map(abs, sim.arm.last().velocities)) < 1e-3 and abs(sim.odom.last().vx) < 1e-3, 5)
        release(sim.user, ROBOT, by="a tester")
        released = time.monotonic()
        wait_until(lambda: events(sim, "ready"), 5, message="no ready event")
        stays_still(sim, 0.6, arm_tolerance=5e-3)   # the stream goes on: nothing moves
        assert stream.longest_gap(released) < m.COMMAND_WATCHDOG_S / 2, "the machine paused the stream itself"
        wait_until(lambda: events(sim, "not_ready"), 5, message="no not_ready event")
        stream.pause()
        # Twice the gap the machine asks for: the sim measures it between arrivals, and on a
        # loaded machine the last command before the pause can arrive late.
        time.sleep(2 * m.COMMAND_WATCHDOG_S)
        stream.resume()
        wait_until(moving, 5, message="the restarted stream did not move the robot")
    finally:
        stream.close()


def test_the_estop_outlives_whoever_engaged_it_and_its_release_says_who(sim):
    with Bus("asibot-estop") as button:
        button.latch(keys.estop(ROBOT), m.EStop(engaged=True, reason="test", by="ana@home (asibot estop, pid 7)"))
        wait_until(lambda: events(sim, "estop"), 5)
    assert "engaged by ana@home (asibot estop, pid 7)" in events(sim, "estop")[0].text
    late = Bus("a-ui-started-later")
    try:
        learnt = Inbox()
        late.subscribe(keys.estop(ROBOT), m.EStop, learnt, latest=True)
        wait_until(lambda: len(learnt), 5, message="a late subscriber learnt nothing of the estop")
        assert learnt.last().engaged
        # Anyone can write a name; a release counts only signed, by the key it names.
        release_counts_only_signed(late, ROBOT, lambda code: events(sim, code), "bob@home (asibot release, pid 8)")
    finally:
        late.close()

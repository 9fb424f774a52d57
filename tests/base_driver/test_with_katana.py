"""The P3-AT with its Katana is one robot with one driver: the base driver serves the Katana
(`--katana`) under the same driver contract, as the sim serves pioneer-sim's arm and base. One
`status`, one `reset_fault`, one estop, a holder for each part."""

from __future__ import annotations

import pytest

from asibot import keys
from asibot.base_driver.service import BaseDriverService
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.messages import ArmCommand, ArmState, EStop, Odometry, Twist
from asibot.safety import ownership
from asibot.testing import Inbox, wait_until

ROBOT = "pioneer"


@pytest.fixture
def pioneer(memory_bus, emulator):
    svc_bus, user = Bus("base_driver"), Bus("test")
    svc = BaseDriverService(svc_bus, ROBOT, emulator.url, katana="emulated", calibrate_katana=False)
    arm_states, odom = Inbox(), Inbox()
    user.subscribe(keys.arm_state(ROBOT), ArmState, arm_states)
    user.subscribe(keys.base_odom(ROBOT), Odometry, odom)
    try:
        wait_until(lambda: len(arm_states) and arm_states.last().mode == "idle" and len(odom), 15,
                   message="the Pioneer's driver did not start both parts")
        yield svc, user, arm_states
    finally:
        user.close()
        svc.close()
        svc_bus.close()


def test_one_driver_serves_the_base_and_the_katana(pioneer):
    svc, user, arm_states = pioneer
    assert sorted(svc.contract.holders) == ["arm", "base"]
    status = user.call(keys.driver_rpc(ROBOT, "status"))
    assert status["robot"] == ROBOT and status["connected"] is True            # the base's own
    assert status["arm"]["serial"] == "emulated" and status["arm"]["fault"] == ""
    assert set(status["holders"]) == {"arm", "base"}
    # Each part obeys its own holder: the arm moves, the base is not touched by it.
    ctl_bus = Bus("test-arm-controller")
    try:
        arm = ownership.announce(ctl_bus, ROBOT, "arm", "test")
        wait_until(lambda: svc.contract.holders["arm"].current == arm.id, 5)
        start = arm_states.last().positions
        goal = [start[0] + 0.3, *start[1:]]
        arm.put(user.publisher(keys.arm_command(ROBOT), ArmCommand), ArmCommand(mode="position", values=goal))
        wait_until(lambda: abs(arm_states.last().positions[0] - goal[0]) < 0.01, 10,
                   message=lambda: f"the Katana stands at {arm_states.last().positions}")
        # A base command signed by the arm's controller is refused: it holds the arm only.
        arm.put(user.publisher(keys.base_cmd_vel(ROBOT), Twist), Twist(vx=0.2, wz=0.0))
        wait_until(lambda: svc.contract.not_holder >= 1, 3)
    finally:
        ctl_bus.close()


def test_the_estop_stops_both_parts_and_reset_fault_waits_for_its_release(pioneer):
    svc, user, arm_states = pioneer
    user.latch(keys.estop(ROBOT), EStop(engaged=True, reason="test"))
    wait_until(lambda: svc.driver.status()["estop"] and svc.arm is not None and svc.arm.status()["estop"], 5,
               message=lambda: f"base {svc.driver.status()['estop']}, arm {svc.arm.status() if svc.arm else None}")
    with pytest.raises(RpcError, match="release it before resetting faults"):
        user.call(keys.driver_rpc(ROBOT, "reset_fault"))


def test_the_emulated_katanas_faults_are_injected_through_the_robots_one_driver(pioneer):
    svc, user, arm_states = pioneer
    user.call(keys.driver_rpc(ROBOT, "inject_fault"), {"fault": "collision", "joint": arm_states.last().names[1]})
    wait_until(lambda: arm_states.last().fault != "", 5)
    assert "reports a collision" in arm_states.last().fault
    # The base is not faulted by it. (Its own fault may still change meanwhile: on a loaded
    # machine its motors were still being enabled as the test began.)
    assert "collision" not in svc.driver.status()["fault"]
    user.call(keys.driver_rpc(ROBOT, "reset_fault"))
    wait_until(lambda: arm_states.last().fault == "", 5)

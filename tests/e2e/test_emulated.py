"""`asibot up --profile emulated`: the real drivers against their wire-level emulators, driven
from the same client API and messages as the simulation."""

import time

import pytest

from asibot import keys
from asibot.safety import ownership
from asibot.client import CartesianClient
from asibot.messages import ArmState, Odometry, Twist
from asibot.testing import wait_until

pytestmark = pytest.mark.slow


def test_the_emulated_profile_drives_both_robots(up):
    stack = up("emulated")
    stack.wait_alive("arm_driver/asibot", "base_driver/pioneer", "kinematics/asibot", "recorder/main")

    # The arm: CANopen drives behind the kinematics service, from CartesianClient. The driver
    # announces itself once the five drives are in operation enabled.
    wait_until(lambda: stack.bus.alive(keys.driver_alive("asibot")), 20)
    states: list[ArmState] = []
    stack.bus.subscribe(keys.arm_state("asibot"), ArmState, states.append)
    with CartesianClient() as arm:
        arm.open("asibot")
        arm.movj(joints=[10, 20, 30, 20, 0])
        arm.wait(timeout=30)
        assert arm.state()["joints"] == pytest.approx([10, 20, 30, 20, 0], abs=0.2)
    assert states and states[-1].positions[0] == pytest.approx(0.1745, abs=0.005)

    # The base: ARCOS over TCP to the emulated P3-AT, cmd_vel in (from the controller that
    # holds the base: this test, asibot.safety.ownership), odometry out.
    controller = ownership.announce(stack.bus, "pioneer", "base", "test")
    wait_until(lambda: stack.bus.call(keys.driver_rpc("pioneer", "status"))["holders"]["base"] == controller.id, 10)
    odom: list[Odometry] = []
    stack.bus.subscribe(keys.base_odom("pioneer"), Odometry, odom.append)
    wait_until(lambda: odom, 10)
    x0 = odom[-1].x
    cmd = stack.bus.publisher(keys.base_cmd_vel("pioneer"), Twist)
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        controller.put(cmd, Twist(vx=0.3, wz=0.0))
        time.sleep(0.05)
    # The driver's 200 ms watchdog stops the base once the commands end.
    wait_until(lambda: abs(odom[-1].vx) < 1e-3, 5)
    assert odom[-1].x - x0 == pytest.approx(0.6, abs=0.12)

    assert stack.stop() == 130   # stopped by Ctrl-C: the shell's 128 + SIGINT

"""Fixtures: fresh simulations of both worlds (fast: built in a fraction of a second), and
the sim service of the apartment on the in-memory bus with controllers that hold its arm and
its base (`sim`)."""

from dataclasses import dataclass

import pytest

from asibot import keys, robots
from asibot.safety import ownership
from asibot import messages as m
from asibot.bus import Bus
from asibot.sim.service import Options, SimService
from asibot.sim.simulation import Simulation
from asibot.testing import Inbox, wait_until

ROBOT = "pioneer-sim"


@pytest.fixture
def robot_catalog():
    return robots


@pytest.fixture
def kitchen() -> Simulation:
    return Simulation("asibot-sim")


@pytest.fixture
def apartment() -> Simulation:
    return Simulation("pioneer-sim", odom_noise=(0.0, 0.0))


@dataclass
class SimOnBus:
    """The sim service (real time, no cameras) and a user on the in-memory bus. The test holds
    the arm and the base with the controllers `arm_controller` and `base_controller`
    (announced on `controller_bus`): its commands carry their ids (asibot.safety.ownership)."""
    svc: SimService
    user: Bus
    arm: Inbox
    odom: Inbox
    events: Inbox
    arm_controller: ownership.Controller
    base_controller: ownership.Controller
    controller_bus: Bus

    def __iter__(self):  # svc, user, arm, odom, events = sim
        return iter((self.svc, self.user, self.arm, self.odom, self.events))

    def codes(self) -> list[str]:
        return [e.code for e in self.events.all()]


@pytest.fixture
def sim(memory_bus):
    svc_bus, user, controller_bus = Bus("sim"), Bus("test"), Bus("test-controller")
    svc = SimService(svc_bus, Simulation(ROBOT, odom_noise=(0.0, 0.0)), Options(camera_hz=0.0))
    arm, odom, events = Inbox(), Inbox(), Inbox()
    user.subscribe(keys.arm_state(ROBOT), m.ArmState, arm)
    user.subscribe(keys.base_odom(ROBOT), m.Odometry, odom)
    user.subscribe(keys.events(ROBOT), m.Event, events)
    arm_controller = ownership.announce(controller_bus, ROBOT, "arm", "test")
    base_controller = ownership.announce(controller_bus, ROBOT, "base", "test")
    try:
        wait_until(lambda: len(arm) and len(odom), 10, message="the sim published no state")
        wait_until(lambda: svc.holders["arm"].current == arm_controller.id
                   and svc.holders["base"].current == base_controller.id, 5, message="the sim never saw the controllers")
        # let the arm settle at home under gravity before measuring stillness
        wait_until(lambda: max(map(abs, arm.last().velocities)) < 1e-3, 10)
        yield SimOnBus(svc, user, arm, odom, events, arm_controller, base_controller, controller_bus)
    finally:
        controller_bus.close()
        user.close()
        svc.close()
        svc_bus.close()

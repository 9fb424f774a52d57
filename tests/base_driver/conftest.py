"""Helpers: an in-memory line to an emulated robot with a fake clock, a TCP emulator, and the
driver service against it on the in-memory bus with a controller that holds the base (`base`)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from asibot import keys
from asibot.safety import ownership
from asibot.base_driver.emulator import ArcosEmulator
from asibot.base_driver.emulator.robot import EmulatedP3at
from asibot.base_driver.service import BaseDriverService
from asibot.bus import Bus
from asibot.messages import Event, Odometry
from asibot.testing import Inbox, wait_until

ROBOT = "pioneer"


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class RobotLink:
    """A Link straight into an EmulatedP3at: every read advances the fake clock by `tick`."""

    def __init__(self, robot: EmulatedP3at | None = None, clock: FakeClock | None = None, tick: float = 0.02):
        self.robot = robot or EmulatedP3at()
        self.clock = clock or FakeClock()
        self.tick = tick
        self.pending = bytearray()
        self.written: list[bytes] = []
        self.closed = False

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        self.pending += self.robot.receive(bytes(data), self.clock())
        return len(data)

    def read(self, size: int = 1) -> bytes:
        self.clock.t += self.tick
        self.pending += self.robot.step(self.clock())
        out = bytes(self.pending[:size])
        del self.pending[:size]
        return out

    @property
    def in_waiting(self) -> int:
        return len(self.pending)

    def reset_input_buffer(self) -> None:
        self.pending.clear()

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def emulator():
    with ArcosEmulator() as emu:
        yield emu


@dataclass
class BaseOnBus:
    """The base driver service and a user on the in-memory bus; `controller` is the id of a
    controller (announced on `controller_bus`: close it and it vanishes) that holds the base:
    the cmd_vel of the tests carry it (asibot.safety.ownership)."""
    svc: BaseDriverService
    user: Bus
    odom: Inbox
    events: Inbox
    emulator: ArcosEmulator
    controller: ownership.Controller
    controller_bus: Bus

    def codes(self) -> list[str]:
        return [e.code for e in self.events.all()]


@pytest.fixture
def base(memory_bus, emulator):
    """The service against the ARCOS emulator (a P3-AT over TCP), connected and held."""
    svc_bus, user, controller_bus = Bus("base_driver"), Bus("test"), Bus("test-controller")
    svc = BaseDriverService(svc_bus, ROBOT, emulator.url)      # --max-vx 0.5, --max-wz 100 deg/s
    odom, events = Inbox(), Inbox()
    user.subscribe(keys.base_odom(ROBOT), Odometry, odom)
    user.subscribe(keys.events(ROBOT), Event, events)
    controller = ownership.announce(controller_bus, ROBOT, "base", "test")
    try:
        wait_until(lambda: svc.driver.connected and len(odom), 5, message="no odometry on the bus")
        wait_until(lambda: svc.holder.current == controller.id, 5, message="the driver never saw the controller")
        yield BaseOnBus(svc, user, odom, events, emulator, controller, controller_bus)
    finally:
        controller_bus.close()
        user.close()
        svc.close()
        svc_bus.close()

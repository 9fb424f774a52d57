"""Fixtures: the emulated Katana on a pty with a `Katana` on the other end, both recording
their frames; and the whole service on the in-memory bus with a controller that holds the arm."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import pytest

from asibot import keys
from asibot.bus import Bus
from asibot.katana_driver.emulator import EmulatedLine, KatanaEmulator
from asibot.katana_driver.katana import Katana
from asibot.katana_driver.service import KatanaDriverService
from asibot.messages import ArmState, Event, GripperState
from asibot.safety import ownership
from asibot.testing import Inbox, wait_until

R = "pioneer"


@dataclass
class Recorder:
    """Frames one side saw, in order: ("tx" | "rx", bytes)."""
    frames: list[tuple[str, bytes]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def __call__(self, direction: str, data: bytes) -> None:
        with self.lock:
            self.frames.append((direction, bytes(data)))

    def sent(self) -> list[bytes]:
        with self.lock:
            return [d for k, d in self.frames if k == "tx"]

    def received(self) -> list[bytes]:
        with self.lock:
            return [d for k, d in self.frames if k == "rx"]


@dataclass
class Wire:
    emulator: KatanaEmulator
    line: EmulatedLine
    katana: Katana
    driver_side: Recorder
    emulator_side: Recorder


def wire(**emulator_options) -> Wire:
    emu = KatanaEmulator(**emulator_options)
    emulator_side, driver_side = Recorder(), Recorder()
    line = EmulatedLine(emu, trace=emulator_side)
    return Wire(emu, line, Katana(line.port, trace=driver_side, timeout=0.1, retries=1), driver_side, emulator_side)


@pytest.fixture
def line():
    """An emulated, calibrated Katana on a pty and the Katana class on its other end."""
    w = wire()
    yield w
    w.line.close()


@dataclass
class KatanaOnBus:
    svc: KatanaDriverService
    user: Bus
    states: Inbox
    grippers: Inbox
    events: Inbox
    controller: ownership.Controller
    controller_bus: Bus

    @property
    def emulator(self) -> KatanaEmulator:
        assert self.svc.emulator is not None
        return self.svc.emulator

    def codes(self) -> list[str]:
        return [e.code for e in self.events.all()]

    def texts(self, code: str) -> list[str]:
        return [e.text for e in self.events.all() if e.code == code]


@pytest.fixture
def katana(memory_bus):
    """The service with an emulated Katana calibrated since it was switched on, idle, on the
    in-memory bus; a short read timeout and one retry, so that silence shows in 0.2 s."""
    svc_bus, user = Bus("katana_driver"), Bus("test")
    svc = KatanaDriverService(svc_bus, R, "emulated", calibrate=False, emulator=KatanaEmulator(),
                              timeout=0.1, retries=1)
    states, grippers, events = Inbox(), Inbox(), Inbox()
    user.subscribe(keys.arm_state(R), ArmState, states)
    user.subscribe(keys.gripper_state(R), GripperState, grippers)
    user.subscribe(keys.events(R), Event, events)
    controller_bus = Bus("test-controller")
    controller = ownership.announce(controller_bus, R, "arm", "test")
    try:
        wait_until(lambda: len(states) and states.last().mode == "idle", 15, message="the Katana driver did not start")
        wait_until(lambda: svc.holder.current == controller.id, 5, message="the driver never saw the controller")
        yield KatanaOnBus(svc, user, states, grippers, events, controller, controller_bus)
    finally:
        controller_bus.close()
        user.close()
        svc.close()
        svc_bus.close()

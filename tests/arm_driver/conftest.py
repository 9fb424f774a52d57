"""Fixtures: a private virtual CAN channel with the five emulated drives, a sniffer on it,
and the arm driver (without Zenoh) whose states and events are captured; and the whole
service on the in-memory bus with a controller that holds the arm (`arm`)."""

from __future__ import annotations

import dataclasses
import threading
import uuid
from dataclasses import dataclass, field

import can
import pytest

from asibot import keys
from asibot.safety import ownership
from asibot.arm_driver import config, emulator
from asibot.arm_driver.driver import ArmDriver
from asibot.arm_driver.master import CanopenMaster
from asibot.arm_driver.service import ArmDriverService
from asibot.bus import Bus
from asibot.messages import ArmState, Event
from asibot.testing import Inbox, wait_until

R = "asibot"


class Sniffer(can.Listener):
    """Records every frame seen on the channel (a third bus: it hears master and drives)."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.frames: list[can.Message] = []
        self._lock = threading.Lock()
        self.notifier = can.Notifier(self.bus, [self], timeout=0.01)

    def on_message_received(self, msg: can.Message) -> None:
        with self._lock:
            self.frames.append(msg)

    def seen(self) -> list[tuple[int, bytes, float]]:
        with self._lock:
            return [(m.arbitration_id, bytes(m.data), m.timestamp) for m in self.frames if not m.is_error_frame]

    def clear(self) -> None:
        with self._lock:
            self.frames.clear()

    def close(self) -> None:
        self.notifier.stop()
        self.bus.shutdown()


@dataclass
class Rig:
    cfg: config.ArmConfig
    emu: emulator.DriveEmulator
    master: CanopenMaster
    sniffer: Sniffer
    driver: ArmDriver | None = None
    states: list = field(default_factory=list)
    events: list = field(default_factory=list)

    @property
    def last(self):
        return self.states[-1]

    def event_codes(self) -> list[str]:
        return [e[1] for e in list(self.events)]

    def start_driver(self) -> ArmDriver:
        self.driver = ArmDriver(self.master, self.cfg, self.states.append, lambda *e: self.events.append(e))
        self.driver.start()
        return self.driver


@pytest.fixture
def cfg() -> config.ArmConfig:
    return config.load("asibot")


#: Missed heartbeat periods before the driver calls a drive silent, in the rigs of tests about
#: anything else than that: the robot's file says 1.5 (0.15 s), for drives on a CAN bus of their
#: own. The emulated drives are threads of a test process on a loaded two-core CI machine: their
#: heartbeats came 0.17-0.26 s apart in two runs, and tests of other things stopped on it.
#: The tests of heartbeat loss itself use `strict_rig`, with the robot's figure.
PATIENT_PERIODS = 6.0


def patient(cfg: config.ArmConfig) -> config.ArmConfig:
    return dataclasses.replace(cfg, heartbeat_timeout_periods=PATIENT_PERIODS)


def _rig(cfg: config.ArmConfig, **emulator_options) -> Rig:
    channel = f"test-{uuid.uuid4().hex[:8]}"
    sniffer = Sniffer(channel)
    emulator_options.setdefault("encoders", emulator.encoders_of(cfg))
    bus, emu = emulator.start_private(channel, cfg.nodes, **emulator_options)
    return Rig(cfg, emu, CanopenMaster(bus, cfg), sniffer)


@pytest.fixture
def rig(cfg):
    """Master + 5 emulated drives (CSP capable); call rig.start_driver() to run the driver.
    A drive is silent after PATIENT_PERIODS missed heartbeats."""
    r = _rig(patient(cfg))
    yield r
    _close(r)


@pytest.fixture
def strict_rig(cfg):
    """As `rig`, with the robot's own heartbeat timeout: for the tests of heartbeat loss."""
    r = _rig(cfg)
    yield r
    _close(r)


#: Where the joints stand when the arm is switched on in `cold_rig`, rad: q2..q4 away from
#: zero (their absolute encoders must tell), q1 and q5 at zero as the ASIBOT requires.
COLD_ANGLES = {1: 0.0, 2: 0.5, 3: -0.4, 4: 0.3, 5: 0.0}


@pytest.fixture
def cold_rig(cfg):
    """As `rig`, just switched on: every drive counts from 0 wherever its joint stands."""
    r = _rig(patient(cfg), positions=COLD_ANGLES)
    for node in cfg.nodes:
        r.emu.power_cycle(node)
    yield r
    _close(r)


@pytest.fixture
def pp_rig(cfg):
    """Same, but the drives only know profile position."""
    r = _rig(patient(cfg), supports_csp=False)
    yield r
    _close(r)


def _close(r: Rig) -> None:
    if r.driver is not None:
        r.driver.close()
    else:
        r.master.close()
    r.emu.close()
    r.sniffer.close()


@dataclass
class ArmOnBus:
    """The arm driver service and a user on the in-memory bus; `controller` is the id of a
    controller (announced on `controller_bus`: close it and it vanishes) that holds the arm:
    the commands of the tests carry it (asibot.safety.ownership)."""
    svc: ArmDriverService
    user: Bus
    states: Inbox
    events: Inbox
    controller: ownership.Controller
    controller_bus: Bus

    def codes(self) -> list[str]:
        return [e.code for e in self.events.all()]


@pytest.fixture
def arm(memory_bus):
    """The arm driver service with its five emulated drives, idle, on the in-memory bus."""
    svc_bus, user = Bus("arm_driver"), Bus("test")
    svc = ArmDriverService(svc_bus, R, "emulated")
    states, events = Inbox(), Inbox()
    user.subscribe(keys.arm_state(R), ArmState, states)
    user.subscribe(keys.events(R), Event, events)
    controller_bus = Bus("test-controller")
    controller = ownership.announce(controller_bus, R, "arm", "test")
    try:
        wait_until(lambda: len(states) and states.last().mode == "idle", 15, message="the arm driver did not start")
        wait_until(lambda: svc.holder.current == controller.id, 5, message="the driver never saw the controller")
        yield ArmOnBus(svc, user, states, events, controller, controller_bus)
    finally:
        controller_bus.close()
        user.close()
        svc.close()
        svc_bus.close()

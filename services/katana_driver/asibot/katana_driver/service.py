"""The Zenoh glue: bus messages to KatanaDriver calls, and the arm's state and events out.

Publishes arm_state and gripper_state; the rest of the driver contract (commands from the
holder only, the estop, events, `status`, `reset_fault`, driver_alive) is
`asibot.safety.driver_contract`'s, with `inject_fault` on the emulated controller.
"""

from __future__ import annotations

import argparse
import logging
from typing import Any, Callable

import serial

from asibot import keys, robots, runtime
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.katana_driver import protocol as p
from asibot.katana_driver.driver import FaultError, KatanaDriver
from asibot.katana_driver.emulator import EmulatedLine, KatanaEmulator
from asibot.katana_driver.katana import Katana
from asibot.messages import ArmCommand, ArmState, GripperCommand, GripperState
from asibot.runtime import Service
from asibot.safety.driver_contract import Command, DriverContract, command
from asibot.verbs import Field, Handler, OneOf, Verb

log = logging.getLogger(__name__)

NAME = "katana_driver"
DEFAULT_ROBOT = "pioneer"
EMULATED = "emulated"
FAULTS = ("collision", "silent", "clear")


def verbs(joints: list[str]) -> dict[str, Verb]:
    """The driver's own verb with the emulated controller."""
    return {"inject_fault": Verb({
        "fault": Field(OneOf(FAULTS), required=True),
        "joint": Field(OneOf((*joints, "gripper")), also="the motor that collides"),
    }, doc="emulated Katana only: a motor collides, or the controller goes silent (clear ends silence)")}


class KatanaArm:
    """The Katana's side of a driver: its serial line (or the emulator), its control loop, its
    states out, and what the driver contract asks of an arm. Served alone by KatanaDriverService,
    or beside the P3-AT's base in the base driver's process (`asibot.base_driver --katana`): one
    robot, one driver contract, as the sim serves both of pioneer-sim's parts."""

    def __init__(self, bus: Bus, robot: str, port: str, on_event: Callable[[str, str, str], None], *,
                 calibrate: bool = True, emulator: KatanaEmulator | None = None,
                 timeout: float = p.READ_TIMEOUT_S, retries: int = p.RETRIES) -> None:
        self.robot = robot
        self.spec = robots.get(robot)
        if self.spec.arm != "katana":
            raise ValueError(f"robot {robot!r} has no Katana arm (its arm: {self.spec.arm}); "
                             f"the Katana's robots: {', '.join(r for r in robots.ids() if robots.get(r).arm == 'katana')}")
        self.emulator: KatanaEmulator | None = None
        self.line: EmulatedLine | None = None
        if port == EMULATED:
            # Just switched on, parked where calibration leaves it: it calibrates as a real one
            # (or, without calibration, one calibrated since it was switched on).
            self.emulator = emulator or KatanaEmulator(calibrated=not calibrate)
            self.line = EmulatedLine(self.emulator)
            link: Any = self.line.port
        else:
            try:
                link = serial.serial_for_url(port, baudrate=p.BAUD, bytesize=p.BYTESIZE, parity=p.PARITY,
                                             stopbits=p.STOPBITS, timeout=0.01, write_timeout=1.0)
            except serial.SerialException as exc:
                raise ValueError(f"cannot open the Katana's serial port {port}: {exc}") from None
        self.link = link
        self._state = bus.publisher(keys.arm_state(robot), ArmState)
        self._gripper = bus.publisher(keys.gripper_state(robot), GripperState)
        self.katana = Katana(link, timeout=timeout, retries=retries)
        self.driver = KatanaDriver(self.katana, self.spec, self._publish, on_event, calibrate=calibrate)

    # ------------------------------------------------------------ what the contract serves
    def commands(self) -> list[Command]:
        return [command("arm", self._obey, self.driver.heard),
                command("gripper", self._obey_gripper, self.driver.heard)]

    def on_holder(self, part: str, holder: str | None) -> None:
        self.driver.set_controller(holder)

    def on_estop(self, engaged: bool, reason: str, by: str) -> None:
        self.driver.set_estop(engaged, reason, by)

    def verbs(self) -> dict[str, Verb]:
        return verbs(self.driver.names) if self.emulator is not None else {}

    def handlers(self) -> dict[str, Handler]:
        return {"inject_fault": self._inject_fault} if self.emulator is not None else {}

    def status(self) -> dict:
        return {**self.driver.status(), "serial": "emulated" if self.emulator else getattr(self.link, "port", "")}

    def reset_fault(self) -> dict:
        try:
            return self.driver.reset_fault()
        except FaultError as exc:
            raise RpcError("fault", str(exc)) from None

    # ------------------------------------------------------------ in
    def _obey(self, cmd: ArmCommand) -> None:
        self.driver.command(cmd.mode, cmd.values, cmd.velocities, cmd.controller)

    def _obey_gripper(self, cmd: GripperCommand) -> None:
        self.driver.command_gripper(cmd.opening, cmd.controller)

    def _inject_fault(self, a: Any) -> dict:
        emu = self.emulator
        if emu is None:
            raise RpcError("unavailable", "Faults can be injected only into the emulated Katana (--serial emulated).")
        if a.fault == "clear":
            emu.go_silent(False)
        elif a.fault == "silent":
            emu.go_silent(True)
        else:
            if a.joint is None:
                raise RpcError("bad_request", f"inject_fault collision needs 'joint': one of "
                                              f"{', '.join(self.driver.names)}, gripper.")
            names = [*self.driver.names, "gripper"]
            emu.collide(names.index(a.joint) + 1)
        return {}

    # ------------------------------------------------------------ out
    def _publish(self, arm: ArmState, gripper: GripperState) -> None:
        self._state.put(arm)
        self._gripper.put(gripper)

    # ------------------------------------------------------------ life
    def start(self) -> None:
        self.driver.start()

    def health(self) -> dict:
        return self.driver.health()

    def close(self) -> None:
        self.driver.close()
        if self.line is not None:
            self.line.close()
        else:
            self.link.close()


class KatanaDriverService(Service):
    """The driver contract for a Katana alone, on the serial port `port` (a device, any pyserial
    URL, or 'emulated')."""

    def __init__(self, bus: Bus, robot: str, port: str, *, calibrate: bool = True,
                 emulator: KatanaEmulator | None = None, timeout: float = p.READ_TIMEOUT_S,
                 retries: int = p.RETRIES) -> None:
        self.robot = robot
        self.bus = bus
        self.contract = DriverContract(bus, robot)
        self.arm = KatanaArm(bus, robot, port, self.contract.event, calibrate=calibrate, emulator=emulator,
                             timeout=timeout, retries=retries)
        self.driver, self.emulator = self.arm.driver, self.arm.emulator
        self.contract.serve(self.arm.commands(), on_holder=self.arm.on_holder, on_estop=self.arm.on_estop,
                            status=self.arm.status, reset_fault=self.arm.reset_fault,
                            verbs=self.arm.verbs(), handlers=self.arm.handlers())
        self.holder = self.contract.holders["arm"]
        self.arm.start()

    def health(self) -> dict:
        return {**self.arm.health(), **self.contract.health()}

    def close(self) -> None:
        self.contract.close()
        self.arm.close()


def add_arguments(p_: argparse.ArgumentParser) -> None:
    p_.add_argument("--serial", default=None,
                    help="the Katana's serial port, as pyserial's serial_for_url names it: /dev/ttyUSB0, "
                         f"rfc2217://host:port, ... or '{EMULATED}' (an emulated Katana in this process)")
    p_.add_argument("--skip-calibration", action="store_true",
                    help="trust the counters: the Katana was calibrated since it was switched on")


def build(bus: Bus, args: argparse.Namespace) -> KatanaDriverService:
    port = args.serial
    if not port:
        raise ValueError(f"no serial port: pass --serial /dev/ttyUSB0 (or --serial {EMULATED})")
    robot = runtime.robot_id(args, DEFAULT_ROBOT)
    if not args.robot and args.instance == "main":   # the runtime announces svc/katana_driver/<instance> after build
        args.instance = robot
    try:
        robots.get(robot)
    except KeyError as exc:
        raise ValueError(f"--robot: {exc.args[0]}") from None
    return KatanaDriverService(bus, robot, port, calibrate=not args.skip_calibration)

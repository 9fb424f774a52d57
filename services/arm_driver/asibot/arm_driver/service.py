"""The Zenoh glue: bus messages to ArmDriver calls, and the driver's state and events out.

Publishes arm_state; the rest of the driver contract (arm_command from the holder only, the
estop, events, `status`, `reset_fault`, driver_alive) is `asibot.safety.driver_contract`'s, with
`inject_fault` on the emulated bus (its table: `verbs`).
"""

from __future__ import annotations

import argparse
import logging
import os
from typing import Any, Sequence

from asibot import keys, runtime
from asibot.arm_driver import canbus, config
from asibot.arm_driver import emulator as emulation
from asibot.arm_driver.driver import ArmDriver, FaultError
from asibot.arm_driver.master import CanopenMaster
from asibot.bus import Bus
from asibot.safety.driver_contract import DriverContract, command
from asibot.errors import RpcError
from asibot.messages import ArmCommand, ArmState
from asibot.runtime import Service
from asibot.verbs import Field, Number, OneOf, Verb

log = logging.getLogger(__name__)

NAME = "arm_driver"
DEFAULT_ROBOT = "asibot"
CAN_ENV = "ASIBOT_ARM_CAN"
FAULTS = ("over_current", "heartbeat_loss", "silent", "bus_off", "reboot", "power_cycle",
          "encoder_silent", "encoder_error", "clear")
#: Longest bus_off an injection may ask for, s.
MAX_BUS_OFF = 60.0


def verbs(joints: Sequence[str]) -> dict[str, Verb]:
    """The driver's own verb on the emulated bus, for an arm whose joints are named `joints`."""
    return {"inject_fault": Verb({
        "fault": Field(OneOf(FAULTS), required=True),
        "joint": Field(OneOf(tuple(joints)), also="for a fault of one drive or encoder"),
        "seconds": Field(Number(0.0, MAX_BUS_OFF, "s", open_low=True), default=0.5, also="how long bus_off lasts"),
    }, doc="emulated CAN bus only: make a drive or an absolute encoder fail as real ones do (clear undoes "
           "all but latched faults)")}


class ArmDriverService(Service):
    """The driver contract for one CANopen arm."""

    def __init__(self, bus: Bus, robot: str, can_name: str, config_path: str | None = None) -> None:
        self.robot = robot
        self.config = config.load(robot, config_path)
        spec = canbus.parse(can_name)
        self.emulator = None
        if spec.emulated:
            if spec.channel not in ("", "pp"):
                raise ValueError("use --can emulated, or --can emulated:pp for drives without cyclic "
                                 "synchronous position")
            can_bus, self.emulator = emulation.start_private(
                canbus.private_channel(), self.config.nodes, supports_csp=spec.channel != "pp",
                counts_per_rad=self.config.joints[0].units.counts_per_rad,
                encoders=emulation.encoders_of(self.config))
        else:
            can_bus = canbus.open_bus(spec, self.config.bitrate)
        self._state = bus.publisher(keys.arm_state(robot), ArmState)
        self.bus = bus
        self.contract = DriverContract(bus, robot)
        self.driver = ArmDriver(CanopenMaster(can_bus, self.config), self.config,
                                on_state=self._state.put, on_event=self.contract.event)
        emulated = self.emulator is not None
        self.contract.serve(
            [command("arm", self._obey, self.driver.heard)],
            on_holder=lambda part, holder: self.driver.set_controller(holder), on_estop=self.driver.set_estop,
            status=self.driver.status, reset_fault=self._reset_fault,
            verbs=verbs(self.config.names) if emulated else {},
            handlers={"inject_fault": self._inject_fault} if emulated else {})
        self.holder = self.contract.holders["arm"]
        self.driver.start()

    @property
    def not_holder(self) -> int:
        return self.contract.not_holder

    # ------------------------------------------------------------ in
    def _obey(self, cmd: ArmCommand) -> None:
        self.driver.command(cmd.mode, cmd.values, cmd.velocities, cmd.controller)

    def _reset_fault(self) -> dict:
        try:
            return self.driver.reset_fault()
        except FaultError as exc:
            raise RpcError("fault", str(exc)) from None

    def _inject_fault(self, a: Any) -> dict:
        """Emulated bus only: `fault` (one of FAULTS) of `joint`'s drive, or of its absolute
        encoder for encoder_*; bus_off for `seconds`; clear undoes all but latched ones."""
        emu = self.emulator
        if emu is None:     # the verb is served only on the emulated bus
            raise RpcError("unavailable", "Faults can be injected only on the emulated CAN bus (--can emulated).")
        if a.fault == "clear":
            emu.clear()
            return {}
        if a.fault == "bus_off":
            emu.bus_off(a.seconds)
            return {}
        if a.joint is None:
            raise RpcError("bad_request", f"inject_fault {a.fault} needs 'joint': one of {', '.join(self.config.names)}.")
        j = self.config.joints[self.config.names.index(a.joint)]
        if a.fault.startswith("encoder_"):
            if j.absolute is None:
                with_encoder = ", ".join(x.name for x in self.config.joints if x.absolute)
                raise RpcError("bad_request", f"joint {a.joint} has no absolute encoder; these do: {with_encoder}")
            emu.encoder_fault(j.absolute.can_id, a.fault.removeprefix("encoder_"))
            return {}
        {"over_current": emu.over_current, "heartbeat_loss": emu.heartbeat_loss,
         "silent": emu.silent, "reboot": emu.reboot, "power_cycle": emu.power_cycle}[a.fault](j.node)
        return {}

    # ------------------------------------------------------------ runtime hooks
    def health(self) -> dict:
        return {**self.driver.health(), **self.contract.health()}

    def close(self) -> None:
        self.contract.close()
        self.driver.close()
        if self.emulator is not None:
            self.emulator.close()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--can", default=None,
                   help="CAN bus, named like python-can: socketcan:can0, pcan:PCAN_USBBUS1, virtual:NAME, or "
                        f"'emulated' (5 emulated drives in this process); default ${CAN_ENV}")
    p.add_argument("--config", default=None, help="CAN configuration YAML (default: robots/<robot>.yaml)")


def build(bus: Bus, args: argparse.Namespace) -> ArmDriverService:
    can_name = args.can or os.environ.get(CAN_ENV)
    if not can_name:
        raise ValueError(f"no CAN bus: pass --can socketcan:can0 (or pcan:PCAN_USBBUS1, or emulated), "
                         f"or set {CAN_ENV}")
    robot = runtime.robot_id(args, DEFAULT_ROBOT)
    if not args.robot and args.instance == "main":   # the runtime announces svc/arm_driver/<instance> after build
        args.instance = robot
    return ArmDriverService(bus, robot, can_name, args.config)

"""The Zenoh glue: bus messages to ArmDriver calls, and the driver's state and events out.

Keys: publishes arm_state and events, subscribes arm_command and estop (latched, and kept
served: asibot.estop), watches the controllers' liveliness to know which one holds the arm
(asibot.ownership: only its commands are obeyed); serves driver rpc `status`, `reset_fault`
and, on the emulated bus, `inject_fault`; announces driver_alive.
"""

from __future__ import annotations

import argparse
import logging
import os

from asibot import estop, keys
from asibot.arm_driver import canbus, config
from asibot.arm_driver import emulator as emulation
from asibot.arm_driver.driver import ArmDriver, FaultError
from asibot.arm_driver.master import CanopenMaster
from asibot.arming import NotReady
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.estop import EStopState
from asibot.events import CommandRefused, EventThrottle, refusal_reason
from asibot.messages import ArmCommand, ArmState, EStop, Event
from asibot.ownership import Holder, NotHolder, holders_status
from asibot.runtime import Service

log = logging.getLogger(__name__)

NAME = "arm_driver"
DEFAULT_ROBOT = "asibot"
CAN_ENV = "ASIBOT_ARM_CAN"
FAULTS = ("over_current", "heartbeat_loss", "silent", "bus_off", "reboot", "power_cycle",
          "encoder_silent", "encoder_error", "clear")


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
        self._events = bus.publisher(keys.events(robot), Event)
        # Refused commands: one Event a second per reason, the rest counted (issue 10).
        self._refusals = EventThrottle(self._events.put)
        self.bus = bus
        self.driver = ArmDriver(CanopenMaster(can_bus, self.config), self.config,
                                on_state=self._state.put, on_event=self._event)
        self.estop = EStopState(bus, robot, self._on_estop, self._release_refused)
        self.holder = Holder(robot, "arm", on_change=self.driver.set_controller)
        self.holder.follow(bus)
        self.not_holder = 0
        bus.subscribe(keys.arm_command(robot), ArmCommand, self._on_command, with_key=True,
                      on_reject=self._refuse_command)
        bus.serve(keys.driver_rpc(robot, "status"), self._status)
        bus.serve(keys.driver_rpc(robot, "reset_fault"), self._reset_fault)
        if self.emulator is not None:
            bus.serve(keys.driver_rpc(robot, "inject_fault"), self._inject_fault)
        bus.announce(keys.driver_alive(robot))
        self.driver.start()

    # ------------------------------------------------------------ in
    def _on_command(self, key: str, cmd: ArmCommand) -> None:
        refused = self.holder.refusal(cmd)
        if refused is not None:     # not the holder's: noted for re-arming, never obeyed
            self.not_holder += 1
            if isinstance(refused, NotHolder):   # a forged one says nothing of the holder's stream
                self.driver.heard(cmd.controller)
            self._refuse_command(key, refused)
            return
        try:
            self.driver.command(cmd.mode, cmd.values, cmd.velocities, cmd.controller)
        except NotReady as exc:     # a stream from before a recovery
            self._refuse_command(key, exc)
        except ValueError as exc:  # beyond the limits, not finite, wrong length: the driver's sentence
            self.bus.reject(key, exc)
            self._refuse_command(key, exc)

    def _refuse_command(self, key: str, exc: Exception) -> None:
        # Answered with an Event, as the driver contract asks, not only counted; a stream of
        # refusals gives one Event a second per reason, with the count of the others.
        level, code = (exc.level, exc.code) if isinstance(exc, CommandRefused) else ("error", "bad_command")
        self._refusals.event(level, code,
                             f"Arm command refused, the arm keeps its previous motion: {str(exc).rstrip('.')}.",
                             reason=f"arm:{refusal_reason(exc)}")

    def _on_estop(self, msg: EStop) -> None:
        self.driver.set_estop(msg.engaged, msg.reason, estop.named(msg))

    def _release_refused(self, msg: EStop, why: str) -> None:
        self._refusals.event("warning", "release_refused", estop.refused_text(msg, why), reason="estop:release")

    def _status(self, request: dict) -> dict:
        return {"robot": self.robot, **holders_status([self.holder]), **self.driver.status()}

    def _reset_fault(self, request: dict) -> dict:
        try:
            return self.driver.reset_fault()
        except FaultError as exc:
            raise RpcError("fault", str(exc)) from None

    def _inject_fault(self, request: dict) -> dict:
        """Emulated bus only: {"fault": one of FAULTS, "joint": "q3", "seconds": 0.5 (bus_off)}.
        encoder_* faults concern the joint's absolute encoder; clear undoes all but latched ones."""
        fault = request.get("fault")
        if fault not in FAULTS:
            raise RpcError("bad_request", f"fault must be one of {', '.join(FAULTS)}")
        emu = self.emulator
        if fault == "clear":
            emu.clear()
            return {}
        if fault == "bus_off":
            seconds = request.get("seconds", 0.5)
            if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not 0 < seconds <= 60:
                raise RpcError("bad_request", "seconds must be a number between 0 and 60")
            emu.bus_off(float(seconds))
            return {}
        joint = request.get("joint")
        if joint not in self.config.names:
            raise RpcError("bad_request", f"joint must be one of {', '.join(self.config.names)}")
        j = self.config.joints[self.config.names.index(joint)]
        if fault.startswith("encoder_"):
            if j.absolute is None:
                with_encoder = ", ".join(x.name for x in self.config.joints if x.absolute)
                raise RpcError("bad_request", f"joint {joint} has no absolute encoder; these do: {with_encoder}")
            emu.encoder_fault(j.absolute.can_id, fault.removeprefix("encoder_"))
            return {}
        {"over_current": emu.over_current, "heartbeat_loss": emu.heartbeat_loss,
         "silent": emu.silent, "reboot": emu.reboot, "power_cycle": emu.power_cycle}[fault](j.node)
        return {}

    # ------------------------------------------------------------ out
    def _event(self, level: str, code: str, text: str) -> None:
        self._events.put(Event(level=level, code=code, text=text))

    # ------------------------------------------------------------ runtime hooks
    def health(self) -> dict:
        return {**self.driver.health(), "holder": self.holder.current or "", "not_holder": self.not_holder}

    def close(self) -> None:
        self._refusals.close()
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
    if not args.robot:
        args.robot = DEFAULT_ROBOT
        if args.instance == "main":      # the runtime announces svc/arm_driver/<instance> after build
            args.instance = DEFAULT_ROBOT
    return ArmDriverService(bus, args.robot, can_name, args.config)

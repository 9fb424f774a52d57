"""The Zenoh glue: bus messages to BaseDriver calls, BaseState to bus messages. Nothing else.

The driver contract (cmd_vel from the holder only, the estop, events, `status`,
`reset_fault`, driver_alive) is `asibot.safety.driver_contract`'s. The P3-AT's Katana, when it
has one (`--katana PORT`), is served in this process under the same contract: one robot, one
driver, as the sim serves pioneer-sim's arm and base (`asibot.katana_driver.KatanaArm`).
"""

from __future__ import annotations

import argparse
import logging
import math
import os

from asibot import keys
from asibot.bus import Bus
from asibot.safety.driver_contract import DriverContract, command
from asibot.katana_driver.service import KatanaArm
from asibot.messages import Battery, Bumpers, Odometry, Sonar, Twist
from asibot.runtime import Service

from asibot.base_driver.driver import DEFAULT_MAX_VX, DEFAULT_MAX_WZ, BaseDriver
from asibot.base_driver.params import KNOWN
from asibot.base_driver.state import BaseState

log = logging.getLogger(__name__)

NAME = "base_driver"
DEFAULT_ROBOT = "pioneer"
KATANA_ENV = "ASIBOT_KATANA_PORT"


class BaseDriverService(Service):
    """Publishes the base side of the driver contract for one robot id."""

    def __init__(self, bus: Bus, robot: str, port: str, *, baud: int = 9600, params: str | None = None,
                 max_vx: float = DEFAULT_MAX_VX, max_wz: float = DEFAULT_MAX_WZ, katana: str = "",
                 calibrate_katana: bool = True) -> None:
        self.robot = robot
        self._odom = bus.publisher(keys.base_odom(robot), Odometry)
        self._sonar = bus.publisher(keys.base_sonar(robot), Sonar)
        self._bumpers = bus.publisher(keys.base_bumpers(robot), Bumpers)
        self._battery = bus.publisher(keys.base_battery(robot), Battery)
        self.bus = bus
        self.contract = DriverContract(bus, robot)
        self.driver = BaseDriver(port, on_state=self._publish_state, on_event=self.contract.event,
                                 baud=baud, params=KNOWN[params] if params else None,
                                 max_vx=max_vx, max_wz=max_wz)
        self._angles: list[float] = []
        self.arm: KatanaArm | None = None
        try:
            if katana:
                self.arm = KatanaArm(bus, robot, katana, self.contract.event, calibrate=calibrate_katana)
        except BaseException:
            self.driver.close()
            raise
        arm = self.arm
        self.contract.serve(
            [command("cmd_vel", self._obey, self.driver.heard), *(arm.commands() if arm else [])],
            on_holder=self._on_holder, on_estop=self._on_estop, status=self._status, reset_fault=self._reset_fault,
            verbs=arm.verbs() if arm else {}, handlers=arm.handlers() if arm else {})
        self.holder = self.contract.holders["base"]
        self.driver.start()
        if arm is not None:
            arm.start()

    @property
    def not_holder(self) -> int:
        return self.contract.not_holder

    # ------------------------------------------------------------ in
    def _obey(self, msg: Twist) -> None:
        self.driver.cmd_vel(msg.vx, msg.wz, msg.controller)

    def _on_holder(self, part: str, holder: str | None) -> None:
        if part == "base":
            self.driver.set_controller(holder)
        elif self.arm is not None:
            self.arm.on_holder(part, holder)

    def _on_estop(self, engaged: bool, reason: str, by: str) -> None:
        self.driver.set_estop(engaged, reason, by)
        if self.arm is not None:
            self.arm.on_estop(engaged, reason, by)

    def _status(self) -> dict:
        """The base's status; with a Katana, its own under "arm"."""
        return {**self.driver.status(), **({"arm": self.arm.status()} if self.arm else {})}

    def _reset_fault(self) -> dict:
        """Both parts' faults; the base's first, so that an arm that cannot be reset leaves the
        base reset (refusals are RpcErrors with the driver's sentence)."""
        done = self.driver.reset_fault()
        return {**done, "arm": self.arm.reset_fault()} if self.arm else done

    # ------------------------------------------------------------ out
    def _publish_state(self, s: BaseState) -> None:
        self._odom.put(Odometry(x=s.x, y=s.y, theta=s.theta, vx=s.vx, wz=s.wz))
        if s.sonar_fresh:
            if len(self._angles) != len(s.sonar_ranges):
                params = self.driver.params
                self._angles = params.sonar_angles() if params else [0.0] * len(s.sonar_ranges)
            self._sonar.put(Sonar(ranges=s.sonar_ranges, angles=self._angles))
        self._bumpers.put(Bumpers(front=s.front_bumpers, rear=s.rear_bumpers))
        self._battery.put(Battery(volts=s.volts))

    # ------------------------------------------------------------ runtime hooks
    def health(self) -> dict:
        st = self.driver.status()
        arm = {f"arm_{k}": v for k, v in self.arm.health().items()} if self.arm else {}
        return {"connected": st["connected"], "mode": st["mode"], "fault": st["fault"], **st["counters"], **arm,
                **self.contract.health()}

    def close(self) -> None:
        self.contract.close()
        self.driver.close()
        if self.arm is not None:
            self.arm.close()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", default=None,
                   help="serial URL: /dev/ttyUSB0 or socket://127.0.0.1:8101 (default $ASIBOT_PIONEER_PORT)")
    p.add_argument("--baud", type=int, default=9600, help="serial baud rate (ARCOS starts at 9600)")
    p.add_argument("--params", choices=sorted(KNOWN), default=None,
                   help="force a parameter set instead of the SYNC2 subclass")
    p.add_argument("--max-vx", type=float, default=DEFAULT_MAX_VX, help="speed limit, m/s (default 0.5); a faster cmd_vel is refused")
    p.add_argument("--katana", default=None,
                   help="the Katana's serial port (pyserial URL, or 'emulated'), served in this process as the "
                        f"robot's arm; default ${KATANA_ENV}; none when empty")
    p.add_argument("--skip-katana-calibration", action="store_true",
                   help="trust the Katana's counters: it was calibrated since it was switched on")
    p.add_argument("--max-wz", type=float, default=DEFAULT_MAX_WZ, help="turn rate limit, rad/s (default 100 deg/s); a faster cmd_vel is refused")


def build(bus: Bus, args: argparse.Namespace) -> BaseDriverService:
    port = args.port or os.environ.get("ASIBOT_PIONEER_PORT")
    if not port:
        raise ValueError("no serial port: pass --port /dev/ttyUSB0 or --port socket://127.0.0.1:8101 "
                         "(or set ASIBOT_PIONEER_PORT)")
    if not (math.isfinite(args.max_vx) and math.isfinite(args.max_wz)):
        raise ValueError("--max-vx and --max-wz must be finite numbers")
    katana = args.katana if args.katana is not None else os.environ.get(KATANA_ENV, "")
    return BaseDriverService(bus, args.robot or DEFAULT_ROBOT, port, baud=args.baud, params=args.params,
                             max_vx=args.max_vx, max_wz=args.max_wz, katana=katana,
                             calibrate_katana=not args.skip_katana_calibration)

"""The Zenoh glue: bus messages to BaseDriver calls, BaseState to bus messages. Nothing else.

The driver contract (cmd_vel from the holder only, the estop, events, `status`,
`reset_fault`, driver_alive) is `asibot.safety.driver_contract`'s.
"""

from __future__ import annotations

import argparse
import logging
import math
import os

from asibot import keys
from asibot.bus import Bus
from asibot.safety.driver_contract import DriverContract, command
from asibot.messages import Battery, Bumpers, Odometry, Sonar, Twist
from asibot.runtime import Service

from asibot.base_driver.driver import DEFAULT_MAX_VX, DEFAULT_MAX_WZ, BaseDriver
from asibot.base_driver.params import KNOWN
from asibot.base_driver.state import BaseState

log = logging.getLogger(__name__)

NAME = "base_driver"
DEFAULT_ROBOT = "pioneer"


class BaseDriverService(Service):
    """Publishes the base side of the driver contract for one robot id."""

    def __init__(self, bus: Bus, robot: str, port: str, *, baud: int = 9600, params: str | None = None,
                 max_vx: float = DEFAULT_MAX_VX, max_wz: float = DEFAULT_MAX_WZ) -> None:
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
        self.contract.serve(
            [command("cmd_vel", self._obey, self.driver.heard)],
            on_holder=lambda part, holder: self.driver.set_controller(holder), on_estop=self.driver.set_estop,
            status=self.driver.status, reset_fault=self._reset_fault)
        self.holder = self.contract.holders["base"]
        self.driver.start()

    @property
    def not_holder(self) -> int:
        return self.contract.not_holder

    # ------------------------------------------------------------ in
    def _obey(self, msg: Twist) -> None:
        self.driver.cmd_vel(msg.vx, msg.wz, msg.controller)

    def _reset_fault(self) -> dict:
        return self.driver.reset_fault()  # refusals are RpcErrors with the driver's sentence

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
        return {"connected": st["connected"], "mode": st["mode"], "fault": st["fault"], **st["counters"],
                **self.contract.health()}

    def close(self) -> None:
        self.contract.close()
        self.driver.close()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", default=None,
                   help="serial URL: /dev/ttyUSB0 or socket://127.0.0.1:8101 (default $ASIBOT_PIONEER_PORT)")
    p.add_argument("--baud", type=int, default=9600, help="serial baud rate (ARCOS starts at 9600)")
    p.add_argument("--params", choices=sorted(KNOWN), default=None,
                   help="force a parameter set instead of the SYNC2 subclass")
    p.add_argument("--max-vx", type=float, default=DEFAULT_MAX_VX, help="speed limit, m/s (default 0.5); a faster cmd_vel is refused")
    p.add_argument("--max-wz", type=float, default=DEFAULT_MAX_WZ, help="turn rate limit, rad/s (default 100 deg/s); a faster cmd_vel is refused")


def build(bus: Bus, args: argparse.Namespace) -> BaseDriverService:
    port = args.port or os.environ.get("ASIBOT_PIONEER_PORT")
    if not port:
        raise ValueError("no serial port: pass --port /dev/ttyUSB0 or --port socket://127.0.0.1:8101 "
                         "(or set ASIBOT_PIONEER_PORT)")
    if not (math.isfinite(args.max_vx) and math.isfinite(args.max_wz)):
        raise ValueError("--max-vx and --max-wz must be finite numbers")
    return BaseDriverService(bus, args.robot or DEFAULT_ROBOT, port, baud=args.baud, params=args.params,
                             max_vx=args.max_vx, max_wz=args.max_wz)

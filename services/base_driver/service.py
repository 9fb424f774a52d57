"""The Zenoh glue: bus messages to BaseDriver calls, BaseState to bus messages. Nothing else.

cmd_vel is obeyed only from the controller that holds the base (asibot.ownership: it
announces itself on `keys.base_controller_alive(robot, id)` and puts its id in every Twist);
the estop state is kept served after its sender exits (asibot.estop).
"""

from __future__ import annotations

import argparse
import logging
import math
import os

from asibot import estop, keys
from asibot.arming import NotReady
from asibot.bus import Bus
from asibot.estop import EStopState
from asibot.events import CommandRefused, EventThrottle, refusal_reason
from asibot.messages import Battery, Bumpers, EStop, Event, Odometry, Sonar, Twist
from asibot.ownership import Holder, NotHolder, holders_status
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
        self._events = bus.publisher(keys.events(robot), Event)
        # Refused commands: one Event a second per reason, the rest counted (issue 10).
        self._refusals = EventThrottle(self._events.put)
        self.bus = bus
        self.driver = BaseDriver(port, on_state=self._publish_state, on_event=self._publish_event,
                                 baud=baud, params=KNOWN[params] if params else None,
                                 max_vx=max_vx, max_wz=max_wz)
        self._angles: list[float] = []
        self.estop = EStopState(bus, robot, self._on_estop, self._release_refused)
        self.holder = Holder(robot, "base", on_change=self.driver.set_controller)
        self.holder.follow(bus)
        self.not_holder = 0
        bus.subscribe(keys.base_cmd_vel(robot), Twist, self._on_cmd_vel, with_key=True,
                      on_reject=self._refuse_command)
        bus.serve(keys.driver_rpc(robot, "status"), self._status)
        bus.serve(keys.driver_rpc(robot, "reset_fault"), self._reset_fault)
        bus.announce(keys.driver_alive(robot))
        self.driver.start()

    # ------------------------------------------------------------ in
    def _on_cmd_vel(self, key: str, msg: Twist) -> None:
        refused = self.holder.refusal(msg)
        if refused is not None:     # not the holder's: noted for re-arming, never obeyed
            self.not_holder += 1
            if isinstance(refused, NotHolder):   # a forged one says nothing of the holder's stream
                self.driver.heard(msg.controller)
            self._refuse_command(key, refused)
            return
        try:
            self.driver.cmd_vel(msg.vx, msg.wz, msg.controller)
        except NotReady as exc:     # a stream from before a recovery
            self._refuse_command(key, exc)
        except ValueError as exc:  # beyond --max-vx/--max-wz, not finite: the driver's sentence
            self.bus.reject(key, exc)
            self._refuse_command(key, exc)

    def _refuse_command(self, key: str, exc: Exception) -> None:
        # Answered with an Event, as the driver contract asks, not only counted; a stream of
        # refusals gives one Event a second per reason, with the count of the others.
        level, code = (exc.level, exc.code) if isinstance(exc, CommandRefused) else ("error", "bad_command")
        self._refusals.event(level, code,
                             f"Base command refused, the base keeps its previous motion: {str(exc).rstrip('.')}.",
                             reason=f"cmd_vel:{refusal_reason(exc)}")

    def _on_estop(self, msg: EStop) -> None:
        self.driver.set_estop(msg.engaged, msg.reason, estop.named(msg))

    def _release_refused(self, msg: EStop, why: str) -> None:
        self._refusals.event("warning", "release_refused", estop.refused_text(msg, why), reason="estop:release")

    def _status(self, request: dict) -> dict:
        return {"robot": self.robot, **holders_status([self.holder]), **self.driver.status()}

    def _reset_fault(self, request: dict) -> dict:
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

    def _publish_event(self, level: str, code: str, text: str) -> None:
        self._events.put(Event(level=level, code=code, text=text))

    # ------------------------------------------------------------ runtime hooks
    def health(self) -> dict:
        st = self.driver.status()
        return {"connected": st["connected"], "mode": st["mode"], "fault": st["fault"], **st["counters"],
                "holder": self.holder.current or "", "not_holder": self.not_holder}

    def close(self) -> None:
        self._refusals.close()
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

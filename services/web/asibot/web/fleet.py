"""What the page shows about every robot on the bus, kept up to date from its messages.

The web server never asks a robot for its state: it listens, like any other service, to the
drivers' and controllers' liveliness, the arm, gripper and Cartesian states, the latched
estop (by the drivers' own rule) and the events, and keeps the newest of each per robot. The page gets a JSON view of
that (`Fleet.view`), in the user's units (m and deg), pushed over its WebSocket.
"""

from __future__ import annotations

import collections
import functools
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from asibot import keys, robots
from asibot.bus import Bus
from asibot.messages import (ArmState, CartState, EStop, Event, GripperState, LaserScan, NavMap, NavPath, NavPose,
                             NavStatus, Odometry)
from asibot.poses import user_point
from asibot.safety.estop import EStopStates
from asibot.web.nav_view import map_json, nav_json

#: Events kept per robot for the page (newest last).
EVENTS_KEPT = 20


#: A gripper this share of its widest opening or more is open; this share or less, closed.
OPEN_SHARE, CLOSED_SHARE = 0.9, 0.1


def gripper_words(gripper: GripperState, widest: float | None) -> str:
    """What the page says the gripper is: "open", "closed, holding something", "closed, empty"
    or "partly open", with the opening in cm (the fingers may stop on a held object anywhere)."""
    cm = f"{gripper.opening * 100:.1f} cm"
    if gripper.holding:
        return f"closed, holding something ({cm})"
    if widest is None:
        return f"open {cm}"
    if gripper.opening >= OPEN_SHARE * widest:
        return f"open ({cm})"
    if gripper.opening <= CLOSED_SHARE * widest:
        return "closed, empty"
    return f"partly open ({cm})"


@dataclass
class RobotView:
    """The newest known state of one robot; None where nothing has come yet."""

    robot_id: str
    driver: bool = False
    controller: bool = False
    arm: ArmState | None = None
    cart: CartState | None = None
    gripper: GripperState | None = None
    odom: Odometry | None = None
    estop: EStop | None = None
    nav_pose: NavPose | None = None
    nav_status: NavStatus | None = None
    nav_path: NavPath | None = None
    nav_map: NavMap | None = None
    scan: LaserScan | None = None
    events: collections.deque = field(default_factory=lambda: collections.deque(maxlen=EVENTS_KEPT))

    def point(self) -> list[float] | None:
        """The arm's current point [x, y, z, rot(y'), rot(z'')] in m and deg."""
        return None if self.cart is None else [round(v, 6) for v in user_point(self.cart.pose)]

    def as_json(self) -> dict[str, Any]:
        try:
            spec = robots.get(self.robot_id)
        except KeyError:
            spec = None
        arm = self.arm
        return {
            "id": self.robot_id,
            "simulated": bool(spec and spec.world),
            "world": spec.world if spec else "",
            "arm": spec.arm if spec else None,
            "has_base": bool(spec and spec.has_base),
            "driver": self.driver,
            "controller": self.controller,
            "estop": {"engaged": bool(self.estop and self.estop.engaged),
                      "reason": self.estop.reason if self.estop else ""},
            "fault": arm.fault if arm else "",
            "mode": arm.mode if arm else "",
            "state": self.cart.state if self.cart else "",
            "joints": None if arm is None else {
                "names": list(arm.names), "deg": [round(math.degrees(v), 3) for v in arm.positions]},
            "point": self.point(),
            "gripper": None if self.gripper is None else {
                "opening": round(self.gripper.opening, 4), "holding": self.gripper.holding,
                "says": gripper_words(self.gripper, spec.gripper_max_opening if spec else None)},
            "base": None if self.odom is None else {
                "x": round(self.odom.x, 3), "y": round(self.odom.y, 3),
                "theta_deg": round(math.degrees(self.odom.theta), 1)},
            "nav": nav_json(self.nav_pose, self.nav_status, self.nav_path, self.scan, self.nav_map),
            "events": list(self.events),
        }


class Fleet:
    """Every robot seen on the bus. `on_change(robot_id)` is called from bus threads whenever
    something about a robot changed; the caller decides how often to push it to the page."""

    def __init__(self, bus: Bus, on_change: Callable[[str], None] = lambda robot_id: None,
                 clock: Callable[[], float] = time.time,
                 on_nav_status: Callable[[str, NavStatus], None] = lambda key, status: None) -> None:
        """`on_nav_status(key, status)` also hears each nav status (the trips counter), so the web
        subscribes to it once."""
        self.bus = bus
        self.on_change = on_change
        self.on_nav_status = on_nav_status
        self.clock = clock
        self._lock = threading.Lock()
        self._robots: dict[str, RobotView] = {}
        for pattern, what in ((keys.ALL_DRIVERS, "driver"), (keys.ALL_CONTROLLERS, "controller")):
            for key in bus.alive(pattern):  # before watch(): see the bus's liveliness notes
                self._alive(what, key, True)
            bus.watch(pattern, functools.partial(self._alive, what))
        self._follow(keys.arm_state, ArmState, "arm")
        self._follow(keys.cart_state, CartState, "cart")
        self._follow(keys.gripper_state, GripperState, "gripper")
        self._follow(keys.base_odom, Odometry, "odom")
        self._follow(keys.nav_pose, NavPose, "nav_pose")
        self._follow(keys.nav_status, NavStatus, "nav_status", also=lambda key, msg: self.on_nav_status(key, msg))
        self._follow(keys.nav_path, NavPath, "nav_path")
        self._follow(keys.scan, LaserScan, "scan")
        bus.subscribe(keys.every_robot(keys.nav_map), NavMap, self._on("nav_map"), with_key=True, latest=True)
        # By the drivers' own rule (asibot.safety.estop), so the page shows the state they hold.
        on_estop = self._on("estop")
        self.estops = EStopStates(bus, lambda robot_id, msg: on_estop(keys.estop(robot_id), msg))
        bus.subscribe(keys.every_robot(keys.events), Event, self._on_event, with_key=True, maxsize=200)

    def _follow(self, key_of_robot: Callable[[str], str], msg_type: type, attr: str,
                also: Callable[[str, Any], None] | None = None) -> None:
        # A ring of one: the page needs the newest state, never a backlog of old ones.
        self.bus.subscribe(keys.every_robot(key_of_robot), msg_type, self._on(attr, also),
                           with_key=True, maxsize=1)

    def _view(self, robot_id: str) -> RobotView:
        view = self._robots.get(robot_id)
        if view is None:
            view = self._robots[robot_id] = RobotView(robot_id)
        return view

    def _alive(self, what: str, key: str, alive: bool) -> None:
        robot_id = keys.robot_of(key)
        if robot_id is None:
            return
        with self._lock:
            setattr(self._view(robot_id), what, alive)
        self.on_change(robot_id)

    def _on(self, attr: str, also: Callable[[str, Any], None] | None = None) -> Callable[[str, Any], None]:
        def store(key: str, msg: Any) -> None:
            robot_id = keys.robot_of(key)
            if robot_id is None:
                return
            with self._lock:
                setattr(self._view(robot_id), attr, msg)
            if also is not None:
                also(key, msg)
            self.on_change(robot_id)
        return store

    def _on_event(self, key: str, event: Event) -> None:
        robot_id = keys.robot_of(key)
        if robot_id is None:
            return
        with self._lock:
            self._view(robot_id).events.append(
                {"time": self.clock(), "level": event.level, "code": event.code, "text": event.text})
        self.on_change(robot_id)

    # --- what the server asks -------------------------------------------------------------
    def ids(self) -> list[str]:
        """Robots with a live driver or controller, sorted: the ones the page can command."""
        with self._lock:
            return sorted(r for r, v in self._robots.items() if v.driver or v.controller)

    def view(self, robot_id: str) -> dict[str, Any]:
        """The page's view of one robot; KeyError when it was never seen."""
        with self._lock:
            return self._robots[robot_id].as_json()

    def views(self) -> list[dict[str, Any]]:
        with self._lock:
            return [v.as_json() for r, v in sorted(self._robots.items()) if v.driver or v.controller]

    def map(self, robot_id: str) -> dict[str, Any] | None:
        """The robot's navigation map for the Base page, or None before nav latched one."""
        with self._lock:
            view = self._robots.get(robot_id)
            return None if view is None or view.nav_map is None else map_json(view.nav_map)

    def point(self, robot_id: str) -> list[float] | None:
        """The robot's current point in m and deg, or None before its first Cartesian state."""
        with self._lock:
            view = self._robots.get(robot_id)
            return None if view is None else view.point()

    def place(self, robot_id: str) -> str:
        """The named place the robot's base stands at (nav arrived there and it has not left), or ""."""
        with self._lock:
            view = self._robots.get(robot_id)
            status = None if view is None else view.nav_status
            return status.place if status is not None and status.state == "succeeded" else ""

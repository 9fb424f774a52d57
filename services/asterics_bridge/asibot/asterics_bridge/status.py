"""What the bridge hears from the robots: user events, nav status, odometry, battery, estop.

`StatusBoard` keeps the latest of each per robot (for `status` and GET /status) and turns
events and estop changes into `Notice`s for the clients that drive that robot: a short phrase
("obstacle ahead", "goal reached", "fault", "estop", "task done") for the NetConnection
port-1 string and speech, the full sentence, and whether it is an alarm (a warning or an error,
an engaged estop), which also fires the port-1 event.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Callable

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.safety.estop import EStopStates

log = logging.getLogger(__name__)

#: Moving means faster than this by odometry (m/s, rad/s).
MOVING_VX, MOVING_WZ = 0.01, 0.02

#: The drivers' events about the estop: told from keys.estop itself (once, whoever engaged it).
ESTOP_CODES = ("estop", "estop_released")

#: Event codes -> phrase. Codes not here use the first clause of their sentence.
PHRASES = {
    "goal_succeeded": "goal reached",
    "goal_aborted": "goal not reached",
    "goal_canceled": "goal canceled",
    "goal_preempted": "goal replaced",
    "drive_done": "done",
    "task_done": "task done",
    "task_failed": "task failed",
    "driver_lost": "fault",
    "disconnected": "fault",
    "controller_lost": "fault",
}


@dataclass(frozen=True)
class Notice:
    robot: str
    phrase: str          # short, for speech and NetConnection port 1
    text: str            # the whole sentence
    level: str = "info"  # info | warning | error
    alarm: bool = False


def phrase_of(event: m.Event) -> str:
    """The short phrase of an event: by its code, "obstacle ahead/behind/..." for any event
    about an obstacle, "fault" for other errors, else its sentence's first clause."""
    if event.code in PHRASES:
        return PHRASES[event.code]
    text = event.text.strip().rstrip(".")
    low = text.lower()
    if "obstacle" in low:
        where = low[low.index("obstacle"):].split(",")[0]
        return where
    if event.level == "error" or "fault" in event.code:
        return "fault"
    return low.split(":")[0].split(",")[0] or event.code


def notice_of(robot: str, event: m.Event) -> Notice:
    return Notice(robot, phrase_of(event), event.text, event.level, event.level in ("warning", "error"))


@dataclass
class RobotStatus:
    nav: m.NavStatus | None = None
    odom: m.Odometry | None = None
    where: m.NavPose | None = None       # nav's pose on the map; the pose people mean
    battery: float | None = None
    estop: bool = False
    last_event: Notice | None = None
    task: str = ""                       # a task started from the bridge and not done yet

    def moving(self) -> bool:
        if self.nav is not None and self.nav.state == "active":
            return True
        o = self.odom
        return o is not None and (abs(o.vx) > MOVING_VX or abs(o.wz) > MOVING_WZ)

    def as_json(self, robot: str) -> dict:
        nav, o = self.nav, self.where or self.odom   # the map pose where nav runs, else odometry's
        return {
            "robot": robot,
            "moving": self.moving(),
            "state": nav.state if nav else "unknown",
            "text": nav.text if nav else "",
            "driving": nav.driving if nav else "",
            "place": nav.place if nav else "",
            "speed": nav.speed if nav else 0,
            "width": nav.width if nav else 0,
            "pose": {"x": round(o.x, 3), "y": round(o.y, 3), "theta": round(math.degrees(o.theta), 1)} if o else None,
            "battery": round(self.battery, 2) if self.battery is not None else None,
            "estop": self.estop,
            "last_event": self.last_event.phrase if self.last_event else "",
            "last_event_text": self.last_event.text if self.last_event else "",
            "task": self.task,
        }


class StatusBoard:
    """Subscribes for every robot; calls `on_notice(notice)` on the bus's threads."""

    def __init__(self, bus: Bus, on_notice: Callable[[Notice], None]) -> None:
        self._lock = threading.Lock()
        self._robots: dict[str, RobotStatus] = {}
        self.on_notice = on_notice
        bus.subscribe(keys.every_robot(keys.events), m.Event, self._on_event, with_key=True, maxsize=200)
        bus.subscribe(keys.every_robot(keys.nav_status), m.NavStatus, self._on_nav, with_key=True, maxsize=50)
        bus.subscribe(keys.every_robot(keys.base_odom), m.Odometry, self._on_odom, with_key=True,
                      maxsize=1)
        bus.subscribe(keys.every_robot(keys.nav_pose), m.NavPose, self._on_pose, with_key=True,
                      maxsize=1)
        bus.subscribe(keys.every_robot(keys.base_battery), m.Battery, self._on_battery, with_key=True,
                      maxsize=1)
        # By the drivers' own rule (asibot.safety.estop): a client hears the state they hold.
        self.estops = EStopStates(bus, self._on_estop)

    def robot(self, robot: str) -> RobotStatus:
        with self._lock:
            return self._robots.setdefault(robot, RobotStatus())

    def json(self, robot: str) -> dict:
        with self._lock:
            return self._robots.setdefault(robot, RobotStatus()).as_json(robot)

    def _update(self, key: str, **values: object) -> tuple[str, RobotStatus] | None:
        robot = keys.robot_of(key)
        if robot is None:
            return None
        with self._lock:
            st = self._robots.setdefault(robot, RobotStatus())
            for name, value in values.items():
                setattr(st, name, value)
        return robot, st

    def _on_event(self, key: str, event: m.Event) -> None:
        robot = keys.robot_of(key)
        if robot is None or event.code in ESTOP_CODES:
            return
        notice = notice_of(robot, event)
        if event.code.startswith("task_"):
            self._update(key, task="")
        self._update(key, last_event=notice)
        self.on_notice(notice)

    def _on_nav(self, key: str, status: m.NavStatus) -> None:
        self._update(key, nav=status)

    def _on_odom(self, key: str, odom: m.Odometry) -> None:
        self._update(key, odom=odom)

    def _on_pose(self, key: str, pose: m.NavPose) -> None:
        self._update(key, where=pose)

    def _on_battery(self, key: str, battery: m.Battery) -> None:
        self._update(key, battery=battery.volts)

    def _on_estop(self, robot: str, estop: m.EStop) -> None:
        key = keys.estop(robot)
        self._update(key, estop=estop.engaged)
        why = f" ({estop.reason})" if estop.reason else ""
        if estop.engaged:
            notice = Notice(robot, "estop", f"Emergency stop engaged{why}.", "error", True)
        else:
            notice = Notice(robot, "estop released", f"Emergency stop released{why}.", "info", False)
        self._update(key, last_event=notice)
        self.on_notice(notice)

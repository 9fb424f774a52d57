"""What every mobile base's driver does the same way around its motion, written once.

A base driver (the Pioneer's over ARCOS, the sim's MuJoCo base) has its own way of sending a
velocity and of stopping; the rest is the same for every base beside a person, as
`guarded_arm` is for arms:

- a velocity is checked whole before anything changes: not finite, or beyond the base's
  limits (more than SPEED_TOLERANCE over), it is refused with a CommandRefused, never clamped
  and obeyed; the base keeps its previous command, which the watchdog ends a period later;
- under the emergency stop every velocity is ignored, never queued; engaging stops the base
  at once (`_halt`), and once released only a new stream of commands moves it
  (asibot.safety.arming), as after a change of the controller that holds it;
- a change of that controller stops a moving base;
- the command watchdog stops a stream that went quiet (`watch`, once a cycle).

Each of these tells the user through `on_event(level, code, text)` in the same words for every
base. A subclass gives `_drive` (send a checked velocity), `_halt` (the emergency stop) and
`_moving` (whether it was last told to move), and says whose limits they are.
"""

from __future__ import annotations

import abc
import math
import threading
import time
from typing import Callable

from asibot.messages import COMMAND_WATCHDOG_S
from asibot.safety.arming import Arming
from asibot.safety.events import CommandRefused, estop_said, quantity
from asibot.safety.watchdog import Watchdog

EventSink = Callable[[str, str, str], None]      # level, code, text
#: A velocity this fraction over a limit is numerical noise: clamped to the limit, not refused.
SPEED_TOLERANCE = 1e-3


class GuardedBase(abc.ABC):
    """The safety around a mobile base's velocity commands (see the module). Not a driver by itself."""

    limits = "the base's"
    """Whose limits a refusal names: "vx 0.8 m/s is beyond the P3-AT's max speed 0.5 m/s"."""
    hints = {"vx": "", "wz": ""}
    """What follows a limit in a refusal, per axis: " (--max-vx)" names the option that sets it."""

    def __init__(self, max_vx: float, max_wz: float, on_event: EventSink, *,
                 watchdog: float = COMMAND_WATCHDOG_S, clock: Callable[[], float] = time.monotonic) -> None:
        if not (max_vx > 0 and max_wz > 0 and math.isfinite(max_vx) and math.isfinite(max_wz)):
            raise ValueError("max_vx and max_wz must be positive, finite limits (m/s, rad/s)")
        self.max_vx, self.max_wz = max_vx, max_wz
        self.on_event = on_event
        self.clock = clock
        self._lock = threading.RLock()
        self.estop = False
        self.arming = Arming()             # a driver starts armed (asibot.safety.arming says why)
        self.watchdog = Watchdog(watchdog)
        self.counters = {"cmd_vel": 0, "ignored_estop": 0, "refused": 0, "not_ready": 0, "watchdog_stops": 0}

    # ------------------------------------------------------------ what a driver gives
    @abc.abstractmethod
    def _drive(self, vx: float, wz: float) -> bool:
        """Send a checked velocity (m/s, rad/s), (0, 0) to stop as the base brakes; whether it
        was sent (under the lock)."""

    @abc.abstractmethod
    def _halt(self) -> None:
        """The emergency stop: stop now, the hardest way the base has (under the lock)."""

    @abc.abstractmethod
    def _moving(self) -> bool:
        """Whether the base was last told to move: a velocity other than (0, 0) (under the lock)."""

    # ------------------------------------------------------------ inputs (any thread)
    def check(self, vx: float, wz: float) -> None:
        """CommandRefused when vx or wz is not finite or beyond the base's limits."""
        for name, v in (("vx", vx), ("wz", wz)):
            if not math.isfinite(v):
                raise CommandRefused("not_finite", f"{name} is {quantity(v)}, not a finite number")
        for name, v, limit, unit, what in (("vx", vx, self.max_vx, "m/s", "max speed"),
                                           ("wz", wz, self.max_wz, "rad/s", "max turn rate")):
            if abs(v) > limit * (1.0 + SPEED_TOLERANCE):
                raise CommandRefused("speed_limit", f"{name} {quantity(v, unit, limit)} is beyond {self.limits} "
                                                    f"{what} {quantity(limit, unit, abs(v))}{self.hints[name]}")

    def command(self, vx: float, wz: float, controller: str = "", now: float | None = None) -> bool:
        """Obey a velocity (m/s, rad/s) of `controller` (the holder: the service checked).
        Returns False when it is ignored (the estop; a base that cannot be reached).

        Raises CommandRefused, and changes nothing, for a velocity that `check` refuses; and
        arming's NotReady when it continues a stream from before the last recovery."""
        try:
            self.check(vx, wz)
        except CommandRefused:
            with self._lock:
                self.counters["refused"] += 1
            raise
        with self._lock:
            self.counters["cmd_vel"] += 1
            now = self.clock() if now is None else now
            may_move = self.arming.admit(controller, now)     # noted even when ignored below
            if self.estop:
                self.counters["ignored_estop"] += 1
                return False
            if not may_move:
                self.counters["not_ready"] += 1
                raise self.arming.refusal("the base")
            self.watchdog.feed(now)
            # Only the tolerated noise is clamped here.
            return self._drive(max(-self.max_vx, min(self.max_vx, vx)), max(-self.max_wz, min(self.max_wz, wz)))

    def heard(self, controller: str) -> None:
        """A command of a controller that does not hold the base (refused by the service):
        noted, so that its stream does not move the base the moment it takes over."""
        with self._lock:
            self.arming.heard(controller, self.clock())

    def latch(self, engaged: bool) -> bool:
        """Engage the emergency stop (the base stops at once and ignores every command) or
        release it (only a new stream moves it then), without a word; whether it changed.
        `set_estop` says it; a driver that speaks for a whole robot (the sim) says it itself."""
        with self._lock:
            if engaged == self.estop:
                return False
            self.estop = engaged
            if engaged:
                self._halt()
            else:
                self.arming.disarm("the emergency stop was released")
            return True

    def set_estop(self, engaged: bool, reason: str = "", by: str = "") -> None:
        """The latched emergency stop (`latch`), told to the user."""
        with self._lock:
            if not self.latch(engaged):
                return
            self.on_event(*estop_said(engaged, reason, by, "the base is stopped and ignores motion commands until "
                                                            "the stop is released"))
            if not engaged:
                self.recovered("the emergency stop was released" + (f" by {by}" if by else ""))

    def set_controller(self, holder: str | None) -> None:
        """The controller that holds the base changed (asibot.safety.ownership): stop the base if
        it was moving, and arm again for the new holder, if any."""
        with self._lock:
            if self._moving():
                self._drive(0.0, 0.0)
                self.on_event("warning", "controller_lost", "The controller of the base changed or disappeared "
                                                            "while the base was moving: the base stopped.")
            if holder is None:
                self.arming.disarm("its controller disappeared")
            else:
                self.recovered(f"controller {holder!r} took hold of it")

    def recovered(self, why: str) -> None:
        """After a recovery (a release, a new controller, a reconnect, a motor reset) only a new
        stream moves the base; say it is ready."""
        with self._lock:
            self.arming.disarm(why)
            self.on_event("info", "ready", self.arming.ready_text("The base"))

    # ------------------------------------------------------------ for the driver
    def watch(self, now: float | None = None) -> bool:
        """The command watchdog, once a cycle on the control thread: a stream that went quiet
        while the base moves stops it, as it brakes; whether it fired."""
        with self._lock:
            fired = self.watchdog.fires(self.clock() if now is None else now, self._moving())
            if fired:
                self.counters["watchdog_stops"] += 1
                self._drive(0.0, 0.0)
        if fired:
            self.on_event("warning", "watchdog", self.watchdog.says("drive command", "the base stopped"))
        return fired

"""User-facing notices from the stream of base states: edges of stall, bumper, estop-button,
motor and battery flags become one Event each, not one per SIP.

Battery thresholds are p2os's diagnostics (docs/arcos.md "P3-AT parameters": WARN below
11.75 V, ERROR below 11.0 V), with a 0.2 V hysteresis so a sagging battery under load does
not chatter.
"""

from __future__ import annotations

from typing import Callable

from asibot.base_driver.params import BATTERY_ERROR_V, BATTERY_WARN_V
from asibot.base_driver.state import BaseState

BATTERY_HYSTERESIS = 0.2

EventSink = Callable[[str, str, str], None]   # level, code, text


class Notices:
    """Feed every BaseState; emits events on the rising edges that matter to the user."""

    def __init__(self, emit: EventSink) -> None:
        self._emit = emit
        self._prev: BaseState | None = None
        self.battery_level = "ok"       # ok | low | critical

    def reset(self) -> None:
        """Forget the previous state (after a reconnect): the next state sets the baseline."""
        self._prev = None

    def update(self, s: BaseState) -> None:
        p, self._prev = self._prev, s
        if p is not None:
            for side, now, before in (("left", s.stall_left, p.stall_left), ("right", s.stall_right, p.stall_right)):
                if now and not before:
                    self._emit("warning", "stall", f"The {side} wheel stalled and its motor power was cut; "
                                                   "clear the obstacle, then reset the fault.")
            for where, now_b, before_b in (("front", s.front_bumpers, p.front_bumpers),
                                           ("rear", s.rear_bumpers, p.rear_bumpers)):
                if any(now_b) and not any(before_b):
                    self._emit("warning", "bumper", f"The {where} bumper hit an obstacle.")
            if s.estop_pressed and not p.estop_pressed:
                self._emit("error", "estop_button", "The Pioneer's own emergency stop button was pressed.")
            if p.motors_enabled and not s.motors_enabled:
                self._emit("warning", "motors_disabled",
                           "The Pioneer's motors were disabled; reset the fault to enable them.")
        self._battery(s.volts)

    def _battery(self, volts: float) -> None:
        if volts <= 0:
            return      # no reading
        level = self.battery_level
        if volts < BATTERY_ERROR_V:
            new = "critical"
        elif volts < BATTERY_WARN_V:
            new = "low" if level == "ok" or volts >= BATTERY_ERROR_V + BATTERY_HYSTERESIS else level
        elif volts >= BATTERY_WARN_V + BATTERY_HYSTERESIS:
            new = "ok"
        else:
            new = level
        if new == level:
            return
        self.battery_level = new
        if new == "critical":
            self._emit("error", "battery_critical",
                       f"Battery at {volts:.1f} V: the controller shuts down near 11 V; charge now.")
        elif new == "low" and level == "ok":
            self._emit("warning", "battery_low",
                       f"Battery low ({volts:.1f} V, below {BATTERY_WARN_V} V); drive to the charger soon.")
        elif new == "ok":
            self._emit("info", "battery_ok", f"Battery back at {volts:.1f} V.")

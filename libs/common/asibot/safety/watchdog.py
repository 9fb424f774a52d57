"""The command watchdog: a robot moved by a stream of commands stops when the stream stops.

Every part of the stack that obeys a stream (the arm driver and the base driver, the sim's
arm and base, the kinematics service's streamed motions) keeps one `Watchdog` and asks it
each cycle; the period is the driver contract's, `messages.COMMAND_WATCHDOG_S` (200 ms),
and the sentences say it in the same words.
"""

from __future__ import annotations

import math

from asibot.messages import COMMAND_WATCHDOG_S


class Watchdog:
    """Fires once when no command came for `period` seconds while the stream still moves
    something; a new command feeds it and makes it ready to fire again. Not thread-safe by
    itself: its owner calls it under its own lock, with its own clock."""

    def __init__(self, period: float = COMMAND_WATCHDOG_S) -> None:
        if not period > 0:
            raise ValueError("the watchdog period must be a positive number of seconds")
        self.period = period
        self.last = -math.inf     # when the last command came
        self.fired = False

    def feed(self, now: float) -> None:
        """A command came at `now`."""
        self.last = now
        self.fired = False

    def silent(self, now: float) -> bool:
        """Whether no command came for longer than the period."""
        return now - self.last > self.period

    def fires(self, now: float, moving: bool = True) -> bool:
        """True once per silence: the stream went quiet for the period while `moving`."""
        if self.fired or not moving or not self.silent(now):
            return False
        self.fired = True
        return True

    def says(self, what: str, then: str) -> str:
        """The sentence of a stop: says("velocity command", "the arm stopped") ->
        "No velocity command for 200 ms: the arm stopped."."""
        return f"No {what} for {self.period * 1000:.0f} ms: {then}."

"""Re-arming: after a recovery, a robot moves only on a motion request made after it.

A fault reset, an estop release, a serial line coming back, a new controller holding the
robot: each ends an interruption during which the robot stood still. A stream of commands
that went on through it (a velocity stream, a held jog button, a program looping over its
errors) must not carry on as if nothing had happened: the arm moved 175 mm by itself after a
restarted kinematics service accepted a stream that was still arriving, the base 4.5 s after
an unplug (issue 10, finding 4). So a recovery disarms the part, and the first command of a
stream that began after it arms it again: a command from a sender that sent nothing during
one watchdog period (`messages.COMMAND_WATCHDOG_S`) before it. A stream that keeps arriving
must pause for a watchdog period, or be restarted, before it moves anything.

Every command passes through `admit`, even one ignored or refused for another reason (the
estop, a fault, a line down, a sender that does not hold the robot: `heard`), so a stream
that went on during the interruption is known for what it is. What `Arming` knows begins
with `since`: a sender first heard within a watchdog period of it may have been sending
before, and counts as a running stream (a restarted controller under a stream of requests).
A driver starts armed, knowing nothing before it (`since=None`): a controller may begin a
motion just as it comes up, and the controller re-arms its own streams.

Not thread-safe by itself: its owner calls it under its own lock, with its own clock.
"""

from __future__ import annotations

import math

from asibot.safety.events import CommandRefused
from asibot.messages import COMMAND_WATCHDOG_S

#: Senders remembered at most; older ones are forgotten (a forgotten sender's next command
#: begins a stream, as it would anyway after a watchdog period of silence).
MAX_SENDERS = 64


class NotReady(CommandRefused):
    """A command that continues a stream from before the last recovery: ignored, nothing moves."""

    code = "not_ready"
    level = "warning"


class Arming:
    """Whether a part of a robot may move on a sender's command, after the last recovery."""

    def __init__(self, since: float | None = None, watchdog: float = COMMAND_WATCHDOG_S) -> None:
        self.watchdog = watchdog
        self._since = -math.inf if since is None else since
        self._last: dict[str, float] = {}
        self.armed = since is None
        self.why = "its start"

    def disarm(self, why: str) -> None:
        """A recovery (`why`: "the emergency stop was released"): from now on only a new
        stream moves the part."""
        self.armed = False
        self.why = why

    def heard(self, sender: str, now: float) -> bool:
        """Note a command of `sender` at `now`; True when it begins a stream (nothing from
        the sender during the watchdog period before it)."""
        previous = self._last.get(sender, self._since)
        if len(self._last) >= MAX_SENDERS and sender not in self._last:
            self._forget(now)
        self._last[sender] = now
        return now - previous >= self.watchdog

    def admit(self, sender: str, now: float) -> bool:
        """Note a command of `sender` at `now`; whether it may move the part: armed, or the
        first command of a stream that began after the recovery (which arms the part)."""
        if self.heard(sender, now) and not self.armed:
            self.armed = True
        return self.armed

    def refusal(self, what: str) -> NotReady:
        """The sentence for a command `admit` did not let through; `what`: "the arm"."""
        ms = f"{self.watchdog * 1000:.0f} ms"
        return NotReady("not_ready", f"{what} was re-armed after {self.why}, and this command continues a "
                                     f"stream that was running before; pause it for {ms} (or restart it) "
                                     f"to move {what} again")

    def ready_text(self, what: str) -> str:
        """The Event after a recovery; `what`: "The arm"."""
        return (f"{what} is ready again after {self.why}: it moves on the next motion request; a stream "
                f"of commands still running from before must pause for {self.watchdog * 1000:.0f} ms first.")

    def _forget(self, now: float) -> None:
        for sender, t in list(self._last.items()):
            if now - t >= self.watchdog:
                del self._last[sender]
        while len(self._last) >= MAX_SENDERS:  # all recent: drop the oldest, it counts as new
            del self._last[min(self._last, key=self._last.__getitem__)]

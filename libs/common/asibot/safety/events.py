"""Events about refused input, rate-limited: what the drivers and the sim share.

A driver answers every refused command with an error Event (`rb/<robot>/events`), so a
user learns why the robot did not move. A program that sends a stream of bad commands (a
bug, a fuzzer, a replay) must not turn that into a stream of events: `EventThrottle` lets
the first event of a reason out at once, counts the ones that follow within the period and,
when the period ends, sends the newest of them with the count ("... (37 more refused
commands in the last second)."). A quiet period ends the burst. Each driver has one
throttle per robot, and reasons are the driver's own short keys ("arm:position_limit",
"cmd_vel:speed_limit" ...), so a different mistake is still reported at once.

`quantity(value, unit, near)` writes a number short in such sentences ("1e+300 rad"), with
enough digits to tell it from `near` (a value just past its limit).
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from dataclasses import dataclass
from typing import Callable

from asibot.errors import MessageError
from asibot.messages import Event

log = logging.getLogger(__name__)


class CommandRefused(ValueError):
    """A command the robot must not obey: a value beyond a limit or not finite (refused whole,
    never clipped), or a sender that does not hold the robot (asibot.safety.ownership), or a stream
    from before a recovery (asibot.safety.arming). `reason` is a short key for rate-limiting the
    refusals ("position_limit", "speed_limit", "not_finite", "not_holder", "not_ready");
    `code` and `level` are those of the Event that says so."""

    code = "bad_command"
    level = "error"

    def __init__(self, reason: str, sentence: str) -> None:
        super().__init__(sentence)
        self.reason = reason


def estop_said(engaged: bool, reason: str, by: str, meanwhile: str) -> tuple[str, str, str]:
    """The Event (level, code, text) of an emergency stop engaged or released, in the same words
    for every driver: "Emergency stop engaged by <who> (<reason>): <meanwhile>." `by` and
    `reason` may be empty; `meanwhile` says what the robot does until the release ("the arm
    holds its position and ignores motion commands until it is released")."""
    who = f" by {by}" if by else ""
    because = f" ({reason})" if reason else ""
    if engaged:
        return "warning", "estop", f"Emergency stop engaged{who}{because}: {meanwhile}."
    return "info", "estop_released", f"Emergency stop released{who}{because}."


def refusal_reason(exc: Exception) -> str:
    """The rate-limiting key of a refused command: a CommandRefused's own, or what the message
    decoder found ("not_finite", "malformed")."""
    if isinstance(exc, CommandRefused):
        return exc.reason
    if isinstance(exc, MessageError) and "not finite" in exc.problem:
        return "not_finite"
    return "malformed"


@dataclass
class _Burst:
    started: float            # when the period that is running began
    held: int = 0             # events held back in it
    newest: Event | None = None
    timer: threading.Timer | None = None


_HELD = re.compile(r"\((\d+) more [^()]+ in the last [^()]+\)\.$")


def stands_for(text: str) -> int:
    """How many events one throttled event's text stands for: itself, plus the count it carries."""
    held = _HELD.search(text)
    return 1 + (int(held.group(1)) if held else 0)


class EventThrottle:
    """At most one event per `period` and reason; the events held back are counted.

    `put(event)` publishes (a Publisher's put). Thread-safe; the summary at the end of a
    period is sent by a timer thread, so a burst that stops is still reported whole.
    """

    def __init__(self, put: Callable[[Event], None], period: float = 1.0, *,
                 what: str = "refused commands", clock: Callable[[], float] = time.monotonic) -> None:
        if not period > 0:
            raise ValueError("period must be a positive number of seconds")
        self._put = put
        self.period = period
        self.what = what
        self._clock = clock
        self._lock = threading.Lock()
        self._bursts: dict[str, _Burst] = {}
        self._closed = False
        self.sent = 0
        self.held = 0

    def event(self, level: str, code: str, text: str, reason: str | None = None) -> bool:
        """Publish Event(level, code, text) now, or count it; True when it went out now."""
        key = reason or code
        now = self._clock()
        with self._lock:
            if self._closed:
                return False
            burst = self._bursts.get(key)
            if burst is None or (now - burst.started >= self.period and burst.held == 0):
                if len(self._bursts) > 256:  # reasons are a handful; never grow without bound
                    self._drop_quiet(now)
                self._bursts[key] = _Burst(started=now)
                self.sent += 1
                send = True
            else:
                burst.held += 1
                burst.newest = Event(level=level, code=code, text=text)
                self.held += 1
                if burst.timer is None:
                    burst.timer = threading.Timer(max(burst.started + self.period - now, 0.0),
                                                  self._end_period, args=(key,))
                    burst.timer.daemon = True
                    burst.timer.start()
                send = False
        if send:
            self._put(Event(level=level, code=code, text=text))
        return send

    def flush(self) -> None:
        """Send every held-back summary now, instead of at the end of its period."""
        for key in list(self._bursts):
            self._end_period(key, cancel=True)

    def close(self) -> None:
        """Stop the timers; events held back and not yet summarised are dropped."""
        with self._lock:
            self._closed = True
            for burst in self._bursts.values():
                if burst.timer is not None:
                    burst.timer.cancel()

    # ------------------------------------------------------------ internals
    def _end_period(self, key: str, cancel: bool = False) -> None:
        with self._lock:
            burst = self._bursts.get(key)
            if burst is None or self._closed:
                return
            if cancel and burst.timer is not None:
                burst.timer.cancel()
            burst.timer = None
            held, newest = burst.held, burst.newest
            if held == 0 or newest is None:
                return
            # The summary opens a new period: a stream that goes on gives one event a period.
            self._bursts[key] = _Burst(started=self._clock())
            self.sent += 1
        text = newest.text
        if held > 1:
            span = "the last second" if self.period == 1.0 else f"the last {self.period:g} s"
            what = self.what if held > 2 or not self.what.endswith("s") else self.what[:-1]
            text = f"{text.rstrip('.')} ({held - 1} more {what} in {span})."
        try:
            self._put(Event(level=newest.level, code=newest.code, text=text))
        except Exception:  # closing bus: the summary is lost, the service goes on
            log.warning("could not publish a summary of %d held-back events", held, exc_info=True)

    def _drop_quiet(self, now: float) -> None:
        for key, burst in list(self._bursts.items()):
            if burst.timer is None and now - burst.started >= self.period:
                del self._bursts[key]


def quantity(value: float, unit: str = "", near: float | None = None) -> str:
    """A number for a sentence: 3 significant digits ("1e+300 rad", "2.5 m/s", "nan"), more
    when needed to tell it from `near`, so "2.8911 rad beyond 2.891 rad" never reads as
    "2.89 beyond 2.89"."""
    suffix = f" {unit}" if unit else ""
    if not math.isfinite(value):
        return f"{value}{suffix}"
    digits = 3
    if near is not None and math.isfinite(near) and value != near:
        while digits < 12 and f"{value:.{digits}g}" == f"{near:.{digits}g}":
            digits += 1
    return f"{value:.{digits}g}{suffix}"

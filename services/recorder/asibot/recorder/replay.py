"""Republish a recording on the bus, with its original timing, scaled, or as fast as possible.

A recording holds commands (arm/command, cmd_vel, estop, RPCs). Replayed into a stack whose
drivers are alive, they would move real or simulated robots that nobody expects to move, so
`LiveGuard` keeps them off the bus while any driver is alive, unless the user says otherwise.
"""

from __future__ import annotations

import fnmatch
import threading
import time
from pathlib import Path
from typing import Callable

from asibot import keys
from asibot.recorder.reader import iter_messages

# Presence and health belong to the live system, not to the replayed one.
DEFAULT_EXCLUDE = (keys.ALL_HEALTH,)


def _excluded(key: str, patterns: tuple[str, ...] | list[str]) -> bool:
    return any(fnmatch.fnmatchcase(key, p.replace("**", "*")) for p in patterns)


class LiveGuard:
    """Knows which drivers are alive (from their liveliness tokens) and holds back commands
    while any is; `held` counts what it kept off the bus."""

    def __init__(self) -> None:
        self.drivers: set[str] = set()
        self.held = 0
        self._lock = threading.Lock()

    def on_driver(self, key: str, alive: bool) -> None:
        with self._lock:
            (self.drivers.add if alive else self.drivers.discard)(keys.robot_of(key) or key)

    def allows(self, key: str) -> bool:
        with self._lock:
            if self.drivers and keys.is_command(key):
                self.held += 1
                return False
            return True


def replay(path: Path | str, put: Callable[[str, bytes], None], *, speed: float | None = 1.0,
           exclude: tuple[str, ...] | list[str] = DEFAULT_EXCLUDE,
           only: tuple[str, ...] | list[str] = (),
           stop: threading.Event | None = None,
           allows: Callable[[str], bool] | None = None) -> int:
    """Call put(key, payload) for each recorded message; returns the number sent.

    speed=1.0 keeps the recorded timing, 2.0 plays twice as fast, None as fast as possible.
    Timing is scheduled against absolute deadlines so it does not drift over long files.
    `allows(key)` is asked just before each message is sent (a `LiveGuard`).
    """
    if speed is not None and not speed > 0:
        raise ValueError("speed must be positive (or None for as fast as possible)")
    stop = stop or threading.Event()
    t0_rec: int | None = None
    t0_wall = 0.0
    sent = 0
    for rec in iter_messages(path):
        if stop.is_set():
            break
        if exclude and _excluded(rec.key, exclude):
            continue
        if only and not _excluded(rec.key, only):
            continue
        if speed is not None:
            if t0_rec is None:
                t0_rec, t0_wall = rec.log_time, time.monotonic()
            due = t0_wall + (rec.log_time - t0_rec) / 1e9 / speed
            delay = due - time.monotonic()
            if delay > 0 and stop.wait(delay):
                break
        if allows is not None and not allows(rec.key):
            continue
        put(rec.key, rec.payload)
        sent += 1
    return sent

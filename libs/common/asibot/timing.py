"""Periodic loops that do not drift, and know how late they were."""

from __future__ import annotations

import threading
import time

import numpy as np


class Ticker:
    """Wake up every 1/rate_hz seconds on an absolute schedule.

    Sleeping `period` after each iteration drifts by the work time; scheduling against
    absolute deadlines does not. A missed deadline is skipped rather than bunched, so an
    overrun does not produce a burst of back-to-back ticks.
    """

    def __init__(self, rate_hz: float, stop: threading.Event | None = None, keep: int = 10000) -> None:
        if not rate_hz > 0:
            raise ValueError("rate_hz must be positive")
        self.period = 1.0 / rate_hz
        self._stop = stop or threading.Event()
        self._next = time.monotonic() + self.period
        self._last: float | None = None
        self._periods: list[float] = []
        self._keep = keep
        self.overruns = 0

    def wait(self) -> bool:
        """Sleep until the next tick; False once stopped."""
        now = time.monotonic()
        delay = self._next - now
        if delay > 0:
            # No busy spin: on a 2-core machine the CPU belongs to the simulation.
            if self._stop.wait(delay):
                return False
        else:
            self.overruns += 1
            missed = int(-delay / self.period)
            self._next += missed * self.period
        if self._stop.is_set():
            return False
        t = time.monotonic()
        if self._last is not None:
            self._periods.append(t - self._last)
            if len(self._periods) > self._keep:
                del self._periods[: len(self._periods) - self._keep]
        self._last = t
        self._next += self.period
        return True

    def __iter__(self):
        while self.wait():
            yield time.monotonic()

    def stop(self) -> None:
        self._stop.set()

    def stats(self) -> dict:
        """Period jitter |actual - nominal| in seconds: p50, p99, max; and overruns."""
        if not self._periods:
            return {"n": 0, "p50": 0.0, "p99": 0.0, "max": 0.0, "overruns": self.overruns}
        jitter = np.abs(np.asarray(self._periods) - self.period)
        return {
            "n": len(jitter),
            "p50": float(np.percentile(jitter, 50)),
            "p99": float(np.percentile(jitter, 99)),
            "max": float(jitter.max()),
            "overruns": self.overruns,
        }

"""The set-point stream: what position each drive is told to be at, one control period at a time.

In cyclic synchronous position the drive follows whatever it is sent, so the master owns the
limits: every step is clamped to the joint's max speed and position limits (the kinematics
service checked them too; the driver checks again). Pure and clocked by the caller.
"""

from __future__ import annotations

import math

from asibot.messages import COMMAND_WATCHDOG_S

FEED_FORWARD_HORIZON_S = 0.1


class JointReference:
    """Per-joint set-points (rad) for position or velocity commands."""

    def __init__(self, lower: list[float], upper: list[float], max_velocity: list[float], period: float) -> None:
        if not (len(lower) == len(upper) == len(max_velocity)):
            raise ValueError("lower, upper and max_velocity must have one value per joint")
        self.lower, self.upper, self.vmax = list(lower), list(upper), list(max_velocity)
        self.period = period
        self.n = len(lower)
        self.target = [0.0] * self.n
        self.rate = [0.0] * self.n          # rad/s of the set-point itself
        self.mode = "idle"
        self._goal = [0.0] * self.n
        self._feed_forward = [0.0] * self.n
        self._velocity = [0.0] * self.n
        self._since = 0.0

    def reset(self, positions: list[float]) -> None:
        """Start from where the joints are, standing still."""
        self._check(positions)
        self.target = list(positions)
        self.hold()
        self.mode = "idle"

    def hold(self) -> None:
        """Stop where the set-point is now (velocity 0, hold position)."""
        self._goal = list(self.target)
        self._feed_forward = [0.0] * self.n
        self._velocity = [0.0] * self.n
        self.rate = [0.0] * self.n

    @property
    def moving(self) -> bool:
        return any(abs(r) > 1e-9 for r in self.rate) or any(
            abs(g - t) > 1e-9 for g, t in zip(self._goal, self.target)) or any(v != 0.0 for v in self._velocity)

    def position(self, values: list[float], feed_forward: list[float] | None, now: float) -> None:
        self._check(values)
        ff = list(feed_forward) if feed_forward else [0.0] * self.n
        self._check(ff)
        self._goal = [min(max(v, lo), hi) for v, lo, hi in zip(values, self.lower, self.upper)]
        self._feed_forward = [max(-m, min(m, f)) for f, m in zip(ff, self.vmax)]
        self._velocity = [0.0] * self.n
        self._since = now
        self.mode = "position"

    def velocity(self, values: list[float], now: float) -> None:
        self._check(values)
        self._velocity = [max(-m, min(m, v)) for v, m in zip(values, self.vmax)]
        self._feed_forward = [0.0] * self.n
        self._since = now
        self.mode = "velocity"

    def watchdog_expired(self, now: float) -> bool:
        """True once a velocity command is older than 200 ms while it still moves the arm."""
        return self.mode == "velocity" and any(self._velocity) and now - self._since > COMMAND_WATCHDOG_S

    def step(self, now: float) -> list[float]:
        """Advance one period; returns the new set-points (rad)."""
        dt = self.period
        new = []
        for i in range(self.n):
            t, lo, hi, vmax = self.target[i], self.lower[i], self.upper[i], self.vmax[i]
            if self.mode == "velocity":
                want = t + self._velocity[i] * dt
            else:
                ahead = min(max(now - self._since, 0.0), FEED_FORWARD_HORIZON_S)
                want = self._goal[i] + self._feed_forward[i] * ahead
            step = max(-vmax * dt, min(vmax * dt, want - t))
            # Never leave the limits; a joint found outside may only move back towards them.
            value = min(max(t + step, min(lo, t)), max(hi, t))
            new.append(value)
        self.rate = [(a - b) / dt for a, b in zip(new, self.target)]
        self.target = new
        return list(new)

    def _check(self, values: list[float]) -> None:
        if len(values) != self.n:
            raise ValueError(f"expected {self.n} joint values, got {len(values)}")
        if not all(math.isfinite(v) for v in values):
            raise ValueError("joint values must be finite numbers")

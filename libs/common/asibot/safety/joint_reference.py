"""The set-point stream: what position each drive is told to be at, one control period at a time.

In cyclic synchronous position the drive follows whatever it is sent, so the master owns the
limits, twice. A command with a value beyond a joint's limits or max speed, or not finite, is
refused whole (CommandRefused, nothing changes: the arm keeps its previous motion); it is
never clipped and obeyed. Then, as a second line of defence, every step of the set-point is
clamped to the joint's max speed and position limits. Pure and clocked by the caller.

Tolerances, for numerical noise only (values within them are clamped, not refused):
- positions: POSITION_TOLERANCE_RAD past a limit. The kinematics planner keeps its paths
  within 1e-9 rad of the limits, and a hold at a measured position is off by at most half an
  encoder count (4.8 urad on the ASIBOT's 104 306 counts/rad), so 1e-4 rad (0.006 deg, ten
  counts) covers both with margin and still refuses anything a person could see. Besides, a
  position is never further out than where the joint already is: a joint found outside its
  limits (switched on there, or a servo overshooting a limit by a few mrad as it arrives) may
  be told to stay or to come back, never to go further out.
- speeds (velocity mode and the position mode's feed-forward): VELOCITY_TOLERANCE of the max
  speed (0.1 %); the planner's feed-forward is within about 1e-6 of it at the peak.
"""

from __future__ import annotations

import math
from typing import Protocol

from asibot.safety.events import CommandRefused, quantity
from asibot.safety.watchdog import Watchdog

FEED_FORWARD_HORIZON_S = 0.1
POSITION_TOLERANCE_RAD = 1e-4
VELOCITY_TOLERANCE = 1e-3
GRIPPER_TOLERANCE_M = 1e-6


class JointReference:
    """Per-joint set-points (rad) for position or velocity commands."""

    def __init__(self, lower: list[float], upper: list[float], max_velocity: list[float], period: float,
                 names: list[str] | None = None) -> None:
        if not (len(lower) == len(upper) == len(max_velocity)):
            raise ValueError("lower, upper and max_velocity must have one value per joint")
        self.lower, self.upper, self.vmax = list(lower), list(upper), list(max_velocity)
        self.period = period
        self.n = len(lower)
        self.names = list(names) if names else [f"q{i + 1}" for i in range(self.n)]
        self.target = [0.0] * self.n
        self.rate = [0.0] * self.n          # rad/s of the set-point itself
        self.mode = "idle"
        self._goal = [0.0] * self.n
        self._feed_forward = [0.0] * self.n
        self._velocity = [0.0] * self.n
        self.watchdog = Watchdog()   # fed by every command

    def reset(self, positions: list[float]) -> None:
        """Start from where the joints are, standing still."""
        self._count(positions)
        _finite(self.names, positions)
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

    def position(self, values: list[float], feed_forward: list[float] | None, now: float,
                 measured: list[float] | None = None) -> None:
        """Go to `values` (rad), with an optional velocity feed-forward (rad/s). Raises
        CommandRefused (nothing changes) for a value past a limit or a max speed: see the
        module's tolerances; `measured` (rad) is where the joints are, if known."""
        self.check("position", values, feed_forward, measured)
        ff = list(feed_forward) if feed_forward else [0.0] * self.n
        # Only the tolerated noise (or a way back from outside the limits) is clamped here.
        self._goal = [min(max(v, lo), hi) for v, lo, hi in zip(values, self.lower, self.upper)]
        self._feed_forward = [max(-m, min(m, f)) for f, m in zip(ff, self.vmax)]
        self._velocity = [0.0] * self.n
        self.watchdog.feed(now)
        self.mode = "position"

    def velocity(self, values: list[float], now: float) -> None:
        """Move at `values` (rad/s); raises CommandRefused (nothing changes) past a max speed."""
        self.check("velocity", values)
        self._velocity = [max(-m, min(m, v)) for v, m in zip(values, self.vmax)]
        self._feed_forward = [0.0] * self.n
        self.watchdog.feed(now)
        self.mode = "velocity"

    def check(self, mode: str, values: list[float], feed_forward: list[float] | None = None,
              measured: list[float] | None = None) -> None:
        """Raise ValueError (CommandRefused for a value past a limit) if this command may not
        be obeyed; changes nothing."""
        self._count(values)
        if feed_forward:
            self._count(feed_forward)
        here = [list(self.target)] + ([list(measured)] if measured is not None and len(measured) == self.n else [])
        check_limits(self, mode, values, feed_forward or [], here)

    @property
    def streaming(self) -> bool:
        """Whether a velocity command moves the arm: what the watchdog stops when it goes quiet."""
        return self.mode == "velocity" and any(self._velocity)

    def step(self, now: float) -> list[float]:
        """Advance one period; returns the new set-points (rad)."""
        dt = self.period
        new = []
        for i in range(self.n):
            t, lo, hi, vmax = self.target[i], self.lower[i], self.upper[i], self.vmax[i]
            if self.mode == "velocity":
                want = t + self._velocity[i] * dt
            else:
                ahead = min(max(now - self.watchdog.last, 0.0), FEED_FORWARD_HORIZON_S)
                want = self._goal[i] + self._feed_forward[i] * ahead
            step = max(-vmax * dt, min(vmax * dt, want - t))
            # Never leave the limits; a joint found outside may only move back towards them.
            value = min(max(t + step, min(lo, t)), max(hi, t))
            new.append(value)
        self.rate = [(a - b) / dt for a, b in zip(new, self.target)]
        self.target = new
        return list(new)

    def _count(self, values: list[float]) -> None:
        if len(values) != self.n:
            raise ValueError(f"expected {self.n} joint values, got {len(values)}")


class Limits(Protocol):
    """An arm's joints and their limits (rad, rad/s), one value per joint."""

    names: list[str]
    lower: list[float]
    upper: list[float]
    vmax: list[float]


def check_limits(arm: Limits, mode: str, values: list[float], feed_forward: list[float],
                 here: list[list[float]]) -> None:
    """Raise CommandRefused if a command ("position" with an optional velocity feed-forward, or
    "velocity") has a value that is not finite or beyond a limit (see the module's tolerances);
    `here` are where the joints are now (the set-point, and the measured positions if known):
    a joint found outside its limits may be told to stay or come back, never to go further out.
    Every arm driver refuses in these words."""
    _finite(arm.names, values)
    _finite(arm.names, feed_forward)
    if mode == "velocity":
        _within_speeds(arm, values, "velocity")
        return
    for i, v in enumerate(values):
        lo, hi = arm.lower[i], arm.upper[i]
        now_at = [h[i] for h in here if math.isfinite(h[i])]
        if v > max([hi] + now_at) + POSITION_TOLERANCE_RAD:
            raise CommandRefused("position_limit", f"joint {arm.names[i]} position {quantity(v, 'rad', hi)} "
                                                   f"is beyond its upper limit {quantity(hi, 'rad', v)}")
        if v < min([lo] + now_at) - POSITION_TOLERANCE_RAD:
            raise CommandRefused("position_limit", f"joint {arm.names[i]} position {quantity(v, 'rad', lo)} "
                                                   f"is beyond its lower limit {quantity(lo, 'rad', v)}")
    if feed_forward:
        _within_speeds(arm, feed_forward, "velocity feed-forward")


def check_gripper(opening: float, max_opening: float) -> None:
    """Raise CommandRefused unless `opening` (m between the fingers) is a finite number within
    0..max_opening; as for the joints, a value out of range is refused, never clipped. Every
    arm driver's gripper refuses in these words."""
    if not math.isfinite(opening):
        raise CommandRefused("not_finite", f"gripper opening {quantity(opening)} is not a finite number")
    if not -GRIPPER_TOLERANCE_M <= opening <= max_opening + GRIPPER_TOLERANCE_M:
        raise CommandRefused("position_limit", f"gripper opening {quantity(opening, 'm')} is outside "
                                               f"0..{max_opening:g} m")


def _finite(names: list[str], values: list[float]) -> None:
    for name, v in zip(names, values):
        if not math.isfinite(v):
            raise CommandRefused("not_finite", f"joint {name} got {quantity(v)}, not a finite number")


def _within_speeds(arm: Limits, values: list[float], what: str) -> None:
    for name, v, m in zip(arm.names, values, arm.vmax):
        if abs(v) > m * (1.0 + VELOCITY_TOLERANCE):
            raise CommandRefused("speed_limit", f"joint {name} {what} {quantity(v, 'rad/s', m)} is beyond "
                                                f"its max speed {quantity(m, 'rad/s', abs(v))}")

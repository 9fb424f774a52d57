"""The mobile base's driver rules (watchdog, estop, speed and acceleration limits) and its
odometry, independent of MuJoCo and of the bus.

Numbers (docs/arcos.md, "P3-AT parameters"): P3-AT MaxVelocity 1.2 m/s and MaxRVelocity
300 deg/s (ARIA p3at-sh.p). ARIA leaves accelerations to the firmware; we use the p2os
navigation limits acc_lim_x 2.5 m/s^2 and acc_lim_th 3.2 rad/s^2 as the ramp. A command
beyond the P3-AT's max speeds (more than SPEED_TOLERANCE over) is refused whole, never
clamped: the base keeps its previous command, which the watchdog ends a period later.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from asibot.safety.events import quantity
from asibot.safety.watchdog import Watchdog
from asibot.sim.arm import BadCommand, CommandRejected, Notice

MAX_VX = 1.2
MAX_WZ = math.radians(300.0)
ACC_X = 2.5
ACC_WZ = 3.2
SPEED_TOLERANCE = 1e-3
"""A command this fraction over a max speed is numerical noise: clamped, not refused."""


@dataclass
class BaseDrive:
    """Turns Twist commands into a ramped body velocity, stopping on watchdog and estop."""

    notify: Callable[[Notice], None] = lambda n: None
    estop: bool = False
    vx: float = 0.0
    wz: float = 0.0
    _goal: tuple[float, float] = (0.0, 0.0)
    watchdog: Watchdog = field(default_factory=Watchdog)   # fed by every command

    def command(self, vx: float, wz: float, now: float) -> None:
        self.check(vx, wz)
        if self.estop:
            raise CommandRejected("the emergency stop is engaged; release it before driving")
        self._goal = (float(np.clip(vx, -MAX_VX, MAX_VX)), float(np.clip(wz, -MAX_WZ, MAX_WZ)))
        self.watchdog.feed(now)

    def check(self, vx: float, wz: float) -> None:
        """BadCommand when vx or wz is not finite or beyond the P3-AT's max speeds."""
        for name, v in (("vx", vx), ("wz", wz)):
            if not math.isfinite(v):
                raise BadCommand("not_finite", f"{name} is {quantity(v)}, not a finite number")
        for name, v, limit, unit, what in (("vx", vx, MAX_VX, "m/s", "speed"), ("wz", wz, MAX_WZ, "rad/s", "turn rate")):
            if abs(v) > limit * (1.0 + SPEED_TOLERANCE):
                raise BadCommand("speed_limit", f"{name} {quantity(v, unit, limit)} is beyond the P3-AT's max {what} "
                                                f"{quantity(limit, unit, abs(v))}")

    def set_estop(self, engaged: bool) -> None:
        """Latch or release; engaging stops at once. (The robot reports the estop once, not here.)"""
        if engaged:
            self.stop()
        self.estop = engaged

    def stop(self) -> None:
        """Immediate stop (estop): no ramp."""
        self._goal = (0.0, 0.0)
        self.vx = self.wz = 0.0

    def step(self, dt: float, now: float) -> tuple[float, float]:
        """Advance the ramp by dt; returns the body velocity (vx m/s, wz rad/s) to apply."""
        if self.watchdog.fires(now):
            if self._goal != (0.0, 0.0):
                self.notify(Notice("warning", "watchdog", self.watchdog.says("drive command", "the base stopped")))
            self._goal = (0.0, 0.0)
        gx, gw = self._goal
        self.vx += float(np.clip(gx - self.vx, -ACC_X * dt, ACC_X * dt))
        self.wz += float(np.clip(gw - self.wz, -ACC_WZ * dt, ACC_WZ * dt))
        return self.vx, self.wz


@dataclass
class Odometer:
    """Dead reckoning from measured body velocities, with configurable noise.

    `noise` = (linear, angular) standard deviations as a fraction of the speed, applied per
    update: a real skid-steer's wheel odometry drifts, mostly when it turns, and the nav
    stack must cope with that; set (0, 0) for exact odometry.
    """

    noise: tuple[float, float] = (0.02, 0.05)
    seed: int | None = None
    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    vx: float = 0.0
    wz: float = 0.0
    _rng: np.random.Generator = field(init=False)

    def __post_init__(self) -> None:
        if min(self.noise) < 0:
            raise ValueError("odometry noise must be >= 0 (fractions of the speed)")
        self._rng = np.random.default_rng(self.seed)

    def update(self, vx: float, wz: float, dt: float) -> None:
        if self.noise[0] > 0:
            vx = vx * (1.0 + self._rng.normal(0.0, self.noise[0]))
        if self.noise[1] > 0:
            wz = wz * (1.0 + self._rng.normal(0.0, self.noise[1]))
        mid = self.theta + 0.5 * wz * dt
        self.x += vx * dt * math.cos(mid)
        self.y += vx * dt * math.sin(mid)
        self.theta = math.atan2(math.sin(self.theta + wz * dt), math.cos(self.theta + wz * dt))
        self.vx, self.wz = vx, wz

    def reset(self, x: float = 0.0, y: float = 0.0, theta: float = 0.0) -> None:
        self.x, self.y, self.theta, self.vx, self.wz = x, y, theta, 0.0, 0.0

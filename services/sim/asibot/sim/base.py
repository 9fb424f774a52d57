"""The sim's mobile base: the rules every base keeps (asibot.safety.guarded_base: limits,
estop, watchdog, re-arming, a change of controller), on the sim's clock, and a ramp to the
commanded velocity; its odometry. Independent of MuJoCo and of the bus.

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

from asibot.safety.guarded_base import SPEED_TOLERANCE, EventSink, GuardedBase

__all__ = ["ACC_WZ", "ACC_X", "MAX_VX", "MAX_WZ", "SPEED_TOLERANCE", "BaseDrive", "Odometer"]

MAX_VX = 1.2
MAX_WZ = math.radians(300.0)
ACC_X = 2.5
ACC_WZ = 3.2


def _quiet(level: str, code: str, text: str) -> None:
    """Events nobody listens to (a base made alone, in a test)."""


class BaseDrive(GuardedBase):
    """Turns Twist commands into a ramped body velocity (`step`, each physics step), stopping
    on watchdog and estop. Its clock is the sim's (`clock`, s), as every time it is given."""

    limits = "the P3-AT's"

    def __init__(self, on_event: EventSink = _quiet, clock: Callable[[], float] = lambda: 0.0) -> None:
        super().__init__(MAX_VX, MAX_WZ, on_event, clock=clock)
        self.vx = self.wz = 0.0
        self._goal = (0.0, 0.0)

    def _drive(self, vx: float, wz: float) -> bool:
        self._goal = (vx, wz)
        return True

    def _halt(self) -> None:
        self.stop()

    def _moving(self) -> bool:
        return self._goal != (0.0, 0.0)      # braking to a stop is not moving on

    def stop(self) -> None:
        """Immediate stop (the estop, a reset of the world): no ramp."""
        with self._lock:
            self._goal = (0.0, 0.0)
            self.vx = self.wz = 0.0

    def step(self, dt: float, now: float) -> tuple[float, float]:
        """Advance the ramp by dt; returns the body velocity (vx m/s, wz rad/s) to apply."""
        self.watch(now)
        with self._lock:
            (gx, gw), ax, aw = self._goal, ACC_X * dt, ACC_WZ * dt
            self.vx += min(max(gx - self.vx, -ax), ax)
            self.wz += min(max(gw - self.wz, -aw), aw)
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

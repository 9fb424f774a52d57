"""The P3-AT as navigation sees it: footprint, speed and acceleration limits.

Geometry from docs/arcos.md "P3-AT parameters" (ARIA p3at-sh.p): RobotLength 626 mm,
RobotWidth 505 mm, LengthFront = LengthRear = 313 mm, so the base is centred on its rotation
point. Hardware limits: MaxVelocity 1200 mm/s, MaxRVelocity 300 deg/s; accelerations are the
p2os navigation limits acc_lim_x 2.5 m/s^2, acc_lim_th 3.2 rad/s^2 (the sim's ramp too).
Navigation drives well below them: an assistive robot in a flat shares the room with its user.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LENGTH_M = 0.626
WIDTH_M = 0.505
HW_MAX_VX = 1.2
HW_MAX_WZ = math.radians(300.0)
HW_ACC_X = 2.5
HW_ACC_WZ = 3.2


@dataclass(frozen=True)
class Footprint:
    """A rectangle centred on the rotation point, x forward."""

    length: float = LENGTH_M
    width: float = WIDTH_M

    @property
    def inscribed_radius(self) -> float:
        return min(self.length, self.width) / 2.0

    @property
    def circumscribed_radius(self) -> float:
        return math.hypot(self.length / 2.0, self.width / 2.0)

    def perimeter(self, spacing: float = 0.1, margin: float = 0.0) -> np.ndarray:
        """(K, 2) points on the outline (grown by `margin`), at most `spacing` apart: what a
        collision check looks up in the costmap so the corners, not only the centre, stay clear."""
        hx, hy = self.length / 2 + margin, self.width / 2 + margin
        nx = max(2, int(math.ceil(2 * hx / spacing)) + 1)
        ny = max(2, int(math.ceil(2 * hy / spacing)) + 1)
        xs, ys = np.linspace(-hx, hx, nx), np.linspace(-hy, hy, ny)
        pts = [np.c_[xs, np.full(nx, hy)], np.c_[xs, np.full(nx, -hy)],
               np.c_[np.full(ny, hx), ys], np.c_[np.full(ny, -hx), ys]]
        return np.unique(np.round(np.vstack(pts), 9), axis=0)

    def contains(self, px: np.ndarray, py: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which points (in the robot frame) lie inside the rectangle grown by `margin`."""
        return (np.abs(px) <= self.length / 2 + margin) & (np.abs(py) <= self.width / 2 + margin)


P3AT = Footprint()


@dataclass(frozen=True)
class Limits:
    """Speeds (m/s, rad/s) and accelerations (m/s^2, rad/s^2) a controller may command."""

    max_vx: float = 0.5
    min_vx: float = 0.0
    max_wz: float = 1.2
    acc_x: float = 1.0
    acc_wz: float = 2.0

    def __post_init__(self) -> None:
        for name, value, hw in (("max_vx", self.max_vx, HW_MAX_VX), ("max_wz", self.max_wz, HW_MAX_WZ),
                                ("acc_x", self.acc_x, HW_ACC_X), ("acc_wz", self.acc_wz, HW_ACC_WZ)):
            if not (0 < value <= hw):
                raise ValueError(f"{name} = {value:g} must be in (0, {hw:g}], the P3-AT's limit")
        if not -self.max_vx <= self.min_vx <= self.max_vx:
            raise ValueError(f"min_vx = {self.min_vx:g} must be within +-max_vx")


P3AT_LIMITS = Limits()

"""Obstacle warnings for the user ("Obstacle ahead, 0.4 m."), debounced so they never flood.

The distance is the gap between the robot's body and the nearest return in the path it is
taking, from the merged scan: straight ahead or behind within the body's width (plus a
margin), or anywhere within its turning circle when it turns in place. The direction comes
from the base odometry's velocity; without odometry the robot is assumed to drive ahead; a
robot that odometry says is standing still is watched ahead too, but only up to `info`
(parked in front of its charging station, it is in no danger).

Levels by distance: error <= 0.3 m, warning <= 0.6 m, info <= 1.0 m. Debounce:

- hysteresis: a level is entered below its threshold and left only above threshold +
  `hysteresis`, so a distance dithering at 0.6 m gives one warning, not one per scan;
- minimum interval: within `min_interval` of the last event only a strictly more severe level
  is announced (a person walking in and out of range says nothing new); getting closer is
  always announced at once, as it may matter now;
- one "clear" (info, code "obstacle_clear") after a warning or an error once the path is
  free; nothing is said when leaving an info.

Events carry the stable code "obstacle" so a program or the UI can match them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asibot.messages import Event
from asibot.perception.merge import ScanGrid

LEVELS = ("none", "info", "warning", "error")
CODE = "obstacle"
CLEAR_CODE = "obstacle_clear"
MOVING = 0.02   # m/s: slower is standing still (odometry noise)
TURNING = 0.2   # rad/s: turning in place when faster and not moving


@dataclass(frozen=True)
class Footprint:
    """The body as a rectangle about the base centre, m (P3-AT: 0.626 x 0.505, ARIA p3at.p)."""

    front: float = 0.313
    rear: float = 0.313
    half_width: float = 0.2525

    @property
    def turning_radius(self) -> float:
        return math.hypot(max(self.front, self.rear), self.half_width)


P3AT = Footprint()


def travel_direction(vx: float | None, wz: float | None) -> tuple[str, str | None]:
    """(direction, cap): "ahead", "behind" or "around" (turning in place), and the most severe
    level allowed (None: any). No odometry (None) means ahead, uncapped."""
    if vx is None or wz is None:
        return "ahead", None
    if vx > MOVING:
        return "ahead", None
    if vx < -MOVING:
        return "behind", None
    if abs(wz) > TURNING:
        return "around", None
    return "ahead", "info"


KNOWN_SECTOR = math.radians(15)
"""A way is known when some beam within this of its direction is watched (not NaN)."""


def clearance(ranges: np.ndarray, grid: ScanGrid, direction: str, footprint: Footprint = P3AT,
              margin: float = 0.05) -> float:
    """Gap in m between the body and the nearest return on its way: 0 if touching, inf if the
    way is watched and free, NaN if no sensor watches it (a silent camera: nothing to say)."""
    a = grid.angles()
    if direction != "around":
        heading = 0.0 if direction == "ahead" else math.pi
        sector = np.abs(np.angle(np.exp(1j * (a - heading)))) <= KNOWN_SECTOR
        if np.isnan(ranges[sector]).all():
            return math.nan
    elif np.isnan(ranges).all():
        return math.nan
    ok = np.isfinite(ranges)
    r = ranges[ok].astype(np.float64)
    x, y = r * np.cos(a[ok]), r * np.sin(a[ok])
    if direction == "around":
        gaps = r - footprint.turning_radius
    else:
        sign, extent = (1.0, footprint.front) if direction == "ahead" else (-1.0, footprint.rear)
        in_path = (sign * x > 0) & (np.abs(y) <= footprint.half_width + margin)
        gaps = sign * x[in_path] - extent
    return max(0.0, float(gaps.min())) if gaps.size else math.inf


@dataclass(frozen=True)
class WarningLevels:
    info: float = 1.0
    warning: float = 0.6
    error: float = 0.3
    hysteresis: float = 0.1
    min_interval: float = 2.0

    def __post_init__(self) -> None:
        if not 0 < self.error < self.warning < self.info:
            raise ValueError("warning distances must satisfy 0 < error < warning < info")
        if self.hysteresis < 0 or self.min_interval < 0:
            raise ValueError("hysteresis and minimum interval must be >= 0")

    def threshold(self, level: int) -> float:
        return (math.inf, self.info, self.warning, self.error)[level]


_WHERE = {"ahead": "ahead", "behind": "behind", "around": "beside the robot while it turns"}


class ObstacleWarner:
    """Turns a stream of (distance, direction) into a few Events; the clock is the caller's."""

    def __init__(self, levels: WarningLevels = WarningLevels()) -> None:
        self.levels = levels
        self.level = 0                 # current level, index into LEVELS
        self.direction = "ahead"
        self._last_level = 0           # level of the last event sent
        self._last_time = -math.inf    # when it was sent

    def _level_for(self, distance: float) -> int:
        lv = self.levels
        enter = max((i for i in (1, 2, 3) if distance <= lv.threshold(i)), default=0)
        stay = max((i for i in (1, 2, 3) if distance <= lv.threshold(i) + lv.hysteresis), default=0)
        return max(enter, min(self.level, stay))

    def update(self, distance: float, direction: str, now: float, cap: str | None = None) -> Event | None:
        """The Event to publish now (or None) for the gap `distance` (m) on the way `direction`;
        a NaN distance (the way is not watched) says nothing and changes nothing."""
        if direction not in _WHERE:
            raise ValueError(f"direction must be one of {', '.join(_WHERE)}, not {direction!r}")
        if math.isnan(distance):
            return None
        if direction != self.direction:   # another way: a new situation, nothing to clear
            self.direction, self.level, self._last_level = direction, 0, 0
        new = self._level_for(distance)
        if cap is not None:
            new = min(new, LEVELS.index(cap))
        old, self.level = self.level, new
        recent = now - self._last_time < self.levels.min_interval
        if new > old and (new > self._last_level or not recent):
            self._last_level, self._last_time = new, now
            return Event(level=LEVELS[new], code=CODE, text=f"Obstacle {_WHERE[direction]}, {distance:.1f} m.")
        if new == 0 and old > 0 and self._last_level >= 2 and not recent:
            self._last_level, self._last_time = 0, now
            return Event(level="info", code=CLEAR_CODE, text=f"The way {_WHERE[direction]} is clear again."
                         if direction != "around" else "Nothing is near the robot any more.")
        return None

"""Several cameras' nearest returns -> one 360-degree LaserScan in the robot's base frame.

The scan is fixed: `beams` beams from -pi, counter-clockwise, beam i at angle_min + i *
increment, ranges measured from the base centre. Values follow REP 117, which the nav
costmap reads that way: a number is the nearest obstacle of that beam; +inf means a sensor
watches the beam and sees nothing in its band and reach (free, cleared by the costmap); NaN
means no sensor watches the beam (unknown: neither marked nor cleared). Without NaN, the
blind sectors between the front and back cameras would clear obstacles seen a moment before.

A camera watches a beam when it sees the whole beam from `watch_from` (1 m from the base
centre) out to `range_max`. The cameras sit at the robot's ends, not at its centre, so near
the edges of their fields of view a beam enters the image only some way out (parallax: the
front camera sees the beam at 25 deg only beyond ~1.6 m); calling such a beam free because
nothing was returned would free the blind wedge beside the camera. Those beams stay NaN
unless a return lands in them. Nearer than `watch_from` the sonar ring is the guard.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from asibot.messages import LaserScan
from asibot.perception.depth_to_scan import CameraScan


@dataclass(frozen=True)
class ScanGrid:
    """The merged scan's beams and limits."""

    beams: int = 720
    range_min: float = 0.05
    """m from the base centre; nothing is nearer than the robot's own body."""
    range_max: float = 8.0
    """m from the base centre; farther returns count as none (+inf)."""
    watch_from: float = 1.0
    """m from the base centre: a camera watches a beam it sees from here to range_max."""

    def __post_init__(self) -> None:
        if not 8 <= self.beams <= 36000:
            raise ValueError(f"a scan needs 8 to 36000 beams, not {self.beams}")
        if not (math.isfinite(self.range_max) and 0 <= self.range_min < self.range_max):
            raise ValueError(f"scan ranges must satisfy 0 <= range min ({self.range_min} m) < range max "
                             f"({self.range_max} m)")
        if not 0 < self.watch_from < self.range_max:
            raise ValueError("watch_from must lie between 0 and range max")

    @property
    def angle_min(self) -> float:
        return -math.pi

    @property
    def increment(self) -> float:
        return 2 * math.pi / self.beams

    def angles(self) -> np.ndarray:
        return self.angle_min + self.increment * np.arange(self.beams)

    def index(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Beam of each base-frame point (the nearest beam angle)."""
        a = np.arctan2(y, x)
        return np.rint((a - self.angle_min) / self.increment).astype(np.int64) % self.beams

    def unknown(self) -> np.ndarray:
        """A scan that watches nothing yet: NaN everywhere."""
        return np.full(self.beams, np.nan, np.float32)

    def cover(self, ranges: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        """Mark the beams of these points as watched: NaN -> +inf (in place)."""
        idx = self.index(x, y)
        ranges[idx] = np.where(np.isnan(ranges[idx]), np.float32(np.inf), ranges[idx])

    def watched(self, scan: CameraScan) -> np.ndarray:
        """The beams `scan`'s camera sees whole from watch_from to range_max (bool, read-only)."""
        return _watched(self, float(scan.origin[0]), float(scan.origin[1]), *scan.fov)

    def add(self, ranges: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        """Put returns at base-frame points into the scan: each beam keeps its nearest (in place).
        Returns beyond range_max only mark their beam as watched; nearer than range_min, dropped."""
        if len(x) == 0:
            return
        r = np.hypot(x, y)
        idx = self.index(x, y)
        self.cover(ranges, x, y)
        ok = (r >= self.range_min) & (r <= self.range_max)
        np.minimum.at(ranges, idx[ok], r[ok].astype(np.float32))

    def message(self, ranges: np.ndarray, stamp: int | None = None) -> LaserScan:
        kw = {} if stamp is None else {"stamp": stamp}
        return LaserScan(angle_min=self.angle_min, angle_increment=self.increment, range_min=self.range_min,
                         range_max=self.range_max, ranges=np.asarray(ranges, np.float32), **kw)


@functools.lru_cache(maxsize=64)
def _watched(grid: ScanGrid, ox: float, oy: float, centre: float, lo: float, hi: float) -> np.ndarray:
    # The field of view is a wedge narrower than pi, so a segment lies in it when both its ends do.
    a = grid.angles()
    ok = np.ones(grid.beams, bool)
    for d in (grid.watch_from, grid.range_max):
        rel = np.angle(np.exp(1j * (np.arctan2(d * np.sin(a) - oy, d * np.cos(a) - ox) - centre)))
        ok &= (rel >= lo) & (rel <= hi)
    ok.flags.writeable = False
    return ok


def merge(grid: ScanGrid, scans: Iterable[CameraScan]) -> np.ndarray:
    """One scan (ranges, float32) from the cameras' nearest returns: each beam the nearest of
    every camera, +inf where watched and empty, NaN where no camera watches."""
    ranges = grid.unknown()
    for s in scans:
        ranges[grid.watched(s) & np.isnan(ranges)] = np.inf
        grid.add(ranges, *s.points())
    return ranges

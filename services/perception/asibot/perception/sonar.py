"""Sonar fused into the scan: what the depth cameras cannot see (glass, very close range);
and the scan of a robot with no depth camera, from its sonar alone (`SonarRing.scan`).

A depth camera sees through glass and has a blind zone near the robot; the Pioneer's ring of
16 sonars hears both. A sonar reading says only "something at range r, somewhere in my
cone", so it is used where the cameras fail and nowhere else:

- a reading is *explained* when the depth scan already has a return inside its cone at about
  that distance from the transducer (within `tolerance`): then the cameras' finer bearings win
  and the sonar changes nothing (otherwise a slanted wall would get the sonar's coarse arc);
- an unexplained reading is laid as an arc at range r across the cone. If the cameras watch
  the whole cone, they missed something there (glass, a black or thin object): each beam of
  the arc takes the sonar's distance where it is nearer than the depth's or the depth has none.
  If part of the cone is watched by no camera (NaN beams), the echo is taken to come from that
  part, and only those beams get it: a wall heard at the edge of a side sonar's cone must not
  become a phantom obstacle in front of the camera that sees the way clear. There, only echoes
  within `unwatched_range` are used: farther, the arc's error is larger than what it adds.

Readings outside [min_range, max_range) are ignored: the P3-AT reports its maximum, 4.335 m,
when no echo comes back (not "free": a specular surface also returns nothing). Transducer
poses are the P3-AT's (ARIA p3at-sh.p, docs/arcos.md, 'P3-AT parameters', the same the sim
and the base driver use); the headings come from each Sonar message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asibot.messages import Sonar
from asibot.perception.errors import BadInput
from asibot.perception.merge import ScanGrid

#: (x mm, y mm) of the P3-AT's 8 + 8 transducers, ARIA p3at-sh.p.
P3AT_POSITIONS_MM = (
    (147, 136), (193, 119), (227, 79), (245, 27), (245, -27), (227, -79), (193, -119), (147, -136),
    (-144, -136), (-189, -119), (-223, -79), (-241, -27), (-241, 27), (-223, 79), (-189, 119), (-144, 136),
)
P3AT_MAX_RANGE = 4.335


@dataclass(frozen=True)
class SonarRing:
    """Where the transducers sit on the base, and what a valid echo is."""

    positions: np.ndarray          # (N, 2) base frame, m
    cone_half_angle: float = math.radians(12.5)
    """rad. The sim casts +-10 deg (services/sim/asibot/sim/sensors.py), a real P3-AT sonar hears ~+-15 deg.
    Wider than the sim's on purpose: sonars 3 and 4 look at +-10 deg from points 5.4 cm apart,
    so +-10 deg arcs leave a gap straight ahead; an echo may come from anywhere in its cone."""
    min_range: float = 0.02
    max_range: float = P3AT_MAX_RANGE
    tolerance: float = 0.1
    """m: a depth return this close to the echo's distance explains the echo."""
    arc_step: float = math.radians(0.5)
    unwatched_range: float = 0.6
    """m: where no camera watches, only nearer echoes are laid in. A cone's nearest echo drawn
    across the cone puts a slanted wall up to r (1 - cos 12.5 deg) / cos(slant) nearer than it
    is, and a table leg up to r sin 12.5 deg to either side: at 4 m that painted ghost
    obstacles half a metre inside the rooms of the sim apartment; at 1.5 m the side sonars,
    which no camera ever clears, laid streaks round the kitchen table that closed both ways
    past it for navigation (its planner found no way at all). Within 0.6 m an arc is off by
    13 cm at most, and that is where a side echo matters: a turn on the spot."""

    @classmethod
    def p3at(cls, **kw: float) -> "SonarRing":
        return cls(np.asarray(P3AT_POSITIONS_MM, float) / 1000.0, **kw)

    def check(self, msg: Sonar) -> tuple[np.ndarray, np.ndarray]:
        """(ranges, headings) of a Sonar message, or BadInput with a sentence."""
        r = np.asarray(msg.ranges, float)
        a = np.asarray(msg.angles, float)
        if len(r) != len(a):
            raise BadInput(f"the sonar message has {len(r)} ranges but {len(a)} angles; it needs one angle "
                           "per range.")
        if len(r) != len(self.positions):
            raise BadInput(f"the sonar message has {len(r)} readings but the ring has {len(self.positions)} "
                           "transducers: a robot with another ring needs its positions in asibot.perception.sonar.")
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(a))):
            raise BadInput("the sonar message contains a value that is not finite; ranges and angles must be "
                           "numbers (the maximum range means no echo).")
        return r, a

    def scan(self, grid: ScanGrid, msg: Sonar) -> np.ndarray:
        """The scan of a robot with sonar alone: each echo at the middle of its cone, seen from
        the base centre; every other beam unknown (NaN), a silent sonar's too (no echo is not
        "free"). The middle is the echo's likeliest place: an arc across the cone would put
        most of its points where nothing is, for localisation and the costmap alike."""
        r, heading = self.check(msg)
        echo = (r >= self.min_range) & (r < self.max_range - 1e-3)
        out = np.full(grid.beams, np.inf, np.float32)
        pos = self.positions[echo]
        grid.add(out, pos[:, 0] + r[echo] * np.cos(heading[echo]), pos[:, 1] + r[echo] * np.sin(heading[echo]))
        out[~np.isfinite(out)] = np.nan
        return out

    def fuse(self, grid: ScanGrid, ranges: np.ndarray, msg: Sonar) -> np.ndarray:
        """`ranges` (the depth scan, left untouched) with the unexplained echoes of `msg` laid in."""
        r, heading = self.check(msg)
        echo = (r >= self.min_range) & (r < self.max_range - 1e-3)
        if not echo.any():
            return ranges
        pos, r, heading = self.positions[echo], r[echo], heading[echo]
        # depth returns in each cone, seen from its transducer
        angles = grid.angles()
        hit = np.isfinite(ranges)
        dx = ranges[hit] * np.cos(angles[hit]) - pos[:, 0, None]
        dy = ranges[hit] * np.sin(angles[hit]) - pos[:, 1, None]
        off = np.abs(np.angle(np.exp(1j * (np.arctan2(dy, dx) - heading[:, None]))))
        seen = np.where(off <= self.cone_half_angle, np.hypot(dx, dy), np.inf).min(axis=1, initial=np.inf)
        new = seen > r + self.tolerance
        if not new.any():
            return ranges
        pos, r, heading = pos[new], r[new], heading[new]
        n = max(2, int(math.ceil(2 * self.cone_half_angle / self.arc_step)) + 1)
        d = np.linspace(-self.cone_half_angle, self.cone_half_angle, n)
        x = pos[:, 0, None] + r[:, None] * np.cos(heading[:, None] + d)      # (echoes, n)
        y = pos[:, 1, None] + r[:, None] * np.sin(heading[:, None] + d)
        whole = ~np.isnan(ranges[grid.index(x, y)]).any(axis=1)             # cone watched whole
        out = ranges.copy()
        for watched in (True, False):
            pick = (whole == watched) & (watched | (r <= self.unwatched_range))
            if not pick.any():
                continue
            arc = np.full(grid.beams, np.inf, np.float32)
            grid.add(arc, x[pick].ravel(), y[pick].ravel())
            # nearer than the depth, or the depth has no number (inf, NaN); or only the unwatched
            take = np.isfinite(arc) & (~(ranges <= arc) if watched else np.isnan(ranges))
            out[take] = np.fmin(out[take], arc[take])
        return out

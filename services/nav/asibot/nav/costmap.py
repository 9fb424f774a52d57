"""A layered costmap: the static map, obstacles seen by the scan, and inflation around both.

Values and the inflation cost function are costmap_2d's (docs/reference/navigation.md,
'Costmap'): FREE 0, INSCRIBED 253, LETHAL 254, NO_INFORMATION 255; a cell at distance d (m)
from the nearest lethal cell costs 254 at d = 0, 253 within the footprint's inscribed
radius, and int(252 exp(-cost_scaling_factor (d - inscribed))) out to `inflation_radius`.
Distances come from OpenCV's exact Euclidean distance transform, so an update is a few
vectorised passes over the grid and never a loop over cells.

Obstacle layer: scan endpoints closer than `obstacle_range` mark cells lethal; every beam
clears the cells it passed through (raytracing, up to `raytrace_range`), before marking, as
costmap_2d does. Two of the users' top pain points (same file, 'Known complaints', "ghost
obstacles") are answered here: a max-range or infinite reading clears its whole ray
(`clear_on_max_range`), and a mark not seen again for `obstacle_decay_s` fades, so an
obstacle that left the field of view of a narrow depth camera does not stay forever. The
cells under the robot are cleared (footprint clearing): the robot cannot stand inside an
obstacle.

Defaults follow nav2's tuned inflation (0.70 m, scaling 3.0), which keeps paths in the middle
of doorways; nav2's obstacle/raytrace ranges 2.5 / 3.0 m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from asibot.messages import LaserScan
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.nav.robot import P3AT, Footprint

FREE, INSCRIBED, LETHAL, NO_INFORMATION = 0, 253, 254, 255
#: Distance transform look-up resolution: 1/8 of a cell.
_SUB = 8


@dataclass(frozen=True)
class CostmapParams:
    inflation_radius: float = 0.70
    cost_scaling_factor: float = 3.0
    obstacle_range: float = 2.5
    raytrace_range: float = 3.0
    clear_on_max_range: bool = True
    obstacle_decay_s: float | None = 30.0
    #: Scan points this close to the footprint are the robot itself or noise: ignored.
    self_filter_margin: float = 0.03


def beam_angles(scan: LaserScan) -> np.ndarray:
    return scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))


def inflation_lut(resolution: float, inscribed: float, radius: float, scaling: float) -> np.ndarray:
    """uint8 cost for distances 0, 1/8, 2/8 ... cells (the last entry, 0, is 'beyond')."""
    d = np.arange(int(math.ceil(radius / resolution * _SUB)) + 2) / _SUB * resolution
    cost = np.where(d <= inscribed, INSCRIBED, np.floor(252.0 * np.exp(-scaling * (d - inscribed))))
    cost = np.where(d > radius, FREE, cost)
    cost[0] = LETHAL
    cost[-1] = FREE
    return cost.astype(np.uint8)


class Costmap:
    """Static + obstacle layers and their inflation over one grid (the map's)."""

    def __init__(self, grid: OccupancyGrid, footprint: Footprint = P3AT,
                 params: CostmapParams = CostmapParams()) -> None:
        self.info: GridInfo = grid.info
        self.footprint = footprint
        self.params = params
        d = grid.data
        # costmap_2d static layer: unknown -> 255, >= 100 lethal, trinary: everything else free.
        self.static = np.where(d < 0, NO_INFORMATION, np.where(d >= 100, LETHAL, FREE)).astype(np.uint8)
        self.marked = np.zeros(self.info.shape, bool)
        self.seen = np.zeros(self.info.shape, np.float64)
        self._lut = inflation_lut(self.info.resolution, footprint.inscribed_radius,
                                  params.inflation_radius, params.cost_scaling_factor)
        self._costs: np.ndarray | None = None
        self._rim: np.ndarray | None = None
        self._perimeter = footprint.perimeter(spacing=self.info.resolution)

    # -------------------------------------------------------------------------- layers

    @property
    def costs(self) -> np.ndarray:
        """The master grid (uint8, row 0 = origin), inflated; recomputed after a change."""
        if self._costs is None:
            self._costs = self._inflate()
            self._rim = None
        return self._costs

    @property
    def rim_costs(self) -> np.ndarray:
        """What the footprint's outline looks up: the inscribed band counts as free (the outline
        may graze it), and lethal or unknown cells are grown by one cell, so a small obstacle
        lying just inside the outline, between two of its samples, still counts."""
        costs = self.costs
        if self._rim is None:
            near = cv2.dilate((costs >= LETHAL).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
            self._rim = np.where(near, LETHAL, np.where(costs == INSCRIBED, FREE, costs)).astype(np.uint8)
        return self._rim

    def _inflate(self) -> np.ndarray:
        master = self.static.copy()
        master[self.marked] = LETHAL
        lethal = master == LETHAL
        if not lethal.any():
            return master
        dist = cv2.distanceTransform((~lethal).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        idx = np.minimum((dist * _SUB + 0.5).astype(np.int32), len(self._lut) - 1)
        inflated = self._lut[idx]
        out = np.maximum(master, inflated)
        unknown = master == NO_INFORMATION
        out[unknown] = np.where(inflated[unknown] >= INSCRIBED, inflated[unknown], NO_INFORMATION)
        return out

    def update_scan(self, pose: Pose, scan: LaserScan, now: float) -> None:
        """Clear along each beam, then mark its endpoint (scan in the base frame, robot at `pose`)."""
        p = self.params
        r = np.asarray(scan.ranges, np.float64)
        a = beam_angles(scan)
        valid = ~np.isnan(r) & (r >= scan.range_min)
        hit = valid & np.isfinite(r) & (r < scan.range_max)
        if p.clear_on_max_range:
            clear_len = np.where(hit, r, scan.range_max)
            clear = valid
        else:
            clear_len, clear = r, hit
        clear_len = np.minimum(np.nan_to_num(clear_len, posinf=p.raytrace_range), p.raytrace_range)
        # endpoints in the robot frame; drop the robot's own body
        rr = np.where(hit, r, 0.0)
        ex, ey = rr * np.cos(a), rr * np.sin(a)
        own = self.footprint.contains(ex, ey, p.self_filter_margin)
        mark = hit & (r <= p.obstacle_range) & ~own
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        res = self.info.resolution
        if clear.any():
            step = res / 2.0
            t = np.arange(0.0, p.raytrace_range, step)
            la, ll = a[clear], clear_len[clear]
            keep = t[None, :] < (ll[:, None] - step)          # stop short of the endpoint's cell
            bx, by = np.cos(la)[:, None] * t[None, :], np.sin(la)[:, None] * t[None, :]
            wx = pose.x + c * bx[keep] - s * by[keep]
            wy = pose.y + s * bx[keep] + c * by[keep]
            self._set(wx, wy, False, now)
        self._clear_footprint(pose)
        if mark.any():
            wx = pose.x + c * ex[mark] - s * ey[mark]
            wy = pose.y + s * ex[mark] + c * ey[mark]
            self._set(wx, wy, True, now)
        if p.obstacle_decay_s is not None:
            old = self.marked & (now - self.seen > p.obstacle_decay_s)
            if old.any():
                self.marked[old] = False
        self._costs = None

    def _set(self, wx: np.ndarray, wy: np.ndarray, value: bool, now: float) -> None:
        rows, cols = self.info.to_cell(wx, wy)
        ok = self.info.inside(rows, cols)
        rows, cols = rows[ok], cols[ok]
        self.marked[rows, cols] = value
        if value:
            self.seen[rows, cols] = now

    def _clear_footprint(self, pose: Pose) -> None:
        res = self.info.resolution
        hx, hy = self.footprint.length / 2, self.footprint.width / 2
        gx, gy = np.meshgrid(np.arange(-hx, hx + 1e-9, res / 2), np.arange(-hy, hy + 1e-9, res / 2))
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        rows, cols = self.info.to_cell(pose.x + c * gx - s * gy, pose.y + s * gx + c * gy)
        ok = self.info.inside(rows, cols)
        self.marked[rows[ok], cols[ok]] = False

    def mark_points(self, xs: np.ndarray, ys: np.ndarray, now: float) -> None:
        """Mark world points lethal (a bumper hit, a sonar echo, a test)."""
        self._set(np.asarray(xs, float), np.asarray(ys, float), True, now)
        self._costs = None

    def clear_obstacles(self, center: Pose | None = None, reset_distance: float = 0.0) -> int:
        """Forget what the scan marked, except inside a square of side `reset_distance` around
        `center` (ClearCostmapRecovery's rule; 0 clears everything). Returns cells cleared."""
        keep = np.zeros(self.info.shape, bool)
        if center is not None and reset_distance > 0:
            rows, cols = np.nonzero(self.marked)
            x, y = self.info.to_world(rows, cols)
            near = (np.abs(x - center.x) <= reset_distance / 2) & (np.abs(y - center.y) <= reset_distance / 2)
            keep[rows[near], cols[near]] = True
        cleared = int((self.marked & ~keep).sum())
        self.marked &= keep
        self._costs = None
        return cleared

    # ------------------------------------------------------------------------- queries

    def cost_of_distance(self, d: float) -> int:
        """The inflation cost of a cell `d` m from the nearest lethal cell (costmap_2d's)."""
        p = self.params
        if d <= 0:
            return LETHAL
        if d <= self.footprint.inscribed_radius:
            return INSCRIBED
        if d > p.inflation_radius:
            return FREE
        return int(252.0 * math.exp(-p.cost_scaling_factor * (d - self.footprint.inscribed_radius)))

    def cost_at(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Cost of the cells holding world points; NO_INFORMATION off the map."""
        rows, cols = self.info.to_cell(x, y)
        ok = self.info.inside(rows, cols)
        out = np.full(np.shape(rows), NO_INFORMATION, np.uint8)
        out[ok] = self.costs[rows[ok], cols[ok]]
        return out

    @property
    def bare_rim_costs(self) -> np.ndarray:
        """`rim_costs` without the one-cell growth: the footprint as it is, for a robot that
        must creep out of a tight spot (a doorway where localisation is 5 cm off)."""
        costs = self.costs
        return np.where(costs == INSCRIBED, FREE, costs).astype(np.uint8)

    def footprint_cost(self, x: np.ndarray | float, y: np.ndarray | float, theta: np.ndarray | float,
                       grown: bool = True) -> np.ndarray:
        """Highest cost under the footprint's outline (`rim_costs`) and centre at each pose
        (arrays of any shape): >= INSCRIBED means the robot would touch an obstacle or leave
        the map. Inside the outline only the centre is looked up: every cell of the P3-AT's
        rectangle is within one cell of the outline or within the inscribed radius of the
        centre, where the inflation already says INSCRIBED."""
        x, y, theta = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float), np.asarray(theta, float))
        px, py = self._perimeter[:, 0], self._perimeter[:, 1]
        c, s = np.cos(theta)[..., None], np.sin(theta)[..., None]
        wx = x[..., None] + c * px - s * py
        wy = y[..., None] + s * px + c * py
        rows, cols = self.info.to_cell(wx, wy)
        ok = self.info.inside(rows, cols)
        rim = np.full(rows.shape, NO_INFORMATION, np.uint8)
        rim[ok] = (self.rim_costs if grown else self.bare_rim_costs)[rows[ok], cols[ok]]
        centre = self.cost_at(x, y)
        if not grown:   # the outline decides; the centre only must not stand on an obstacle
            centre = np.where(centre >= LETHAL, centre, FREE)
        return np.maximum(rim.max(axis=-1), centre)

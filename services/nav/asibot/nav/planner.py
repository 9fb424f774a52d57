"""Global planner: A* over the costmap (pyastar2d, C++), then shortcutting and resampling.

Cell costs are navfn's (docs/reference/navigation.md, 'Global planner'): neutral 50 +
factor x costmap value (2.0, see below), cells >= INSCRIBED (253) are walls, unknown cells are
walls unless `allow_unknown`. The cost is divided by the neutral cost so free space costs 1
per cell, which keeps pyastar2d's heuristic admissible. pyastar2d was chosen because it is a
56 kB compiled A* that plans a 20 m x 20 m, 5 cm map in about 10 ms where scipy's csgraph
Dijkstra needs ~130 ms (building the sparse graph dominates) and a per-cell Python heap
needs seconds. Its diagonal steps cost the same as straight ones, so the raw path zig-zags;
shortcutting (string pulling on the costmap) straightens it, accepting a straight segment
only when it passes no closer to obstacles than the A* path it replaces did.

A goal in a wall or in the inscribed band is moved to the nearest free cell when that is
within `tolerance`; otherwise the error names the nearest free spot, so the user can send that.
A start in the inscribed band (the robot touching a wall after a recovery) may leave it:
the band around the start costs dearly but is passable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyastar2d

from asibot.nav.costmap import INSCRIBED, LETHAL, NO_INFORMATION, Costmap
from asibot.nav.errors import NavError, Unreachable
from asibot.nav.geometry import Pose


@dataclass(frozen=True)
class PlannerParams:
    neutral_cost: float = 50.0
    #: navfn's 0.8 sent the sim's P3-AT between the kitchen wall and a chair (0.9 m for a
    #: 0.8 m turning circle) to save 2 m; a base with an arm, near a person, takes the open way
    #: (global_planner's default is 3.0).
    cost_factor: float = 2.0
    allow_unknown: bool = False
    #: A goal this close (m) to free space is moved there without a word (nav2 NavfnPlanner: 0.5).
    tolerance: float = 0.25
    #: Around the start, cells in the inscribed band are passable at this cost per cell.
    escape_radius: float = 0.45
    escape_cost: float = 40.0
    #: Cells nearer an obstacle than the base's turning radius plus a little cost this much
    #: more each: a passage where the P3-AT fits only straight (0.9 m between a wall and a
    #: chair) is taken only when there is no other way, and paths keep room to turn.
    narrow_clearance: float = 0.46
    narrow_penalty: float = 10.0
    #: Resampled path spacing (m).
    spacing: float = 0.05
    #: Shortcuts may pass cells up to this cost even if the A* path stayed lower.
    shortcut_free_cost: int = 30
    #: The last metres are a straight line along the goal's heading, when there is room: a
    #: rectangular base that arrives askew beside furniture cannot turn there.
    approach: float = 0.6


@dataclass
class Path:
    """Waypoints (N, 2) in the map frame, the goal pose, and the length along them."""

    points: np.ndarray
    goal: Pose
    length: float

    @staticmethod
    def from_points(points: np.ndarray, goal: Pose) -> "Path":
        seg = np.hypot(*np.diff(points, axis=0).T) if len(points) > 1 else np.zeros(0)
        return Path(points, goal, float(seg.sum()))


def nearest_free(costmap: Costmap, x: float, y: float, allow_unknown: bool = False) -> tuple[float, float] | None:
    """World centre of the free cell nearest to (x, y): cost below INSCRIBED."""
    costs = costmap.costs
    ok = costs < INSCRIBED
    if allow_unknown:
        ok |= costs == NO_INFORMATION
    rows, cols = np.nonzero(ok)
    if rows.size == 0:
        return None
    wx, wy = costmap.info.to_world(rows, cols)
    i = int(np.argmin((wx - x) ** 2 + (wy - y) ** 2))
    return float(wx[i]), float(wy[i])


def resample(points: np.ndarray, spacing: float) -> np.ndarray:
    """Points along the polyline at most `spacing` apart, keeping its vertices."""
    if len(points) < 2:
        return points.copy()
    seg = np.diff(points, axis=0)
    n = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / spacing).astype(int))
    t = np.concatenate([np.arange(k) / k for k in n])
    base = np.repeat(points[:-1], n, axis=0) + np.repeat(seg, n, axis=0) * t[:, None]
    return np.vstack([base, points[-1:]])


class GlobalPlanner:
    def __init__(self, params: PlannerParams = PlannerParams()) -> None:
        self.params = params

    def weights(self, costmap: Costmap, start_cell: tuple[int, int]) -> np.ndarray:
        p = self.params
        c = costmap.costs
        w = (p.neutral_cost + p.cost_factor * c.astype(np.float32)) / p.neutral_cost
        blocked = c >= INSCRIBED
        if p.allow_unknown:
            blocked &= c != NO_INFORMATION
            w[c == NO_INFORMATION] = (p.neutral_cost + p.cost_factor * INSCRIBED) / p.neutral_cost
        w[c >= costmap.cost_of_distance(p.narrow_clearance)] += p.narrow_penalty
        w[blocked] = np.inf
        # the way out of the inscribed band around the start
        r = int(math.ceil(p.escape_radius / costmap.info.resolution))
        r0, c0 = start_cell
        sl = (slice(max(0, r0 - r), r0 + r + 1), slice(max(0, c0 - r), c0 + r + 1))
        band = c[sl] == INSCRIBED
        w[sl][band] = p.escape_cost
        w[r0, c0] = 1.0
        return w.astype(np.float32)

    def plan(self, costmap: Costmap, start: Pose, goal: Pose, goal_name: str = "") -> Path:
        """A path from start to goal, or NavError/Unreachable with a sentence."""
        info = costmap.info
        what = goal_name or f"({goal.x:.2f}, {goal.y:.2f})"
        for label, pose in (("The robot's position", start), (f"The goal {what}", goal)):
            if not all(math.isfinite(v) for v in pose):
                raise NavError(f"{label} is not a finite pose: {pose}.")
            if not info.contains(pose.x, pose.y):
                raise NavError(f"{label} ({pose.x:.2f}, {pose.y:.2f}) is outside the map ({info.bounds()}).")
        gx, gy = goal.x, goal.y
        gcost = int(costmap.cost_at(gx, gy))
        if gcost >= INSCRIBED and not (self.params.allow_unknown and gcost == NO_INFORMATION):
            free = nearest_free(costmap, gx, gy, self.params.allow_unknown)
            where = {LETHAL: "inside an obstacle", NO_INFORMATION: "in an unknown part of the map"}.get(
                gcost, "too close to an obstacle for the robot")
            if free is None:
                raise Unreachable(f"The goal {what} is {where}, and the map has no free space at all.")
            dist = math.hypot(free[0] - gx, free[1] - gy)
            if dist > self.params.tolerance:
                raise Unreachable(f"The goal {what} is {where}; the nearest free spot is "
                                  f"({free[0]:.2f}, {free[1]:.2f}), {dist:.2f} m away: send that instead.")
            gx, gy = free
        final = Pose(gx, gy, goal.theta)
        approach = self._approach(costmap, final, start)
        if approach is not None:
            gx, gy = approach.x, approach.y
        (sr,), (sc,) = info.to_cell(np.array([start.x]), np.array([start.y]))
        (gr,), (gc,) = info.to_cell(np.array([gx]), np.array([gy]))
        w = self.weights(costmap, (int(sr), int(sc)))
        if costmap.costs[sr, sc] == LETHAL and not np.isfinite(w[sr, sc]):
            raise Unreachable("The robot is inside an obstacle on the map; clear the costmap or move it by hand.")
        if (sr, sc) == (gr, gc):
            pts = np.array([[start.x, start.y], [gx, gy]])
        else:
            cells = pyastar2d.astar_path(w, (int(sr), int(sc)), (int(gr), int(gc)), allow_diagonal=True)
            if cells is None:
                raise Unreachable(f"There is no way to {what}: walls or obstacles close every route "
                                  f"(the robot needs {2 * costmap.footprint.inscribed_radius:.2f} m to pass).")
            cells = np.asarray(cells)
            keep = self.shortcut(costmap, cells)
            wx, wy = info.to_world(cells[keep, 0], cells[keep, 1])
            pts = np.c_[wx, wy]
            pts[0] = (start.x, start.y)
            pts[-1] = (gx, gy)
        if approach is not None:
            pts = np.vstack([pts, [[final.x, final.y]]])
        return Path.from_points(resample(pts, self.params.spacing), final)

    def _approach(self, costmap: Costmap, goal: Pose, start: Pose) -> Pose | None:
        """The point `approach` m before the goal along its heading, when the footprint fits
        all the way from there to the goal at the goal's heading and the robot is not already
        about there; else None."""
        d = self.params.approach
        if d <= 0 or start.distance(goal) < d:
            return None
        s = np.linspace(0.0, d, max(2, int(d / costmap.info.resolution) + 1))
        xs, ys = goal.x - s * math.cos(goal.theta), goal.y - s * math.sin(goal.theta)
        if (costmap.footprint_cost(xs, ys, goal.theta) >= INSCRIBED).any():
            return None
        return Pose(float(xs[-1]), float(ys[-1]), goal.theta)

    def shortcut(self, costmap: Costmap, cells: np.ndarray) -> np.ndarray:
        """Indices of the cells kept by string pulling: from each kept cell, jump to the
        farthest later cell whose straight segment is no costlier than the path between."""
        costs = costmap.costs
        along = costs[cells[:, 0], cells[:, 1]].astype(np.int16)
        n = len(cells)
        keep = [0]
        i = 0
        window = 400
        while i < n - 1:
            j = np.arange(i + 1, min(n, i + 1 + window))
            d = cells[j] - cells[i]
            steps = int(np.abs(d).max()) * 2 + 1
            t = np.linspace(0.0, 1.0, steps)
            rr = np.rint(cells[i, 0] + d[:, 0, None] * t[None, :]).astype(np.int64)
            cc = np.rint(cells[i, 1] + d[:, 1, None] * t[None, :]).astype(np.int64)
            seg_max = costs[rr, cc].max(axis=1).astype(np.int16)
            path_max = np.maximum.accumulate(along[i + 1:i + 1 + len(j)])
            limit = np.maximum(np.maximum(path_max, along[i]), self.params.shortcut_free_cost)
            ok = (seg_max <= limit) & (seg_max < INSCRIBED)
            ok[0] = True
            nxt = int(j[np.nonzero(ok)[0][-1]])
            keep.append(nxt)
            i = nxt
        return np.array(keep)

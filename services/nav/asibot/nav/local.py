"""Local controller: DWA-style sampling of (v, w), scored on the costmap, at 10-20 Hz.

What it does each cycle (facts: docs/reference/navigation.md, 'Local controller', DWA and
DWB):
- the dynamic window: speeds reachable within one control period from the current ones at
  the P3-AT's accelerations, inside the navigation limits (`asibot.nav.robot.Limits`), with
  the top speed lowered near the goal so the robot can always stop on it;
- every (v, w) pair of the window is rolled out as an arc for `sim_time` seconds, all at
  once as arrays; a trajectory whose footprint (outline and centre) meets a lethal or
  unknown cell anywhere along it is discarded, so what is chosen leaves room to stop;
- the survivors are scored as DWA does: distance of the end point to the path (path_bias),
  to the local goal a little way ahead on the path (goal_bias), the worst cell cost passed
  (occ_bias), and the distance of a point ahead of the robot to the path (align_bias, DWB's
  PathAlign); a turn against the previous turn direction before the robot moved at all costs
  extra (the oscillation critic).
- Two of the users' top complaints about DWA (same file, 'Known complaints': rotate-in-place
  trajectories scored poorly, creeping or failing near the goal) are handled outside the
  sampling: when the path starts behind the robot it first turns in place (DWB's
  RotateToGoal idea applied to the path), and once within xy_goal_tolerance it only turns to
  the goal's heading.

`compute` returns a `Control` with the speeds and a status: "moving", "arrived" or
"blocked" with a sentence. It never sees the bus or a clock beyond the arguments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asibot.nav.costmap import INSCRIBED, Costmap
from asibot.nav.geometry import Pose, wrap
from asibot.nav.planner import Path
from asibot.nav.robot import P3AT_LIMITS, Limits


@dataclass(frozen=True)
class LocalParams:
    sim_time: float = 1.5
    sim_dt: float = 0.1
    period: float = 0.1          # control period (s): the dynamic window's width
    vx_samples: int = 9
    wz_samples: int = 21
    path_bias: float = 2.0        # per m
    goal_bias: float = 1.5        # per m
    occ_bias: float = 0.006       # per cost unit (0..252) of the centre's worst cell
    occ_fade_distance: float = 1.5
    align_bias: float = 0.8       # per m
    oscillation_cost: float = 0.3
    oscillation_reset_dist: float = 0.05
    oscillation_reset_angle: float = 0.2
    forward_point: float = 0.3
    lookahead: float = 1.2        # local goal, m along the path
    rotate_first_angle: float = 1.0   # rad: turn in place when the path is this far off the heading
    xy_goal_tolerance: float = 0.08
    yaw_goal_tolerance: float = 0.08
    final_decel_fraction: float = 0.6  # plan to stop using this share of the deceleration
    min_rotate_wz: float = 0.15
    creep_speed: float = 0.1      # m/s at most where only the bare footprint fits
    min_progress_vx: float = 0.02  # m/s and rad/s: slower than both, a chosen way is standing still
    min_progress_wz: float = 0.05


@dataclass
class Control:
    vx: float
    wz: float
    status: str = "moving"       # moving | arrived | blocked
    text: str = ""
    remaining: float = 0.0       # m along the path to the goal


def arcs(x: float, y: float, th: float, v: np.ndarray, w: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Poses after time t (T,) on constant (v, w) arcs (K,): arrays (K, T)."""
    v, w, t = v[:, None], w[:, None], t[None, :]
    straight = np.abs(w) < 1e-6
    ws = np.where(straight, 1.0, w)
    th_t = th + w * t
    xs = np.where(straight, x + v * t * math.cos(th), x + v / ws * (np.sin(th_t) - math.sin(th)))
    ys = np.where(straight, y + v * t * math.sin(th), y - v / ws * (np.cos(th_t) - math.cos(th)))
    return xs, ys, np.broadcast_to(th_t, xs.shape)


class LocalController:
    def __init__(self, limits: Limits = P3AT_LIMITS, params: LocalParams = LocalParams()) -> None:
        self.limits = limits
        self.params = params
        self.path: Path | None = None
        self._index = 0
        self._last = (0.0, 0.0)
        self._flip_pose: Pose | None = None

    def set_path(self, path: Path) -> None:
        """Follow a new path (a replan keeps the oscillation memory: the robot has not moved)."""
        self.path = path
        self._index = 0

    def clear(self) -> None:
        self.path = None
        self._index = 0
        self._last = (0.0, 0.0)
        self._flip_pose = None

    # ---------------------------------------------------------------------------- helpers

    def _progress(self, pose: Pose) -> tuple[int, float]:
        """Index of the path point nearest the robot (never far behind the last one) and the
        distance left along the path from there."""
        assert self.path is not None
        pts = self.path.points
        lo = max(0, self._index - 10)
        hi = min(len(pts), self._index + 200)
        d = np.hypot(pts[lo:hi, 0] - pose.x, pts[lo:hi, 1] - pose.y)
        i = lo + int(np.argmin(d))
        self._index = max(i, self._index - 10)
        seg = np.hypot(*np.diff(pts[i:], axis=0).T) if len(pts) - i > 1 else np.zeros(0)
        return i, float(seg.sum() + d[i - lo])

    def _turn(self, err: float, w0: float) -> float:
        """A turn rate toward heading error `err` that decelerates to stop on it."""
        lim = self.limits
        stop_w = math.sqrt(2 * lim.acc_wz * self.params.final_decel_fraction * abs(err))
        w = math.copysign(max(self.params.min_rotate_wz, min(lim.max_wz, stop_w, 2.0 * abs(err))), err)
        return float(np.clip(w, w0 - lim.acc_wz * self.params.period, w0 + lim.acc_wz * self.params.period))

    def _can_turn(self, pose: Pose, err: float, costmap: Costmap) -> bool:
        steps = max(2, int(abs(err) / 0.1))
        th = pose.theta + np.linspace(0.0, err, steps)
        return bool((costmap.footprint_cost(pose.x, pose.y, th) < INSCRIBED).all())

    # ---------------------------------------------------------------------------- control

    def compute(self, pose: Pose, velocity: tuple[float, float], costmap: Costmap) -> Control:
        """Speeds for the next period; `velocity` is the base's current (vx, wz)."""
        p, lim = self.params, self.limits
        if self.path is None:
            return Control(0.0, 0.0, "arrived", "no path to follow")
        i, remaining = self._progress(pose)
        goal = self.path.goal
        v0, w0 = velocity
        dist_goal = math.hypot(goal.x - pose.x, goal.y - pose.y)
        if dist_goal <= p.xy_goal_tolerance:
            err = wrap(goal.theta - pose.theta)
            if abs(err) <= p.yaw_goal_tolerance:
                return self._out(Control(0.0, 0.0, "arrived", "arrived", 0.0), pose)
            return self._out(Control(0.0, self._turn(err, w0), "moving", "turning to the goal's heading", dist_goal), pose)
        pts = self.path.points
        n_ahead = max(2, int(round(p.lookahead / max(1e-3, self._spacing()))))
        local = pts[i:i + n_ahead]
        carrot = pts[min(len(pts) - 1, i + max(1, int(round(0.4 / max(1e-3, self._spacing())))))]
        heading_err = wrap(math.atan2(carrot[1] - pose.y, carrot[0] - pose.x) - pose.theta)
        if abs(heading_err) > p.rotate_first_angle and abs(v0) < 0.1 and self._can_turn(pose, heading_err, costmap):
            return self._out(Control(0.0, self._turn(heading_err, w0), "moving", "turning toward the path", remaining), pose)
        # the dynamic window
        vmax = min(lim.max_vx, math.sqrt(2 * lim.acc_x * p.final_decel_fraction * dist_goal))
        vlo, vhi = max(lim.min_vx, v0 - lim.acc_x * p.period), min(vmax, v0 + lim.acc_x * p.period)
        if vhi < vlo:   # faster than the slow-down allows: brake as hard as allowed
            vhi = vlo
        wlo, whi = max(-lim.max_wz, w0 - lim.acc_wz * p.period), min(lim.max_wz, w0 + lim.acc_wz * p.period)
        vs = np.unique(np.r_[np.linspace(vlo, vhi, p.vx_samples), np.clip(0.0, vlo, vhi)])
        ws = np.unique(np.r_[np.linspace(wlo, whi, p.wz_samples), np.clip(0.0, wlo, whi)])
        V, W = (a.ravel() for a in np.meshgrid(vs, ws))
        t = np.arange(1, int(round(p.sim_time / p.sim_dt)) + 1) * p.sim_dt
        xs, ys, ths = arcs(pose.x, pose.y, pose.theta, V, W, t)
        cost = costmap.footprint_cost(xs, ys, ths)
        ok = (cost < INSCRIBED).all(axis=1)
        if not ok.any():
            # a tight spot (a doorway, localisation a few cm off): creep on with the bare
            # footprint, slowly, rather than give up where the robot still fits
            cost = costmap.footprint_cost(xs, ys, ths, grown=False)
            ok = (cost < INSCRIBED).all(axis=1) & (np.abs(V) <= p.creep_speed)
        if not ok.any():
            return self._out(Control(0.0, 0.0, "blocked", self._blocked_text(pose, costmap), remaining), pose)
        ex, ey, eth = xs[:, -1], ys[:, -1], ths[:, -1]
        dpath = np.hypot(ex[:, None] - local[None, :, 0], ey[:, None] - local[None, :, 1]).min(axis=1)
        dgoal = np.hypot(ex - local[-1, 0], ey - local[-1, 1])
        fx, fy = ex + p.forward_point * np.cos(eth), ey + p.forward_point * np.sin(eth)
        dalign = np.hypot(fx[:, None] - local[None, :, 0], fy[:, None] - local[None, :, 1]).min(axis=1)
        occ = costmap.cost_at(xs, ys).max(axis=1).astype(float)
        # near the goal the obstacle term fades (collisions are still refused): the goal is
        # often beside furniture, and a cost that grows toward it would stop the robot short
        fade = min(1.0, dist_goal / p.occ_fade_distance)
        score = p.path_bias * dpath + p.goal_bias * dgoal + p.align_bias * dalign + p.occ_bias * fade * occ
        score += p.oscillation_cost * self._oscillating(pose, V, W)
        score[~ok] = np.inf
        k = int(np.argmin(score))
        if abs(V[k]) < 0.02 and abs(heading_err) > 0.15 and abs(v0) < 0.05 and self._can_turn(pose, heading_err, costmap):
            # DWA's deadlock: nothing forward scores better than standing still; turning
            # toward the path (which arcs cannot score, as they do not move) opens a way
            return self._out(Control(0.0, self._turn(heading_err, w0), "moving", "turning toward the path", remaining), pose)
        if abs(V[k]) < p.min_progress_vx and abs(W[k]) < p.min_progress_wz:
            # Standing still won on points: from rest the window reaches only a few cm, and
            # the first step into the inflation around a doorway or a table costs more than
            # those cm gain, so the robot would wait there for ever (seen for 20 s and more
            # in the sim apartment). Standing still is never a way to the goal: take the best
            # way that moves, or say the way is blocked, so the navigator replans or recovers.
            moving = ok & (V >= p.min_progress_vx)
            if not moving.any():
                return self._out(Control(0.0, 0.0, "blocked", self._blocked_text(pose, costmap), remaining), pose)
            k = int(np.argmin(np.where(moving, score, np.inf)))
        return self._out(Control(float(V[k]), float(W[k]), "moving", "", remaining), pose)

    def _spacing(self) -> float:
        assert self.path is not None
        pts = self.path.points
        return float(self.path.length / max(1, len(pts) - 1)) if len(pts) > 1 else 0.05

    def _oscillating(self, pose: Pose, V: np.ndarray, W: np.ndarray) -> np.ndarray:
        """1 for turning in place against the last turn before the robot moved, else 0."""
        lv, lw = self._last
        if self._flip_pose is not None:
            moved = pose.distance(self._flip_pose) > self.params.oscillation_reset_dist or \
                abs(wrap(pose.theta - self._flip_pose.theta)) > self.params.oscillation_reset_angle
            if moved:
                self._flip_pose = None
        if abs(lw) < 0.05 or abs(lv) > 0.05:
            return np.zeros(len(V))
        return ((np.sign(W) == -np.sign(lw)) & (np.abs(V) < 0.05) & (self._flip_pose is not None)).astype(float)

    def _out(self, c: Control, pose: Pose) -> Control:
        lw = self._last[1]
        if abs(c.wz) > 0.05 and abs(lw) > 0.05 and math.copysign(1, c.wz) != math.copysign(1, lw):
            self._flip_pose = pose
        self._last = (c.vx, c.wz)
        return c

    def _blocked_text(self, pose: Pose, costmap: Costmap) -> str:
        """Where the way is blocked, for a sentence."""
        ahead = np.arange(0.1, 1.6, 0.05)
        xs = pose.x + ahead * math.cos(pose.theta)
        ys = pose.y + ahead * math.sin(pose.theta)
        hit = np.nonzero(costmap.cost_at(xs, ys) >= INSCRIBED)[0]
        if hit.size:
            return f"the way is blocked: an obstacle {ahead[hit[0]]:.1f} m ahead leaves no safe way forward"
        return "the way is blocked: every way forward would touch an obstacle"

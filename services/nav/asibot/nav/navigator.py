"""The goal state machine: plan, follow, replan, recover, and tell the user how it goes.

Action semantics (docs/reference/navigation.md, 'Action semantics': actionlib's
SimpleActionServer): one goal at a time; `goto` answers at once with a goal id; a new goal
preempts the running one (its result is PREEMPTED); `cancel` ends it (CANCELED); it ends
SUCCEEDED when the robot stands on the goal within the controller's tolerances, or ABORTED
with a sentence that says why. Bad input (a NaN, a pose off the map, a goal in a wall) is
refused by `goto` with a sentence and changes nothing: the running goal, if any, goes on.

`step(now, pose, scan, odom)` is called at the control rate (10-20 Hz) with the localised
map pose, the latest scan (or None) and the odometry (for the current speeds); it updates the
costmap with the scan and returns the `Command` to send, or None when there is nothing to
send (no goal: the base belongs to whoever else drives it). Replanning: every
`replan_period`, and at once when the path ahead is blocked. Patience: a controller that
finds no safe way for `controller_patience`, a plan that fails, or no progress (0.5 m in
10 s, nav2's progress checker) starts the next recovery; when they are used up the goal is
aborted with what was tried. Localisation lost for `lost_timeout` makes the robot turn on the
spot to find where it is; a whole turn that does not find it aborts. Without a recent scan
(`seeing` false) the robot stands still, as move_base does when its costmap is not current:
it cannot see what came into its way; after `blind_timeout` the goal is aborted.
"""

from __future__ import annotations

import itertools
import math
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from asibot.messages import LaserScan
from asibot.nav.costmap import INSCRIBED, Costmap
from asibot.nav.errors import NavError, Unreachable
from asibot.nav.geometry import Pose, as_pose
from asibot.nav.local import LocalController
from asibot.nav.planner import GlobalPlanner, Path
from asibot.nav.recovery import Recovery, Spin, default_recoveries

IDLE, ACTIVE, SUCCEEDED, ABORTED, CANCELED, PREEMPTED = "idle", "active", "succeeded", "aborted", "canceled", "preempted"
TERMINAL = (SUCCEEDED, ABORTED, CANCELED, PREEMPTED)


class OdomLike(Protocol):
    vx: float
    wz: float


@dataclass(frozen=True)
class NavParams:
    replan_period: float = 2.0
    controller_patience: float = 3.0
    progress_distance: float = 0.5
    progress_timeout: float = 10.0
    #: s not localised (standing still) before the robot turns on the spot to find where it is
    lost_timeout: float = 2.0
    look_speed: float = 0.5            # rad/s: slow enough for each scan to be placed where it was taken
    look_timeout: float = 25.0         # s for that whole turn
    blocked_lookahead: float = 2.5     # m of path ahead checked against new obstacles
    nominal_speed: float = 0.35        # m/s for the ETA before the robot has moved
    #: A periodic replan takes a new way only if it is at most this much longer than what is
    #: left of the current one (m, or that share of it, whichever is more).
    switch_margin: float = 0.5
    switch_fraction: float = 0.1
    results_kept: int = 50
    #: s without a recent scan, standing still, before the goal is aborted
    blind_timeout: float = 10.0


@dataclass
class Command:
    vx: float
    wz: float


@dataclass
class NavStatus:
    goal_id: int | None = None
    state: str = IDLE
    place: str = ""
    goal: Pose | None = None
    text: str = "no goal"
    distance_remaining: float = 0.0
    eta: float = 0.0
    recoveries: int = 0
    started: float = 0.0
    path: Path | None = field(default=None, repr=False)


def goal_label(goal: Pose, place: str) -> str:
    return place or f"({goal.x:.2f}, {goal.y:.2f})"


class Navigator:
    def __init__(self, costmap: Costmap, planner: GlobalPlanner | None = None,
                 controller: LocalController | None = None,
                 recoveries: Callable[[], list[Recovery]] | None = None,
                 params: NavParams = NavParams()) -> None:
        self.costmap = costmap
        self.planner = planner or GlobalPlanner()
        self.controller = controller or LocalController()
        self.make_recoveries = recoveries or (lambda: default_recoveries(costmap.footprint))
        self.params = params
        self.status = NavStatus()
        self.results: OrderedDict[int, NavStatus] = OrderedDict()
        self._ids = itertools.count(1)
        self._reset_goal_state()

    def _reset_goal_state(self) -> None:
        self._recoveries: list[Recovery] = []
        self._recovery: Recovery | None = None
        self._recovery_index = 0
        self._tried: list[str] = []
        self._last_plan = -math.inf
        self._blocked_since: float | None = None
        self._progress_mark: tuple[float, Pose | None, float] = (0.0, None, math.inf)
        self._lost_since: float | None = None
        self._blind_since: float | None = None
        self._looking: Spin | None = None      # the turn made to find where the robot is
        self._need_plan = True
        self._send_stop = False

    # -------------------------------------------------------------------------- requests

    def goto(self, now: float, goal: object, place: str = "", pose: Pose | None = None) -> int:
        """Accept a new goal (preempting the running one) and return its id; NavError or
        Unreachable with a sentence when it cannot be a goal, and then nothing changes."""
        g = as_pose(goal, "goal")
        info = self.costmap.info
        label = goal_label(g, place)
        if not info.contains(g.x, g.y):
            raise NavError(f"The goal {label} ({g.x:.2f}, {g.y:.2f}) is outside the map ({info.bounds()}).")
        path = None
        if pose is not None:
            path = self.planner.plan(self.costmap, pose, g, label)   # raises with the reason
        else:
            self.planner.plan(self.costmap, g, g, label)              # at least: not in a wall
        if self.status.state == ACTIVE:
            old = self.status
            self._finish(PREEMPTED, f"the trip to {old.place or 'the goal'} was replaced by a new goal ({label})")
        gid = next(self._ids)
        self._reset_goal_state()
        self.controller.clear()
        self.status = NavStatus(goal_id=gid, state=ACTIVE, place=place, goal=g, started=now,
                                text=f"driving to {label}")
        self._recoveries = self.make_recoveries()
        if path is not None:
            self._set_path(now, path, pose)
        return gid

    def cancel(self, now: float, goal_id: int | None = None) -> NavStatus:
        """Cancel the running goal (or `goal_id` if it is the running one); the status after."""
        if self.status.state == ACTIVE and (goal_id is None or goal_id == self.status.goal_id):
            self._finish(CANCELED, f"stopped: the trip to {self.status.place or 'the goal'} was canceled")
        elif goal_id is not None and goal_id != self.status.goal_id and goal_id not in self.results:
            raise NavError(f"There is no goal {goal_id}; the last one is {self.status.goal_id}.")
        return self.status

    def result(self, goal_id: int) -> NavStatus:
        if goal_id == self.status.goal_id:
            return self.status
        if goal_id in self.results:
            return self.results[goal_id]
        raise NavError(f"There is no goal {goal_id} (only the last {self.params.results_kept} are kept).")

    # ------------------------------------------------------------------------------ loop

    def step(self, now: float, pose: Pose, scan: LaserScan | None, odom: OdomLike | None,
             localised: bool = True, scan_pose: Pose | None = None, seeing: bool = True) -> Command | None:
        """`scan_pose`: where the robot was when the scan was taken (default `pose`); a scan
        placed at the pose of its arrival smears walls across doorways while the robot turns.
        `seeing`: a recent scan came (the costmap shows what is around the robot now)."""
        finite = all(math.isfinite(v) for v in pose)
        at = scan_pose if scan_pose is not None else pose
        if scan is not None and finite and all(math.isfinite(v) for v in at):
            self.costmap.update_scan(at, scan, now)
        goal = self.status.goal
        if self.status.state != ACTIVE or goal is None:   # an active status always has its goal
            if self._send_stop:
                self._send_stop = False
                return Command(0.0, 0.0)
            return None
        velocity = (float(odom.vx), float(odom.wz)) if odom is not None else (0.0, 0.0)
        label = goal_label(goal, self.status.place)
        if not seeing:
            return self._wait_to_see(now, pose, label)
        self._blind_since = None
        # localisation
        if not (localised and finite):
            return self._find_where_i_am(now, pose, label, finite)
        self._lost_since = None
        if self._looking is not None:                # found: on with the trip, by a new plan
            self._looking = None
            self._need_plan = True
            self._progress_mark = (now, pose, math.inf)
        # recovering
        if self._recovery is not None:
            return self._recover(now, pose, label)
        # planning
        forced = self._need_plan or self._path_blocked(pose)
        if forced or now - self._last_plan >= self.params.replan_period:
            try:
                path = self.planner.plan(self.costmap, pose, goal, label)
            except NavError as exc:
                return self._abort(f"could not reach {label}: {exc.message}")
            except Unreachable as exc:
                return self._start_recovery(now, pose, label, exc.message.rstrip("."))
            if forced or self._better(path, pose):
                self._set_path(now, path, pose)
            else:
                self._last_plan = now
        ctl = self.controller.compute(pose, velocity, self.costmap)
        self.status.distance_remaining = ctl.remaining
        if ctl.status == "arrived":
            self._finish(SUCCEEDED, f"arrived at {label}")
            return Command(0.0, 0.0)
        if ctl.status == "blocked":
            if self._blocked_since is None:
                self._blocked_since = now
                self._need_plan = True          # first, try another way around
            elif now - self._blocked_since >= self.params.controller_patience:
                return self._start_recovery(now, pose, label, ctl.text)
            self.status.text = f"waiting: {ctl.text} on the way to {label}"
            return Command(0.0, 0.0)
        self._blocked_since = None
        # progress
        t0, p0, r0 = self._progress_mark
        if p0 is None or pose.distance(p0) >= self.params.progress_distance or ctl.remaining <= r0 - self.params.progress_distance \
                or ctl.remaining < 0.3:
            self._progress_mark = (now, pose, ctl.remaining)
        elif now - t0 > self.params.progress_timeout:
            return self._start_recovery(now, pose, label, f"no progress for {self.params.progress_timeout:.0f} s")
        speed = max(abs(velocity[0]), self.params.nominal_speed if now - self.status.started < 2 else 0.1)
        self.status.eta = ctl.remaining / speed
        # a moving controller says what it does only when it is not simply following the path
        self.status.text = f"{ctl.text} ({label})" if ctl.text else f"driving to {label}, {ctl.remaining:.1f} m left"
        return Command(ctl.vx, ctl.wz)

    # --------------------------------------------------------------------------- helpers

    def _set_path(self, now: float, path: Path, pose: Pose | None) -> None:
        self.controller.set_path(path)
        self.status.path = path
        self.status.distance_remaining = path.length
        self._last_plan = now
        self._need_plan = False
        if self._progress_mark[1] is None and pose is not None:
            self._progress_mark = (now, pose, path.length)

    def _better(self, path: Path, pose: Pose) -> bool:
        """Whether a periodic replan should replace the path being followed (which is still
        free): only when it is not much longer than what is left of it. Without this the robot
        turned back and forth between the two ways around the kitchen table, as chairs seen a
        moment ago made one or the other a little dearer."""
        current = self.status.path
        if current is None:
            return True
        pts = current.points
        i = int(np.argmin(np.hypot(pts[:, 0] - pose.x, pts[:, 1] - pose.y)))
        seg = np.hypot(*np.diff(pts[i:], axis=0).T) if len(pts) - i > 1 else np.zeros(0)
        left = float(seg.sum() + math.hypot(pts[i, 0] - pose.x, pts[i, 1] - pose.y))
        return path.length <= left + max(self.params.switch_margin, self.params.switch_fraction * left)

    def _path_blocked(self, pose: Pose) -> bool:
        path = self.status.path
        if path is None:
            return True
        pts = path.points
        d = np.hypot(pts[:, 0] - pose.x, pts[:, 1] - pose.y)
        i = int(np.argmin(d))
        n = int(self.params.blocked_lookahead / max(1e-3, path.length / max(1, len(pts) - 1)))
        ahead = pts[i:i + max(1, n)]
        costs = self.costmap.cost_at(ahead[:, 0], ahead[:, 1])
        # the last cells may be the goal's own inscribed band (a goal close to the fridge)
        far = np.hypot(ahead[:, 0] - path.goal.x, ahead[:, 1] - path.goal.y) > 0.3
        return bool(((costs >= INSCRIBED) & far).any())

    def _start_recovery(self, now: float, pose: Pose, label: str, why: str) -> Command:
        if self._recovery_index >= len(self._recoveries):
            tried = ", ".join(dict.fromkeys(self._tried)) or "nothing"
            return self._abort(f"could not reach {label}: {why.rstrip('.')}; I tried {tried}, without success")
        self._recovery = self._recoveries[self._recovery_index]
        self._recovery_index += 1
        self._tried.append(self._recovery.name)
        self.status.recoveries += 1
        self._why = why
        self._recovery.start(now, pose, self.costmap)
        return self._recover(now, pose, label)

    def _recover(self, now: float, pose: Pose, label: str) -> Command:
        assert self._recovery is not None
        rec = self._recovery
        step = rec.step(now, pose, self.costmap)
        self.status.text = (f"{self._why} on the way to {label}; {rec.name} "
                            f"(recovery {self._recovery_index} of {len(self._recoveries)})")
        if step.done:
            self._recovery = None
            self._need_plan = True
            self._blocked_since = None
            self._progress_mark = (now, pose, math.inf)
            if step.failed:
                self._tried[-1] = f"{rec.name} ({step.failed})"
            return Command(0.0, 0.0)
        return Command(step.vx, step.wz)

    def _wait_to_see(self, now: float, pose: Pose, label: str) -> Command:
        """No recent scan: stand still (a turn or a recovery too), for `blind_timeout`, then
        abort. The progress clock restarts once scans come back: the wait was not the way's."""
        self._blind_since = now if self._blind_since is None else self._blind_since
        blind = now - self._blind_since
        if blind >= self.params.blind_timeout:
            return self._abort(f"could not reach {label}: I could not see obstacles for {blind:.0f} s "
                               "(no scan: is the perception service running?)")
        self._progress_mark = (now, pose, math.inf)
        self._blocked_since = None
        self.status.text = f"waiting: I cannot see obstacles (no scan) on the way to {label}"
        return Command(0.0, 0.0)

    def _find_where_i_am(self, now: float, pose: Pose, label: str, finite: bool) -> Command:
        """The filter spread out on the way (scans that stopped fitting: something not on the map
        in view, a wheel that slipped). It updates only while the robot moves, so after
        `lost_timeout` standing still the robot turns on the spot, as `localize` does, until the
        scans fit again; a whole turn that does not find it aborts the goal."""
        self._lost_since = now if self._lost_since is None else self._lost_since
        if now - self._lost_since < self.params.lost_timeout:
            return Command(0.0, 0.0)
        gave_up = "Set my position on the map (or drive me to the charging station) and try again."
        if not finite:              # no pose to turn about, or to check the turn against the costmap
            return self._abort(f"could not reach {label}: I am not sure where I am any more. {gave_up}")
        if self._looking is None:
            self._looking = Spin(speed=self.params.look_speed, timeout=self.params.look_timeout,
                                 name="turning on the spot to find where I am")
            self._looking.start(now, pose, self.costmap)
            self.controller.clear()
        step = self._looking.step(now, pose, self.costmap)
        self.status.text = f"I am not sure where I am on the way to {label}; {self._looking.name}"
        if step.done:
            why = f" ({step.failed})" if step.failed else ""
            return self._abort(f"could not reach {label}: I am not sure where I am any more, even after turning "
                               f"on the spot to look{why}. {gave_up}")
        return Command(step.vx, step.wz)

    def _abort(self, text: str) -> Command:
        self._finish(ABORTED, text)
        self._send_stop = False
        return Command(0.0, 0.0)

    def _finish(self, state: str, text: str) -> None:
        self.status.state = state
        self.status.text = text
        self.status.eta = 0.0
        if state == SUCCEEDED:
            self.status.distance_remaining = 0.0
        self.controller.clear()
        self._recovery = self._looking = None
        self._send_stop = state in (CANCELED, PREEMPTED)
        if self.status.goal_id is not None:
            self.results[self.status.goal_id] = self.status
            while len(self.results) > self.params.results_kept:
                self.results.popitem(last=False)

"""One robot's navigation in one object: where it is, where it goes, and how a person drives it.

The nav service moves messages between the bus and a `Pilot`; tests drive a `Pilot` from a
simulator. It knows nothing of Zenoh and takes the time as an argument.

- Where it is: AMCL on odometry and scans (`Amcl`). The filter updates when a new scan has
  come and the robot moved enough; between updates the pose is carried by odometry. The
  robot counts as localised while the filter's main cluster is tighter than `localised_std`,
  or while it holds its last trusted pose against an estimate that leapt (`Amcl.holding`).
  Odometry that goes back in time or leaps (`odometry_jump`: a base driver or the sim that
  restarted, the robot carried off) means the robot no longer knows where it is: the filter
  looks everywhere (so it is not localised, never "localised" metres off), whatever drives
  ends, and the person is told. `localize` (asked for) then turns in place, up to twice, until
  the filter has found the robot, and says how that went.
- Where it goes: goals through the `Navigator` (action semantics: `goto` answers a goal id at
  once, a newer goal preempts, `cancel`, `result`), to a named place (`Places`) or a pose.
- How a person drives it: the thesis's primitives (`Primitives`), closed-loop on odometry.
- Mapping a new home (`Mapper`): `map_start` builds a new map from the scans while the person
  drives (primitives only: goals are refused, there is no map to plan on); the pose is then
  the mapper's. `map_grid` is the map so far; `use_map` switches AMCL, the costmap and the
  planner to a new map at the robot's pose on it.

Goals and primitives are exclusive: a primitive cancels the running goal and a goal stops the
running primitive, so one thing at a time drives the base. The emergency stop ends both and
refuses new ones until it is released; nothing resumes by itself after it. Odometry older than
`input_timeout` stops whatever runs (the base driver is gone: no closed loop without it); a
scan older than that counts as no scan (a primitive and a goal stand still and wait: they
cannot see).

Every end of a goal or a primitive is told through `on_event(level, code, text)`.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from asibot import messages as m
from asibot.errors import RpcError
from asibot.nav.amcl import Amcl, AmclParams
from asibot.nav.costmap import Costmap
from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose, as_pose, wrap
from asibot.nav.grid import OccupancyGrid
from asibot.nav.mapping import Mapper, MapperParams
from asibot.nav.navigator import ABORTED, ACTIVE, CANCELED, PREEMPTED, SUCCEEDED, Command, Navigator, NavStatus
from asibot.nav.places import Places
from asibot.nav.primitives import Primitives

EventSink = Callable[[str, str, str], None]

#: Which event level and code the end of a goal is told with.
_GOAL_ENDS = {SUCCEEDED: ("info", "goal_succeeded"), ABORTED: ("warning", "goal_aborted"),
              CANCELED: ("info", "goal_canceled"), PREEMPTED: ("info", "goal_preempted")}


@dataclass(frozen=True)
class PilotParams:
    input_timeout: float = 0.5        # s: older odometry or scans are not used
    localised_std: float = 0.5        # m and rad: the filter's spread below which it can drive
    particles_shown: int = 300        # particles sent with each pose, for a map view
    odometry_kept: int = 100          # readings kept to place a late scan (5 s at 20 Hz)
    #: m and rad between two odometry readings past which it is a restart or a leap, not motion
    #: (the P3-AT covers 0.06 m and 0.15 rad between two 20 Hz readings at full speed)
    odometry_jump: tuple[float, float] = (0.5, 1.0)
    finding_turns: int = 2            # full turns in place `localize` makes at most to find the robot


@dataclass
class _Reading:
    pose: Pose
    vx: float
    wz: float
    at: float          # our clock, s
    stamp: int         # the producer's, ns


def odometry_at(history: "deque[_Reading]", stamp: int, slack_ns: int = 60_000_000) -> Pose | None:
    """The odometry pose at `stamp` (ns), interpolated between the readings around it: a scan
    is matched with where the robot was when its images were taken, not where it is when the
    scan arrives (100-200 ms later on a loaded machine, 0.1-0.2 rad while turning). None when
    `stamp` is older than the history, or newer than its last reading by more than `slack_ns`."""
    if not history:
        return None
    last = history[-1]
    if stamp >= last.stamp:
        return last.pose if stamp - last.stamp <= slack_ns else None
    if stamp < history[0].stamp:
        return None
    stamps = [r.stamp for r in history]
    i = bisect.bisect_right(stamps, stamp)
    a, b = history[i - 1], history[i]
    f = (stamp - a.stamp) / max(1, b.stamp - a.stamp)
    return Pose(a.pose.x + f * (b.pose.x - a.pose.x), a.pose.y + f * (b.pose.y - a.pose.y),
                a.pose.theta + f * wrap(b.pose.theta - a.pose.theta))


class Pilot:
    def __init__(self, grid: OccupancyGrid, places: Places, start: Pose, *,
                 amcl_params: AmclParams = AmclParams(), navigator: Navigator | None = None,
                 primitives: Primitives | None = None, params: PilotParams = PilotParams(),
                 on_event: EventSink = lambda level, code, text: None, seed: int | None = None) -> None:
        self.grid, self.places, self.params = grid, places, params
        self.amcl = Amcl(grid, amcl_params, seed=seed)
        self.amcl.set_pose(start)
        self.navigator = navigator or Navigator(Costmap(grid))
        self.primitives = primitives or Primitives()
        self.on_event = on_event
        self._rng = np.random.default_rng(seed)
        self._odom: _Reading | None = None
        self._history: deque[_Reading] = deque(maxlen=params.odometry_kept)
        self._scan: tuple[m.LaserScan, float] | None = None
        self._scan_used = True           # the newest scan went into the filter already
        self._scan_odom: Pose | None = None   # the odometry pose where the newest scan was taken
        self._driving = False            # a primitive ran at the last tick
        self._halt = False               # a primitive was stopped: send the base one zero
        self._told: int | None = None    # the goal whose end was told
        #: The latest thing that drove the base, "goal" or "drive", and how the latest drive
        #: ended (a goal's end is the navigator's): what `status_message` reports.
        self._latest = "goal"
        self._drive_state = "idle"
        self.estopped = False
        self.mapper_params = MapperParams(resolution=grid.info.resolution)
        self.mapper: Mapper | None = None   # the latest map being built (kept after map_stop, to save)
        self.mapping = False
        #: Why the robot lost track of where it is ("" when it has not, or found itself since).
        self.lost = ""
        self._finding = 0                # turns in place left while `localize` looks for the robot
        self._looking = False            # a turn made to find the robot runs

    # ------------------------------------------------------------------------- inputs

    def odometry(self, now: float, msg: m.Odometry) -> None:
        pose = Pose(msg.x, msg.y, msg.theta)
        if all(math.isfinite(v) for v in (*pose, msg.vx, msg.wz)):
            self._odom = _Reading(pose, msg.vx, msg.wz, now, msg.stamp)
            last = self._history[-1] if self._history else None
            if last is not None and msg.stamp <= last.stamp:
                self._history.clear()       # a restarted base driver, or a clock step
            if last is not None and (msg.stamp < last.stamp or self._leapt(last.pose, pose)):
                self._lose_track(now, "the base's odometry started again (its driver or the simulation "
                                      "restarted, or the robot was carried)")
            self._history.append(self._odom)

    def _leapt(self, before: Pose, after: Pose) -> bool:
        metres, radians = self.params.odometry_jump
        return (math.hypot(after.x - before.x, after.y - before.y) > metres
                or abs(wrap(after.theta - before.theta)) > radians)

    def _lose_track(self, now: float, why: str) -> None:
        """The robot may be anywhere: look everywhere, end what drives, tell the person."""
        self.lost = why
        self._end_everything(now, f"I lost track of where I am: {why}")
        if self.mapping:
            self.on_event("warning", "lost", f"I lost track of where I am: {why}. The map being made "
                                             "no longer fits; stop mapping (map_stop) and start again.")
            return
        self.amcl.global_localization()
        self.amcl.odometry_restarted()
        self._scan_used = True          # a scan taken before the restart cannot be placed
        self.on_event("warning", "lost", f"I lost track of where I am: {why}. Ask me to find where I am "
                                         "(I turn in place), or set my position on the map.")

    def scan(self, now: float, msg: m.LaserScan) -> None:
        self._scan = (msg, now)
        self._scan_used = False

    def estop(self, now: float, engaged: bool) -> None:
        """Engaged: end the goal and the primitive now; released: nothing moves by itself."""
        self.estopped = engaged
        if engaged:
            self._end_everything(now, "the emergency stop was engaged")

    # ------------------------------------------------------------------------ queries

    def _fresh_odom(self, now: float) -> _Reading | None:
        o = self._odom
        return o if o is not None and now - o.at <= self.params.input_timeout else None

    def _fresh_scan(self, now: float) -> m.LaserScan | None:
        s = self._scan
        return s[0] if s is not None and now - s[1] <= self.params.input_timeout else None

    @property
    def localised(self) -> bool:
        if self.mapping:
            return True          # the map is drawn around where the mapper says the robot is
        est = self.amcl.estimate
        if est is None or self.amcl.searching:
            return False
        return self.amcl.holding or est.within(self.params.localised_std)

    def pose(self) -> Pose:
        """The map pose now (the filter's estimate, or the mapper's, carried forward by odometry)."""
        return self._pose_at(self._odom.pose) if self._odom is not None else self.amcl.current_estimate().pose

    def _pose_at(self, odom: Pose) -> Pose:
        if self.mapping and self.mapper is not None:
            return self.mapper.pose(odom)
        return self.amcl.pose(odom)

    def pose_message(self) -> m.NavPose:
        p = self.pose()
        if self.mapping:
            return m.NavPose(x=p.x, y=p.y, theta=p.theta, covariance=[0.0] * 9, localised=True,
                             particles=np.zeros((0, 3), np.float32))
        est = self.amcl.current_estimate()
        n = len(self.amcl.poses)
        pick = self._rng.choice(n, size=min(n, self.params.particles_shown), replace=False)
        return m.NavPose(x=p.x, y=p.y, theta=p.theta, covariance=est.covariance.reshape(-1).tolist(),
                         localised=self.localised, particles=self.amcl.poses[pick].astype(np.float32))

    def status(self) -> NavStatus:
        return self.navigator.status

    def status_message(self) -> m.NavStatus:
        """The latest goal's or drive's state and sentence: a drive is `active`, then
        `succeeded` (done), `aborted` (an obstacle, no scan) or `canceled` (stopped)."""
        s, prim = self.navigator.status, self.primitives
        state, text = s.state, s.text
        if self._latest == "drive":
            state, text = ("active" if prim.active else self._drive_state), prim.last_text
        return m.NavStatus(goal_id=s.goal_id or 0, state=state, text=text, place=s.place,
                           goal=list(s.goal) if s.goal is not None else [], distance=float(s.distance_remaining),
                           eta=float(s.eta), recoveries=s.recoveries, driving=prim.last_text if prim.active else "",
                           localised=self.localised, speed=prim.settings.speed, width=prim.settings.width,
                           mapping=self.mapping_text())

    def mapping_text(self) -> str:
        """'mapping: 42.0 m² mapped from 120 scans', or how a stopped map waits; '' without one."""
        if self.mapper is None:
            return ""
        if self.mapping:
            return f"mapping: {self.mapper.summary()}"
        return f"mapping stopped: {self.mapper.summary()}, not in use (map_save NAME saves it)"

    # ----------------------------------------------------------------------- requests

    def _may_move(self, what: str) -> None:
        if self.estopped:
            raise RpcError("estop", f"The emergency stop is engaged; release it before {what}.")

    def goto(self, now: float, place: object = None, pose: object = None) -> dict:
        """A new goal, to a named place or to a pose [x, y, theta]; its id at once."""
        if (place is None) == (pose is None):
            raise NavError("Say where to go: a place name ({\"place\": \"fridge\"}) or a pose "
                           "({\"pose\": [x, y, theta]}, m and rad), not both.")
        self._may_move("sending the robot somewhere")
        if place is not None:
            found = self.places.get(place)
            label, goal = found.name, found.pose
        else:
            label, goal = "", as_pose(pose, "goal")
        return self._goto(now, goal, label)

    def recall_position(self, now: float) -> dict:
        """The thesis's recall: drive back to where `save_position` was called."""
        self._may_move("sending the robot back")
        return self._goto(now, self.places.recall_position(), "the saved position")

    def _goto(self, now: float, goal: Pose, label: str) -> dict:
        if self.mapping:
            raise RpcError("busy", "I am mapping, so there is no map to plan on yet. Drive me with the primitives; "
                                   "save the map (map_save NAME with use) or stop mapping (map_stop) first.")
        if not self.localised:
            why = f" ({self.lost})" if self.lost else ""
            raise RpcError("unavailable", f"I am not sure where I am{why}, so I cannot plan a way there. Ask me "
                                          "to find where I am (I turn in place), or set my position on the map, "
                                          "and try again.")
        if self._fresh_odom(now) is None:
            raise RpcError("unavailable", "No odometry from the base: is the base driver (or the sim) running?")
        before = self.navigator.status
        gid = self.navigator.goto(now, goal, label, self.pose())   # raises, changing nothing, when it cannot
        if before.state == PREEMPTED:
            self._tell(before)
        if self.primitives.active:
            self.primitives.stop(f"stopped: replaced by the trip to {label or 'the goal'}")
            self._driving, self._drive_state = False, CANCELED
        self._latest = "goal"
        s = self.navigator.status
        return {"goal_id": gid, "place": label, "goal": list(goal), "text": s.text}

    def cancel(self, now: float, goal_id: int | None = None) -> dict:
        s = self.navigator.cancel(now, goal_id)
        self._tell_goal_end()
        return _result(s)

    def result(self, goal_id: int) -> dict:
        return _result(self.navigator.result(goal_id))

    def drive(self, now: float, name: str, continuous: bool = False, amount: float | None = None) -> dict:
        """Start a primitive (or `stop`), named as asibot.driving spells it; ends the running goal first."""
        if name == "stop":
            return self.stop(now)
        self._may_move("driving")
        odom = self._fresh_odom(now)
        if odom is None:
            raise RpcError("unavailable", "No odometry from the base: is the base driver (or the sim) running?")
        text = self.primitives.start(now, name, odom.pose, continuous, amount)   # raises on a bad name
        if self.navigator.status.state == ACTIVE:
            self.navigator.cancel(now)
            self._tell_goal_end()
        self._driving, self._latest = True, "drive"
        return {"text": text}

    def stop(self, now: float) -> dict:
        """Stop whatever drives the base: the goal and the primitive."""
        self._end_everything(now, "")
        return {"text": "stopped"}

    def taken_over(self, now: float, who: str) -> None:
        """A person took the base (a joystick, a teleop program: asibot.safety.ownership): end
        what nav drives, with a sentence, and send nothing more (the base is theirs)."""
        self._end_everything(now, f"{who} took over the base (driven by hand); ask me again once they stop")
        self._halt = False

    def settings(self, change: str | None) -> dict:
        """One level of the primitives' speed or width (asibot.driving.CHANGES: faster, slower,
        wider, narrower); None: the levels now."""
        prim = self.primitives
        actions = {"faster": prim.faster, "slower": prim.slower, "wider": prim.wider, "narrower": prim.narrower}
        text = actions[change]() if change is not None else f"speed {prim.settings.speed}, width {prim.settings.width}"
        return {"text": text, "speed": prim.settings.speed, "width": prim.settings.width}

    def set_pose(self, now: float, pose: object, cov: Sequence[float] | None = None) -> dict:
        """"I am here": restart the filter around `pose` (any running goal ends: the way there was
        planned from a pose that was wrong); `cov`: the variances [xx, yy, theta-theta] (m^2,
        m^2, rad^2) of the guess, the filter's defaults when None."""
        p = as_pose(pose, "pose")
        variances = (float(cov[0]), float(cov[1]), float(cov[2])) if cov is not None else None
        self.amcl.set_pose(p, variances)   # raises on a pose off the map, changing nothing
        self._end_everything(now, "my position was set again")
        self.lost = ""
        self._scan_used = False      # the next scan corrects the new guess at once
        return {"pose": list(p)}

    def localize(self, now: float) -> dict:
        """Forget where the robot is, look everywhere (amcl's global localisation) and turn in
        place, up to `finding_turns` times, until the filter has found the robot."""
        self._may_move("finding where I am")
        odom = self._fresh_odom(now)
        if odom is None or self._fresh_scan(now) is None:
            raise RpcError("unavailable", "I cannot look for where I am without odometry and a scan from the "
                                          "base: are the base driver (or the sim) and perception running?")
        self.amcl.global_localization()
        self._end_everything(now, "localisation started again")
        self._scan_used = False
        self._finding = self.params.finding_turns
        self._turn_to_find(now, odom.pose)
        return {"text": "looking for where I am: turning in place"}

    def _turn_to_find(self, now: float, odom: Pose) -> None:
        self._finding -= 1
        self.primitives.start(now, "turn left", odom, amount=2 * math.pi)
        self._driving, self._latest, self._looking = True, "drive", True

    def _found(self, now: float, odom: Pose, done: bool) -> bool:
        """A turn made to find the robot ended: True when another turn starts."""
        self._looking = False
        if self.localised:
            self._finding, self.lost = 0, ""
            self.on_event("info", "localised", "I know where I am again.")
            return False
        if done and self._finding > 0:
            self._turn_to_find(now, odom)
            return True
        self._finding = 0
        self.on_event("warning", "not_localised", "I could not find where I am"
                      + (": the turn was stopped" if not done else "")
                      + ". Set my position on the map, or drive me somewhere I can see more and ask again.")
        return False

    # ------------------------------------------------------------------------ mapping

    def map_start(self, now: float) -> dict:
        """Start a new map where the robot believes it is (its frame is the current one: in a
        new home, the initial pose). A running goal ends; a running drive goes on."""
        if self.mapping and self.mapper is not None:
            raise RpcError("busy", f"I am already mapping ({self.mapper.summary()}); save the map (map_save NAME) "
                                   "or stop mapping (map_stop) first.")
        odom = self._fresh_odom(now)
        if odom is None:
            raise RpcError("unavailable", "No odometry from the base: is the base driver (or the sim) running?")
        start = self.pose()
        self._end_goal(now, "mapping started")
        self.mapper = Mapper(start, self.mapper_params, odom=odom.pose)
        self.mapping = True
        self._scan_used = False
        text = "mapping: drive me slowly through every room and back to the start, then save the map"
        self.on_event("info", "mapping_started", text)
        return {"text": text, "pose": list(start)}

    def map_stop(self, now: float) -> dict:
        """Stop mapping; the map is kept to be saved until the next map_start. Localisation
        goes back to the map in use."""
        if not self.mapping or self.mapper is None:
            raise RpcError("bad_request", "I am not mapping; start with map_start.")
        self.mapping = False
        self._scan_used = False
        return {"text": self.mapping_text()}

    def map_grid(self) -> OccupancyGrid:
        """The map built so far (during mapping or after map_stop), as an occupancy grid."""
        if self.mapper is None:
            raise NavError("Nothing has been mapped: start mapping (map_start) and drive me around first.")
        if self.mapper.stats.scans == 0:
            raise RpcError("unavailable", "No scan has been mapped yet: is the scan (the perception service) running?")
        return self.mapper.to_grid()

    def use_map(self, now: float, grid: OccupancyGrid) -> dict:
        """Localise and navigate on `grid` from now on, starting at the robot's pose on it (the
        mapper's, when a map was built: also after map_stop, when AMCL went back to the old
        map). Refused, changing nothing, when that pose is off the map."""
        pose = self.mapper.pose(self._odom.pose) if self.mapper is not None and self._odom is not None else self.pose()
        amcl = Amcl(grid, self.amcl.params, seed=int(self._rng.integers(2 ** 31)))
        amcl.set_pose(pose, (0.05 ** 2, 0.05 ** 2, 0.05 ** 2))   # NavError when the pose is off the map
        self._end_goal(now, "the map changed")
        old = self.navigator.costmap
        self.grid, self.amcl = grid, amcl
        self.navigator.costmap = Costmap(grid, old.footprint, old.params)
        self.places.info = grid.info
        self.mapping, self.mapper = False, None
        self._scan_used = False
        text = f"now on the new map ({grid.info.bounds()}), at {pose}"
        self.on_event("info", "map_changed", text)
        return {"text": text, "pose": list(pose)}

    def _end_goal(self, now: float, why: str) -> None:
        if self.navigator.status.state == ACTIVE:
            self.navigator.cancel(now)
            if why:
                self.navigator.status.text = f"stopped: {why}"
            self._tell_goal_end()

    def _end_everything(self, now: float, why: str) -> None:
        # A stopped primitive says "stop" to the base at the next cycle (the navigator does so
        # for goals): silence alone stops the base only at its watchdog, later, and with a
        # warning the user did not cause.
        self._halt = self._halt or self.primitives.active or self._driving
        self._looking, self._finding = False, 0
        self._end_goal(now, why)
        if self.primitives.active:
            self.primitives.stop(f"stopped: {why}" if why else "stopped")
            self._driving, self._drive_state = False, CANCELED
            if why:
                self.on_event("warning", "drive_stopped", self.primitives.last_text)

    # --------------------------------------------------------------------------- loop

    def tick(self, now: float) -> Command | None:
        """One control cycle: what to send to the base now, or None to send nothing (nothing
        drives it: another program may)."""
        odom = self._fresh_odom(now)
        scan = self._fresh_scan(now)
        if odom is None:
            if self.navigator.status.state == ACTIVE or self.primitives.active:
                self._end_everything(now, "no odometry from the base for "
                                          f"{self.params.input_timeout:g} s (is the base driver running?)")
                return Command(0.0, 0.0)
            return None
        if scan is not None and not self._scan_used:
            self._scan_used = True
            self._scan_odom = odometry_at(self._history, scan.stamp)
            if self._scan_odom is not None and self.mapping and self.mapper is not None:
                try:
                    self.mapper.update(self._scan_odom, scan)
                except NavError:
                    pass         # a scan the mapper cannot use is left out; the next one comes
            elif self._scan_odom is not None:
                self.amcl.update(self._scan_odom, scan)
        if self.estopped:
            return None
        if self._halt and not self.primitives.active and self.navigator.status.state != ACTIVE:
            self._halt = False
            return Command(0.0, 0.0)
        self._halt = False
        if self.primitives.active or self._driving:
            motion = self.primitives.step(now, odom.pose, scan)
            if motion.active:
                return Command(motion.vx, motion.wz)
            self._driving = False
            done = motion.done
            self._drive_state = SUCCEEDED if done else ABORTED
            if self._looking:
                if self._found(now, odom.pose, done):
                    return Command(0.0, 0.0)
            else:
                self.on_event("info" if done else "warning", "drive_done" if done else "drive_stopped", motion.text)
            return Command(0.0, 0.0)
        if self.lost and self.localised:          # found while the person drove it
            self.lost = ""
            self.on_event("info", "localised", "I know where I am again.")
        # the costmap takes a scan only where it was taken (a scan that cannot be placed waits)
        placed: m.LaserScan | None = None
        scan_pose: Pose | None = None
        if scan is not None and self._scan_odom is not None:
            placed, scan_pose = scan, self._pose_at(self._scan_odom)
        cmd = self.navigator.step(now, self.pose(), placed, odom, localised=self.localised, scan_pose=scan_pose,
                                  seeing=scan is not None)
        self._tell_goal_end()
        return cmd

    def _tell_goal_end(self) -> None:
        self._tell(self.navigator.status)

    def _tell(self, s: NavStatus) -> None:
        """Tell the end of goal `s` once."""
        if s.goal_id is not None and s.state in _GOAL_ENDS and self._told != s.goal_id:
            self._told = s.goal_id
            level, code = _GOAL_ENDS[s.state]
            self.on_event(level, code, s.text)


def _result(s: NavStatus) -> dict:
    return {"goal_id": s.goal_id or 0, "state": s.state, "text": s.text, "place": s.place,
            "distance": float(s.distance_remaining), "recoveries": s.recoveries}

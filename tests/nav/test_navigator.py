"""The navigator end to end in the tiny simulator: AMCL in the loop, judged by ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asibot.nav.amcl import Amcl
from asibot.nav.costmap import INSCRIBED, LETHAL, Costmap
from asibot.nav.errors import NavError, Unreachable
from asibot.nav.geometry import Pose
from asibot.nav.local import LocalController
from asibot.nav.navigator import ABORTED, ACTIVE, CANCELED, IDLE, PREEMPTED, SUCCEEDED, Navigator
from asibot.nav.planner import GlobalPlanner, Path

from .tinysim import Harness, TinySim

XY_TOL, YAW_TOL = 0.25, 0.25


def make(apartment, start: Pose, seed: int = 3) -> Harness:
    sim = TinySim(apartment.grid, pose=start, odom=Pose(0.0, 0.0, 0.0), seed=seed)
    amcl = Amcl(apartment.grid, seed=seed)
    amcl.set_pose(start)
    h = Harness(sim, amcl, Navigator(Costmap(apartment.grid)))
    h.localise()
    return h


def on_goal(sim: TinySim, goal: Pose) -> bool:
    return sim.pose.distance(goal) <= XY_TOL and abs(math.remainder(sim.pose.theta - goal.theta, 2 * math.pi)) <= YAW_TOL


@pytest.mark.slow
def test_reaches_every_named_place(apartment, world_places):
    h = make(apartment, world_places.get("charging station").pose)
    for name in ("fridge", "desk", "shelf", "charging station"):
        goal = world_places.get(name).pose
        gid = h.nav.goto(h.now, goal, name, h.pose())
        assert h.nav.status.state == ACTIVE and h.nav.status.text.startswith(f"driving to {name}")
        h.run(lambda: h.nav.status.state != ACTIVE, limit=90.0)
        status = h.nav.result(gid)
        assert status.state == SUCCEEDED, status.text
        assert status.text == f"arrived at {name}"
        assert on_goal(h.sim, goal), f"{name}: at {h.sim.pose}, goal {goal}"
        assert not h.sim.collided
    speeds = np.array(h.commands)
    assert np.abs(speeds[:, 0]).max() <= h.nav.controller.limits.max_vx + 1e-9
    assert np.abs(speeds[:, 1]).max() <= h.nav.controller.limits.max_wz + 1e-9


@pytest.mark.slow
def test_avoids_a_box_that_is_not_on_the_map(apartment, world_places):
    start, fridge = world_places.get("charging station").pose, world_places.get("fridge").pose
    h = make(apartment, start)
    first = GlobalPlanner().plan(h.nav.costmap, start, fridge)
    # a box on the planned path across the living room, unknown to the map
    mid = first.points[np.argmin(np.abs(first.points[:, 0] - 2.5))]
    box = (mid[0] - 0.2, mid[1] - 0.2, mid[0] + 0.2, mid[1] + 0.2)
    h.sim.add_box(*box)
    assert (h.nav.costmap.cost_at(mid[0], mid[1]) < INSCRIBED)
    gid = h.nav.goto(h.now, fridge, "fridge", h.pose())
    h.run(lambda: h.nav.status.state != ACTIVE, limit=90.0)
    assert h.nav.result(gid).state == SUCCEEDED, h.nav.status.text
    assert on_goal(h.sim, fridge) and not h.sim.collided
    xs, ys = np.meshgrid(np.linspace(box[0], box[2], 9), np.linspace(box[1], box[3], 9))
    assert (h.nav.costmap.cost_at(xs, ys) == LETHAL).sum() >= 5      # its sides, seen by the scan
    path = h.nav.status.path
    near = np.hypot(path.points[:, 0] - mid[0], path.points[:, 1] - mid[1]).min()
    assert near > 0.45                                              # the last plan went around it


def test_a_goal_inside_a_wall_fails_with_a_sentence(apartment, world_places):
    h = make(apartment, world_places.get("charging station").pose)
    with pytest.raises(Unreachable, match=r"inside an obstacle; the nearest free spot is \(") as err:
        h.nav.goto(h.now, Pose(5.0, 2.0, 0.0), "the wall", h.pose())
    assert err.value.code == "unreachable"
    assert h.nav.status.state == IDLE and h.nav.step(h.now, h.pose(), None, None) is None


def test_bad_goals_change_nothing(apartment, world_places):
    h = make(apartment, world_places.get("charging station").pose)
    gid = h.nav.goto(h.now, world_places.get("shelf").pose, "shelf", h.pose())
    for _ in range(10):
        h.step()
    before = (h.nav.status.goal_id, h.nav.status.state, h.nav.status.goal)
    for bad, words in (((math.nan, 1.0, 0.0), "x must be a finite number"),
                       ((1.0, 2.0), "three numbers"),
                       ((50.0, 1.0, 0.0), "outside the map"),
                       ("fridge", "three numbers"),
                       ((1.0, 1e300, 0.0), "not a place in a home")):
        with pytest.raises(NavError, match=words):
            h.nav.goto(h.now, bad, "", h.pose())
    assert (h.nav.status.goal_id, h.nav.status.state, h.nav.status.goal) == before == (gid, ACTIVE, before[2])


def test_cancel_and_preemption(apartment, world_places):
    h = make(apartment, world_places.get("charging station").pose)
    first = h.nav.goto(h.now, world_places.get("fridge").pose, "fridge", h.pose())
    for _ in range(30):
        h.step()
    second = h.nav.goto(h.now, world_places.get("shelf").pose, "shelf", h.pose())
    assert second != first
    assert h.nav.result(first).state == PREEMPTED
    assert "replaced by a new goal (shelf)" in h.nav.result(first).text
    assert h.nav.status.state == ACTIVE and h.nav.status.place == "shelf"
    for _ in range(20):
        h.step()
    assert h.nav.status.eta > 0 and h.nav.status.distance_remaining > 0.5
    h.nav.cancel(h.now)
    assert h.nav.result(second).state == CANCELED and "canceled" in h.nav.status.text
    cmd = h.nav.step(h.now, h.pose(), h.sim.scan(), None)
    assert cmd is not None and (cmd.vx, cmd.wz) == (0.0, 0.0)       # one stop, then nothing
    assert h.nav.step(h.now, h.pose(), None, None) is None
    with pytest.raises(NavError, match="no goal 99"):
        h.nav.cancel(h.now, 99)


def test_blocked_for_good_aborts_after_the_recoveries(apartment, world_places):
    # the doorway to the fridge's room closed by a door the map does not know
    start = world_places.get("charging station").pose
    h = make(apartment, start)
    h.sim.add_box(4.9, 2.9, 5.1, 4.4)
    h.nav.params = type(h.nav.params)(progress_timeout=5.0, controller_patience=1.0)
    gid = h.nav.goto(h.now, world_places.get("fridge").pose, "fridge", h.pose())
    h.run(lambda: h.nav.status.state != ACTIVE, limit=150.0)
    status = h.nav.result(gid)
    assert status.state == ABORTED and not h.sim.collided
    assert status.text.startswith("could not reach fridge: ")
    assert "I tried" in status.text and "turning on the spot" in status.text
    assert status.recoveries == 5


def _lose_track_on_the_way(apartment, world_places) -> tuple[Harness, list[float]]:
    """A trip from the charging station to the desk that loses track of where it is after 3 s:
    the harness says "not localised" until the test says otherwise; the turn made meanwhile."""
    h = make(apartment, world_places.get("charging station").pose)
    h.nav.goto(h.now, world_places.get("desk").pose, "desk", h.pose())
    h.run(lambda: False, limit=3.0)
    assert h.nav.status.state == ACTIVE and h.sim.vx > 0.05, h.nav.status.text
    headings = [h.sim.pose.theta]
    h.localised = lambda: (headings.append(h.sim.pose.theta), False)[1]
    return h, headings


def test_lost_on_the_way_it_stops_then_turns_on_the_spot_and_goes_on_once_found(apartment, world_places):
    h, headings = _lose_track_on_the_way(apartment, world_places)
    at, mark = h.sim.pose, len(h.commands)
    h.run(lambda: h.sim.wz > 0.1, limit=5.0)           # it waits, still, then starts to turn
    waited = h.commands[mark:]
    assert h.now - 3.0 >= h.nav.params.lost_timeout - 0.15 and all(vx == 0.0 for vx, _ in waited), waited
    assert "I am not sure where I am on the way to desk; turning on the spot" in h.nav.status.text

    def turned() -> float:
        return float(np.ptp(np.unwrap(headings)))
    h.run(lambda: turned() > math.pi / 2, limit=20.0)  # the filter "finds" the robot a quarter turn on
    assert h.sim.pose.distance(at) < 0.1, "it drove while it did not know where it was"
    h.localised = lambda: True
    h.run(lambda: h.nav.status.state != ACTIVE, limit=90.0)
    assert h.nav.status.state == SUCCEEDED, h.nav.status.text
    assert on_goal(h.sim, world_places.get("desk").pose) and not h.sim.collided


def test_lost_on_the_way_and_not_found_in_a_whole_turn_aborts_with_a_sentence(apartment, world_places):
    h, headings = _lose_track_on_the_way(apartment, world_places)
    at = h.sim.pose
    h.run(lambda: h.nav.status.state != ACTIVE, limit=60.0)
    assert h.nav.status.state == ABORTED
    assert h.nav.status.text.startswith("could not reach desk: I am not sure where I am any more, even after "
                                        "turning on the spot to look. Set my position"), h.nav.status.text
    assert np.ptp(np.unwrap(headings)) > 1.9 * math.pi and h.sim.pose.distance(at) < 0.1
    h.run(lambda: False, limit=1.0)
    assert abs(h.sim.vx) < 1e-6 and abs(h.sim.wz) < 1e-6, "still moving after the goal ended"


def test_a_nan_pose_is_a_lost_robot_not_a_crash(apartment, world_places):
    h = make(apartment, world_places.get("charging station").pose)
    h.nav.goto(h.now, world_places.get("desk").pose, "desk", h.pose())
    for k in range(25):
        cmd = h.nav.step(h.now + 0.1 * k, Pose(math.nan, 1.0, 0.0), h.sim.scan(), None)
        assert cmd is None or (cmd.vx, cmd.wz) == (0.0, 0.0)
    assert h.nav.status.state == ABORTED and "not sure where I am" in h.nav.status.text


def test_local_controller_limits_and_blocking(apartment):
    cm = Costmap(apartment.grid)
    ctl = LocalController()
    start, goal = Pose(1.0, 1.0, 0.0), Pose(3.5, 1.0, 0.0)
    ctl.set_path(GlobalPlanner().plan(cm, start, goal))
    c = ctl.compute(start, (0.0, 0.0), cm)
    assert c.status == "moving" and 0 < c.vx <= ctl.limits.acc_x * ctl.params.period + 1e-9
    cm.mark_points(np.linspace(1.3, 1.6, 7), np.full(7, 1.0), now=0.0)   # right in front
    cm.mark_points(np.full(21, 1.45), np.linspace(0.5, 1.5, 21), now=0.0)
    c = ctl.compute(start, (0.2, 0.0), cm)
    assert c.status == "blocked" and "obstacle" in c.text and (c.vx, c.wz) == (0.0, 0.0)


def test_at_rest_on_the_edge_of_the_inflation_it_moves_on(apartment):
    """Seen in the sim apartment: the robot stopped for 20 s where its path entered the
    inflation beside the kitchen's east wall, since from rest the window reaches a few cm and
    the first cm into the inflation cost more than they gained. Standing still is no way on."""
    cm = Costmap(apartment.grid)
    start = Pose(9.08, 2.86, math.radians(81))
    # what the scans had marked there: the chair's corner and the wall, a cell off the map's
    cm.mark_points(np.r_[np.full(5, 8.12), 8.18, 8.43], np.r_[np.linspace(2.88, 3.12, 5), 3.28, 3.18], now=0.0)
    cm.mark_points(np.full(13, 10.02), np.linspace(2.43, 3.03, 13), now=0.0)
    ctl = LocalController()
    ctl.set_path(GlobalPlanner().plan(cm, start, Pose(0.75, 1.5, math.pi)))
    pose, v = start, (0.0, 0.0)
    for _ in range(30):       # 3 s at 10 Hz on ideal wheels
        c = ctl.compute(pose, v, cm)
        assert c.status == "moving", c.text
        v = (c.vx, c.wz)
        th = pose.theta + c.wz * 0.1
        pose = Pose(pose.x + c.vx * 0.1 * math.cos(th), pose.y + c.vx * 0.1 * math.sin(th), th)
    assert pose.distance(start) > 0.5


def test_a_periodic_replan_keeps_the_way_being_followed_unless_the_new_one_is_no_longer(apartment):
    """Chairs seen beside one way round the kitchen table made it a little dearer than the other
    for a moment, and the robot turned back and forth between them. A way that is still free is
    kept unless the new one is no longer; a blocked one is replaced at once."""
    start, goal = Pose(9.0, 2.2, math.pi / 2), Pose(0.75, 1.5, math.pi)
    real = GlobalPlanner()

    class Planner:
        """The real planner's first way, then whatever the test says the next plan is."""
        def __init__(self) -> None:
            self.next = None

        def plan(self, costmap, a, b, label=""):
            return self.next or real.plan(costmap, a, b, label)

    cm, planner = Costmap(apartment.grid), Planner()
    nav = Navigator(cm, planner=planner)
    nav.goto(0.0, goal, "charging station", start)
    first = nav.status.path
    odom = type("Odom", (), {"vx": 0.0, "wz": 0.0})()
    longer = Path.from_points(np.vstack([first.points[:1], [[9.5, 0.5], [6.0, 0.3], [4.5, 3.6], [2.0, 0.5]], first.points[-1:]]), goal)
    assert longer.length > first.length + 1.5
    planner.next = longer
    t = nav.params.replan_period + 0.1
    nav.step(t, start, None, odom)
    assert nav.status.path is first                    # still free, and the other way is longer
    shorter = Path.from_points(first.points[::2], goal)
    planner.next = shorter
    t += nav.params.replan_period + 0.1
    nav.step(t, start, None, odom)
    assert nav.status.path is shorter
    # blocked right ahead: the new way is taken at once, however long
    planner.next = longer
    near = shorter.points[np.argmin(np.abs(np.hypot(shorter.points[:, 0] - start.x, shorter.points[:, 1] - start.y) - 1.0))]
    cm.mark_points(np.full(5, near[0]) + np.linspace(-0.1, 0.1, 5), np.full(5, near[1]), now=0.0)
    nav.step(t + 0.1, start, None, odom)
    assert nav.status.path is longer

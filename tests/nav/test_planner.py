"""Global planner on the apartment: paths to every place, bad goals as sentences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asibot.nav.costmap import INSCRIBED, Costmap
from asibot.nav.errors import NavError, Unreachable
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.nav.planner import GlobalPlanner


@pytest.fixture(scope="module")
def costmap(request):
    return Costmap(request.getfixturevalue("apartment").grid)


def test_a_clear_path_to_every_place(costmap, world_places):
    planner = GlobalPlanner()
    start = world_places.get("charging station").pose
    for place in world_places.list():
        path = planner.plan(costmap, start, place.pose, place.name)
        pts = path.points
        assert np.allclose(pts[0], (start.x, start.y)) and np.allclose(pts[-1], (place.pose.x, place.pose.y))
        assert (costmap.cost_at(pts[:, 0], pts[:, 1]) < INSCRIBED).all()
        assert np.hypot(*np.diff(pts, axis=0).T).max() <= 0.05 + 1e-9
        straight = start.distance(place.pose)
        assert straight - 1e-6 <= path.length <= 2.2 * straight + 1.0   # shortcut, not a staircase


def test_goal_inside_a_wall_names_the_nearest_free_spot(costmap, world_places):
    start = world_places.get("charging station").pose
    with pytest.raises(Unreachable) as err:
        GlobalPlanner().plan(costmap, start, Pose(5.0, 2.0, 0.0), "the wall")
    msg = err.value.message
    assert "The goal the wall is inside an obstacle" in msg and "nearest free spot is (" in msg
    assert err.value.code == "unreachable"


def test_goal_close_to_free_space_is_moved_there(costmap, world_places):
    start = world_places.get("charging station").pose
    # a goal a hair inside the inscribed band of a wall: within the tolerance
    free = GlobalPlanner().plan(costmap, start, Pose(4.68, 2.0, 0.0))
    assert costmap.cost_at(free.points[-1, 0], free.points[-1, 1]) < INSCRIBED
    assert GlobalPlanner().plan(costmap, start, Pose(4.74, 2.0, 0.0)).goal.distance(Pose(4.74, 2.0, 0.0)) <= 0.25


def test_no_path_is_a_sentence():
    data = np.zeros((80, 80), np.int8)
    data[:, 40] = 100                          # a wall from side to side
    cm = Costmap(OccupancyGrid(GridInfo(80, 80, 0.05), data))
    with pytest.raises(Unreachable, match="There is no way to the other side"):
        GlobalPlanner().plan(cm, Pose(0.5, 2.0, 0.0), Pose(3.5, 2.0, 0.0), "the other side")


def test_bad_poses_are_sentences(costmap):
    planner = GlobalPlanner()
    with pytest.raises(NavError, match="outside the map"):
        planner.plan(costmap, Pose(0.75, 1.5, 0.0), Pose(50.0, 1.0, 0.0))
    with pytest.raises(NavError, match="robot's position .* outside the map"):
        planner.plan(costmap, Pose(-20.0, 1.5, 0.0), Pose(2.0, 2.0, 0.0))
    with pytest.raises(NavError, match="not a finite pose"):
        planner.plan(costmap, Pose(0.75, 1.5, 0.0), Pose(math.nan, 1.0, 0.0))


def test_a_robot_touching_a_wall_can_still_leave(costmap):
    # 0.15 m from the outer wall at x = -0.05: inside the inscribed band
    start = Pose(0.1, 2.5, 0.0)
    assert costmap.cost_at(start.x, start.y) >= INSCRIBED
    path = GlobalPlanner().plan(costmap, start, Pose(1.0, 1.0, 0.0))
    assert path.length < 3.0


def test_the_last_stretch_follows_the_goals_heading(costmap, world_places):
    fridge = world_places.get("fridge").pose
    path = GlobalPlanner().plan(costmap, world_places.get("charging station").pose, fridge)
    tail = path.points[-12:]
    heading = np.arctan2(*(tail[-1] - tail[0])[::-1])
    assert abs(math.remainder(heading - fridge.theta, 2 * math.pi)) < 0.05

"""Costmap: costmap_2d's values and inflation function, marking, raytrace clearing, fading."""

from __future__ import annotations

import math

import numpy as np

from asibot.messages import LaserScan
from asibot.nav.costmap import INSCRIBED, LETHAL, NO_INFORMATION, Costmap, CostmapParams
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.nav.robot import P3AT


def empty_grid(size_m: float = 8.0, res: float = 0.05) -> OccupancyGrid:
    n = int(size_m / res)
    return OccupancyGrid(GridInfo(n, n, res, Pose(0.0, 0.0, 0.0)), np.zeros((n, n), np.int8))


def scan_of(ranges, fov=2 * math.pi, range_max=6.0) -> LaserScan:
    ranges = np.asarray(ranges, np.float32)
    return LaserScan(angle_min=-fov / 2, angle_increment=fov / len(ranges), range_min=0.05,
                     range_max=range_max, ranges=ranges)


def test_footprint_radii():
    assert math.isclose(P3AT.inscribed_radius, 0.2525)
    assert math.isclose(P3AT.circumscribed_radius, math.hypot(0.313, 0.2525))


def test_inflation_follows_costmap_2d():
    grid = empty_grid()
    grid.data[80, 80] = 100                      # one lethal cell at (4.025, 4.025)
    cm = Costmap(grid, params=CostmapParams(inflation_radius=0.7, cost_scaling_factor=3.0))
    c = cm.costs
    assert c[80, 80] == LETHAL
    res, r_in = 0.05, P3AT.inscribed_radius
    for cells in range(1, 16):
        d = cells * res
        if d <= r_in:
            want = INSCRIBED
        elif d <= 0.7:
            want = int(252 * math.exp(-3.0 * (d - r_in)))
        else:
            want = 0
        assert abs(int(c[80, 80 + cells]) - want) <= 1, (cells, c[80, 80 + cells], want)


def test_unknown_stays_unknown_unless_inscribed():
    grid = empty_grid()
    grid.data[:, :40] = -1
    grid.data[100, 60] = 100
    cm = Costmap(grid)
    assert cm.costs[0, 0] == NO_INFORMATION
    assert cm.cost_at(100.0, 100.0) == NO_INFORMATION          # off the map


def test_scan_marks_and_raytrace_clears():
    cm = Costmap(empty_grid())
    pose = Pose(2.0, 4.0, 0.0)
    ranges = np.full(360, np.inf)
    ranges[180] = 2.0                                          # straight ahead: a box at x = 4.0
    cm.update_scan(pose, scan_of(ranges), now=0.0)
    assert cm.cost_at(4.0, 4.0) == LETHAL
    assert cm.cost_at(3.0, 4.0) < INSCRIBED
    # the box leaves: the beam now reaches 5 m, clearing the cell it passed through
    ranges[180] = 5.0
    cm.update_scan(pose, scan_of(ranges), now=1.0)
    assert cm.cost_at(4.0, 4.0) < INSCRIBED and cm.cost_at(7.0, 4.0) < LETHAL  # 7 m is beyond obstacle_range


def test_max_range_readings_clear_ghosts():
    cm = Costmap(empty_grid())
    pose = Pose(2.0, 4.0, 0.0)
    cm.mark_points(np.array([3.5]), np.array([4.0]), now=0.0)
    assert cm.cost_at(3.5, 4.0) == LETHAL
    cm.update_scan(pose, scan_of(np.full(360, np.inf)), now=1.0)     # nothing seen anywhere
    assert cm.cost_at(3.5, 4.0) < INSCRIBED


def test_marks_fade_and_the_robot_is_never_inside_an_obstacle():
    cm = Costmap(empty_grid(), params=CostmapParams(obstacle_decay_s=5.0))
    cm.mark_points(np.array([6.0, 2.0]), np.array([6.0, 4.0]), now=0.0)
    narrow = scan_of(np.full(10, 1.0), fov=0.1)                     # looks elsewhere, at 1 m
    cm.update_scan(Pose(2.0, 4.0, math.pi), narrow, now=1.0)
    assert cm.cost_at(2.0, 4.0) < INSCRIBED                          # footprint clearing
    assert cm.cost_at(6.0, 6.0) == LETHAL                            # not seen, not yet old
    cm.update_scan(Pose(2.0, 4.0, math.pi), narrow, now=6.0)
    assert cm.cost_at(6.0, 6.0) < INSCRIBED                          # faded


def test_scan_points_on_the_robot_are_ignored():
    cm = Costmap(empty_grid())
    ranges = np.full(360, np.inf)
    ranges[180] = 0.2                                                # inside the footprint
    cm.update_scan(Pose(4.0, 4.0, 0.0), scan_of(ranges), now=0.0)
    assert not cm.marked.any()


def test_clear_obstacles_keeps_the_nearby_ones():
    cm = Costmap(empty_grid())
    cm.mark_points(np.array([1.0, 7.0]), np.array([1.0, 7.0]), now=0.0)
    assert cm.clear_obstacles(Pose(1.2, 1.2, 0.0), reset_distance=3.0) == 1
    assert cm.cost_at(1.0, 1.0) == LETHAL and cm.cost_at(7.0, 7.0) < INSCRIBED
    cm.clear_obstacles()
    assert not cm.marked.any()


def test_footprint_cost_sees_the_corners():
    grid = empty_grid()
    cm = Costmap(grid)
    cm.mark_points(np.array([4.30]), np.array([4.24]), now=0.0)     # just inside the front-left corner
    assert cm.footprint_cost(4.0, 4.0, 0.0) >= LETHAL
    assert cm.footprint_cost(4.0, 3.5, 0.0) < INSCRIBED

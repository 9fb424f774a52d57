"""Sonar fused for what the depth cameras miss: a glass wall, the blind zone near the robot."""

import math

import numpy as np
import pytest

from asibot import messages as m
from asibot.perception.depth_to_scan import DepthToScan
from asibot.perception.errors import BadInput
from asibot.perception.merge import ScanGrid, merge
from asibot.perception.rays import CameraRays
from asibot.perception.sonar import P3AT_MAX_RANGE, P3AT_POSITIONS_MM, SonarRing

from .synth import FRONT, camera_info, render, wall_x

GRID = ScanGrid()
RING = SonarRing.p3at()
HEADINGS = [math.radians(h) for h in (90, 50, 30, 10, -10, -30, -50, -90, -90, -130, -150, -170, 170, 150, 130, 90)]


def sonar_facing_wall(x_wall: float) -> m.Sonar:
    """What the ring hears of a wall across the way at x_wall (nearest echo in each +-10 deg cone)."""
    ranges = []
    for (px, py), h in zip(np.asarray(P3AT_POSITIONS_MM) / 1000, HEADINGS):
        best = P3AT_MAX_RANGE
        for d in np.radians([-10, 0, 10]):
            c = math.cos(h + d)
            if c > 1e-6:
                best = min(best, (x_wall - px) / c)
        ranges.append(best)
    return m.Sonar(ranges=ranges, angles=HEADINGS)


def depth_scan(x_wall: float):
    rays = CameraRays.from_info(camera_info(FRONT, width=320, height=240))
    return merge(GRID, [DepthToScan(rays).convert(render(rays, [wall_x(x_wall)])[0])])


def test_a_glass_wall_the_depth_cannot_see_is_put_in_by_the_sonar():
    ranges = depth_scan(3.0)                      # the cameras see through the glass to a wall at 3 m
    fused = RING.fuse(GRID, ranges, sonar_facing_wall(1.0))
    a = GRID.angles()
    ahead = np.abs(a) < math.radians(12)          # the cones of sonars 3 and 4
    assert np.all(fused[ahead] < 1.3) and np.all(fused[ahead] > 0.95)
    np.testing.assert_allclose(fused[np.abs(a) < math.radians(1)], 1.0, atol=0.03)
    # the sonar only makes the scan nearer, and only where its cones are
    finite = np.isfinite(ranges)
    assert np.all(fused[finite] <= ranges[finite])
    # sonars 1, 2, 5, 6 hear the glass 1.3 m away where no camera watches: farther than
    # unwatched_range, so not laid in (their arcs drew streaks that nothing ever cleared)
    assert np.isnan(fused[np.abs(np.abs(a) - math.radians(40)) < math.radians(5)]).all()
    assert np.isnan(fused[np.abs(np.abs(a) - math.radians(80)) < math.radians(5)]).all()   # 0 and 7: no echo


def test_a_near_echo_where_no_camera_watches_is_laid_in():
    ranges = depth_scan(3.0)
    fused = RING.fuse(GRID, ranges, sonar_facing_wall(0.45))     # glass 0.45 m ahead
    a = GRID.angles()
    assert np.isfinite(fused[np.abs(np.abs(a) - math.radians(40)) < math.radians(5)]).all()  # sonars 1, 2, 5, 6


def test_an_echo_the_cameras_explain_changes_nothing():
    ranges = depth_scan(2.0)
    sonar = sonar_facing_wall(2.0)
    fused = RING.fuse(GRID, ranges, sonar)
    front = np.abs(GRID.angles()) < math.radians(25)
    np.testing.assert_array_equal(fused[front], ranges[front])


def test_no_echo_is_not_an_obstacle():
    ranges = depth_scan(3.0)
    quiet = m.Sonar(ranges=[P3AT_MAX_RANGE] * 16, angles=HEADINGS)
    np.testing.assert_array_equal(RING.fuse(GRID, ranges, quiet), ranges)


def test_a_very_close_box_below_the_cameras_view_is_heard():
    ranges = GRID.unknown()                       # the cameras see nothing at all
    sonar = sonar_facing_wall(10.0)
    sonar.ranges[3] = 0.15                        # something 15 cm in front of sonar 3
    fused = RING.fuse(GRID, ranges, sonar)
    hit = np.isfinite(fused)
    assert hit.any() and np.all(np.abs(fused[hit] - 0.4) < 0.03)    # 0.245 + 0.15 from the centre


@pytest.mark.parametrize("ranges, angles, words", [
    ([1.0] * 15, HEADINGS[:15], "15 readings but the ring has 16"),
    ([1.0] * 16, HEADINGS[:15], "16 ranges but 15 angles"),
    ([float("nan")] + [1.0] * 15, HEADINGS, "not finite"),
])
def test_bad_sonar_messages_are_refused(ranges, angles, words):
    with pytest.raises(BadInput, match=words):
        RING.fuse(GRID, GRID.unknown(), m.Sonar(ranges=ranges, angles=angles))

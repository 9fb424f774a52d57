"""Front and back cameras into one 360-degree scan; when the assembler publishes."""

import math

import numpy as np
import pytest

from asibot.perception.assembler import ScanAssembler
from asibot.perception.depth_to_scan import DepthToScan
from asibot.perception.merge import ScanGrid, merge
from asibot.perception.rays import CameraRays

from .synth import BACK, FRONT, camera_info, render, wall_x

GRID = ScanGrid()


def camera_scan(info, boxes):
    rays = CameraRays.from_info(info)
    return DepthToScan(rays).convert(render(rays, boxes)[0])


@pytest.fixture
def front_back():
    boxes = [wall_x(2.0), wall_x(-3.0)]
    return (camera_scan(camera_info(FRONT), boxes),
            camera_scan(camera_info(BACK, yaw=math.pi), boxes))


def test_front_and_back_cameras_make_one_scan_in_the_base_frame(front_back):
    ranges = merge(GRID, front_back)
    a = GRID.angles()
    assert ranges.dtype == np.float32 and len(ranges) == 720
    ahead, behind = np.isfinite(ranges) & (np.cos(a) > 0), np.isfinite(ranges) & (np.cos(a) < 0)
    assert ahead.sum() > 80 and behind.sum() > 80
    np.testing.assert_allclose(ranges[ahead], 2.0 / np.cos(a[ahead]), rtol=3e-3)
    np.testing.assert_allclose(ranges[behind], 3.0 / -np.cos(a[behind]), rtol=3e-3)
    # the sides are watched by neither camera: unknown, never "free"
    sides = np.abs(np.abs(a) - math.pi / 2) < math.radians(30)
    assert np.isnan(ranges[sides]).all()


def test_beam_i_is_at_angle_min_plus_i_increments():
    scan = GRID.message(GRID.unknown())
    assert scan.angle_min == -math.pi and scan.angle_increment == pytest.approx(math.radians(0.5))
    assert scan.range_min == 0.05 and scan.range_max == 8.0
    ranges = GRID.unknown()
    GRID.add(ranges, np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, -2.0]))   # left, behind, right
    assert ranges[540] == 1.0 and ranges[0] == 1.0 and ranges[180] == 2.0


def test_returns_beyond_range_max_leave_the_beam_free():
    ranges = GRID.unknown()
    GRID.add(ranges, np.array([9.0]), np.array([0.0]))
    assert np.isinf(ranges[360]) and np.isnan(ranges).sum() == 719


def test_bad_grids_are_refused():
    with pytest.raises(ValueError, match="beams"):
        ScanGrid(beams=3)
    with pytest.raises(ValueError, match="range"):
        ScanGrid(range_max=float("nan"))


# ---------------------------------------------------------------------- the assembler
def test_a_scan_goes_out_once_every_fresh_camera_delivered(front_back):
    f, b = front_back
    asm = ScanAssembler(["front", "back"], freshness=0.5)
    assert asm.add("front", f, 0.00, 1) is not None      # the back camera was never heard: do not wait
    assert asm.add("back", b, 0.05, 2) is None           # now both are known: wait for the front one
    assert [fr.stamp for fr in asm.add("front", f, 0.10, 3)] == [3, 2]
    assert asm.add("back", b, 0.15, 4) is None
    assert [fr.stamp for fr in asm.add("front", f, 0.20, 5)] == [5, 4]   # one scan per camera cycle


def test_a_faster_or_late_camera_does_not_hold_the_scan_back(front_back):
    f, b = front_back
    asm = ScanAssembler(["front", "back"], freshness=0.5)
    asm.add("front", f, 0.0, 1), asm.add("back", b, 0.0, 2)
    assert asm.add("front", f, 0.1, 3) is not None
    assert asm.add("front", f, 0.2, 4) is None           # waits for the back camera...
    frames = asm.add("front", f, 0.3, 5)                 # ...but not for two front frames
    assert [fr.stamp for fr in frames] == [5, 2]         # the back's newest frame is still fresh


def test_a_silent_camera_is_left_out_and_named(front_back):
    f, b = front_back
    asm = ScanAssembler(["front", "back"], freshness=0.5)
    asm.add("front", f, 0.0, 1), asm.add("back", b, 0.0, 2)
    assert asm.silent(0.4) == []
    for i, t in enumerate((0.6, 0.7, 0.8)):              # back silent since 0.0
        frames = asm.add("front", f, t, 10 + i)
        assert [fr.stamp for fr in frames] == [10 + i]   # one scan per front frame, front only
    assert asm.silent(0.8) == ["back"] and asm.heard() == ["front", "back"]
    ranges = merge(GRID, [fr.scan for fr in frames])
    assert np.isnan(ranges[np.cos(GRID.angles()) < -0.95]).all()   # behind: unknown


def test_the_assembler_knows_its_cameras(front_back):
    with pytest.raises(ValueError, match="not one of"):
        ScanAssembler(["front"]).add("back", front_back[1], 0.0, 1)
    sonar_alone = ScanAssembler([])                 # no camera: nothing is due, nothing silent
    assert sonar_alone.silent(0.0) == [] and sonar_alone.heard() == []
    with pytest.raises(ValueError, match="not one of"):
        sonar_alone.add("front", front_back[0], 0.0, 1)

"""One camera's depth image -> nearest returns, against scenes of known geometry (synth.py)."""

import math

import numpy as np
import pytest

from asibot import messages as m
from asibot.perception.depth_to_scan import BandConfig, DepthToScan, centre_rows
from asibot.perception.errors import BadInput
from asibot.perception.merge import ScanGrid, merge
from asibot.perception.rays import CameraRays

from .synth import FRONT, Box, camera_info, render, wall_x

GRID = ScanGrid()


def scan_of(info: m.CameraInfo, boxes, floor=True, band=BandConfig()):
    rays = CameraRays.from_info(info)
    conv = DepthToScan(rays, band)
    depth, _ = render(rays, boxes, floor)
    return conv, conv.convert(depth), depth


def beams_seen(ranges):
    a = GRID.angles()
    return a[np.isfinite(ranges)], ranges[np.isfinite(ranges)]


def test_a_wall_at_2_m_reads_2_m_over_cos_angle_from_the_base_centre():
    info = camera_info(FRONT, width=320, height=240)
    conv, scan, _ = scan_of(info, [wall_x(2.0)])
    assert conv.mode == "columns"
    a, r = beams_seen(merge(GRID, [scan]))
    # every beam of the field of view, seen from the base centre 0.32 m behind the camera
    half_span = math.atan((2.0 - FRONT[0]) * info.cx / info.fx / 2.0)
    assert len(a) >= 2 * half_span / GRID.increment - 1
    np.testing.assert_allclose(r, 2.0 / np.cos(a), rtol=2e-3)   # beam quantisation: 0.25 deg
    # the camera's own bearings are exact: rho is the distance from the camera
    np.testing.assert_allclose(scan.rho * np.cos(scan.bearing), 2.0 - FRONT[0], rtol=1e-5)


def test_the_floor_alone_gives_no_return_but_the_beams_are_watched():
    _, scan, depth = scan_of(camera_info(FRONT), [])
    assert (depth > 0).mean() > 0.4                 # the camera does see the floor
    ranges = merge(GRID, [scan])
    assert not np.isfinite(ranges).any()
    watched = np.isinf(ranges)                     # +inf: free
    # the beams the camera, 0.32 m ahead of the base centre, sees whole from 1 m out: about
    # +-20 deg of its +-28.8 (merge.py, watch_from)
    a = np.degrees(GRID.angles()[watched])
    assert a.min() == pytest.approx(-20, abs=1) and a.max() == pytest.approx(20, abs=1)
    assert watched.sum() == pytest.approx(80, abs=4)
    assert np.isnan(ranges[~watched]).all()        # NaN: nobody looks there


def test_a_5_cm_box_at_1_m_is_seen_thanks_to_the_band_and_missed_by_the_centre_row():
    box = Box((1.0, -0.1, 0.0), (1.2, 0.1, 0.05))
    info = camera_info(FRONT, width=320, height=240)
    conv, scan, depth = scan_of(info, [box, wall_x(3.0)])
    ranges = merge(GRID, [scan])
    ahead = np.abs(GRID.angles()) < math.radians(3)
    np.testing.assert_allclose(ranges[ahead], 1.0 / np.cos(GRID.angles()[ahead]), rtol=3e-3)
    # depthimage_to_laserscan's centre rows see only the wall behind it
    angles, centre = centre_rows(depth, conv.rays, scan_height=1)
    mid = np.abs(angles) < math.radians(3)
    assert np.all(centre[mid] * np.cos(angles[mid]) > 2.6)


def test_a_pitched_camera_is_scanned_by_bearing_bins_and_still_reads_the_wall():
    info = camera_info((0.2, 0.0, 0.45), pitch=math.radians(15), width=320, height=240, fovy_deg=50)
    conv, scan, _ = scan_of(info, [wall_x(2.0)])
    assert conv.mode == "bins"
    x, y = scan.points()
    assert len(x) > 100
    np.testing.assert_allclose(x, 2.0, atol=0.01)     # bins of 0.25 deg: < 1 cm across the wall


def test_a_camera_turned_sideways_reports_in_the_base_frame():
    conv, scan, _ = scan_of(camera_info((0.0, 0.2, 0.3), yaw=math.pi / 2), [Box((-5, 1.5, 0), (5, 1.6, 2))])
    x, y = scan.points()
    np.testing.assert_allclose(y, 1.5, atol=1e-4)


def test_obstacles_above_the_band_and_the_floor_below_it_are_not_obstacles():
    shelf = Box((1.0, -1.0, 1.2), (1.5, 1.0, 1.3))         # above max_height 1.0
    _, scan, depth = scan_of(camera_info(FRONT, fovy_deg=90), [shelf])
    assert (depth > 0).any()
    assert not np.isfinite(scan.rho).any()
    # the same shelf lowered into the band is seen
    low = Box((1.0, -1.0, 0.8), (1.5, 1.0, 0.9))
    _, scan, _ = scan_of(camera_info(FRONT, fovy_deg=90), [low])
    assert np.isfinite(scan.rho).sum() > 10


def test_range_limits_apply_from_the_camera():
    band = BandConfig(range_max=1.5)
    _, scan, _ = scan_of(camera_info(FRONT), [wall_x(2.0)], band=band)   # 1.68 m from the camera
    assert not np.isfinite(scan.rho).any()


def test_centre_rows_is_depthimage_to_laserscan():
    rays = CameraRays.from_info(camera_info(FRONT, width=320, height=240))
    depth, _ = render(rays, [wall_x(2.0)], floor=False)
    angles, ranges = centre_rows(depth, rays, scan_height=4)
    assert angles[0] > 0 > angles[-1]                         # left of the image = largest angle
    np.testing.assert_allclose(ranges * np.cos(angles), 2.0 - FRONT[0], rtol=1e-5)
    with pytest.raises(BadInput, match="scan_height"):
        centre_rows(depth, rays, scan_height=400)


# ---------------------------------------------------------------------- bad input
@pytest.fixture
def conv():
    return DepthToScan(CameraRays.from_info(camera_info(FRONT)))


def test_nan_depth_is_refused_with_a_sentence(conv):
    depth = np.ones((120, 160), np.float32)
    depth[5, 7] = np.nan
    with pytest.raises(BadInput, match="NaN.*mark pixels without a return with 0"):
        conv.convert(depth, "the front camera")


@pytest.mark.parametrize("depth, words", [
    (np.ones((160, 120), np.float32), "120x160"),
    (np.ones((120, 160, 1), np.float32), "CameraInfo says"),
    (np.ones((120, 160), np.uint16), "float32 metres"),
    (np.full((120, 160), -1.0, np.float32), "negative"),
    (np.full((120, 160), np.inf, np.float32), "inf"),
    ([[1.0]], "not an array"),
])
def test_malformed_depth_images_are_refused(conv, depth, words):
    with pytest.raises(BadInput, match=words):
        conv.convert(depth)


@pytest.mark.parametrize("change, words", [
    ({"fx": 0.0}, "fx = 0.0; a focal length must be a positive"),
    ({"fy": float("nan")}, "fy = nan"),
    ({"cx": float("inf")}, "principal point"),
    ({"width": 1}, "width 1"),
    ({"height": 100000}, "height 100000"),
    ({"pose": [0, 0, 0.3, 1, 0, 0]}, "7 finite numbers"),
    ({"pose": [0, 0, 0.3, 0, 0, 0, 0]}, "unit quaternion"),
    ({"pose": [0, 0, float("nan"), 1, 0, 0, 0]}, "7 finite numbers"),
])
def test_impossible_camera_infos_are_refused(change, words):
    info = camera_info(FRONT)
    for k, v in change.items():
        setattr(info, k, v)
    with pytest.raises(BadInput, match=words):
        CameraRays.from_info(info, "the front camera")


def test_band_settings_are_checked():
    with pytest.raises(ValueError, match="height band is empty"):
        BandConfig(min_height=1.0, max_height=0.5).check()
    with pytest.raises(ValueError, match="range min"):
        BandConfig(range_min=0.0).check()

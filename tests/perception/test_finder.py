"""The red-object finder on synthetic images: registered and unregistered RGB and depth cameras."""

import math

import numpy as np
import pytest

from asibot.perception import finder
from asibot.perception.errors import BadInput
from asibot.perception.rays import CameraRays

from .synth import FRONT, Box, camera_info, colour_image, jpeg, render, wall_x

RED, GREEN, WOOD = (20, 20, 200), (40, 160, 30), (75, 115, 150)   # BGR
CAN = Box((1.4, -0.233, 0.45), (1.466, -0.167, 0.57), RED)        # a 'can' on a table, 1.4 m ahead
TABLE = Box((1.0, -0.5, 0.0), (1.8, 0.3, 0.45), WOOD)
SCENE = [CAN, TABLE, wall_x(3.0)]
DEPTH_CAM = camera_info(FRONT, width=320, height=240)
RGB_CAM = camera_info((0.2, 0.0, 0.45), pitch=math.radians(15), width=320, height=240, fovy_deg=50)


def shoot(info, boxes=SCENE):
    rays = CameraRays.from_info(info)
    depth, label = render(rays, boxes)
    bgr = finder.decode_jpeg(jpeg(colour_image(label, boxes)).jpeg, info.width, info.height)  # through JPEG
    return rays, depth, bgr


def test_the_red_can_is_found_with_an_unregistered_depth_camera():
    rgb_rays, _, bgr = shoot(RGB_CAM)
    depth_rays, depth, _ = shoot(DEPTH_CAM)
    ans = finder.find(bgr, "red", rgb_rays, [depth_rays.points(depth)])
    assert ans["found"] and ans["pixels"] > 100 and ans["depth_points"] >= 5
    x, y, z = ans["point"]
    assert x == pytest.approx(1.4, abs=0.02)          # on the can's visible face
    assert y == pytest.approx(-0.2, abs=0.02) and 0.45 <= z <= 0.57


def test_registered_cameras_give_the_same_point():
    rays, depth, bgr = shoot(DEPTH_CAM)
    ans = finder.find(bgr, "red", rays, [rays.points(depth)])
    assert ans["found"] and ans["point"][0] == pytest.approx(1.4, abs=0.01)


def test_no_red_object_in_view_says_so():
    rgb_rays, _, bgr = shoot(RGB_CAM, [TABLE, wall_x(3.0)])
    ans = finder.find(bgr, "red", rgb_rays, [])
    assert ans == {"found": False, "pixels": 0,
                   "message": "No red object is in view of the camera; turn the robot or move closer."}


def test_an_object_no_depth_camera_sees_has_no_position():
    rgb_rays, _, bgr = shoot(RGB_CAM)
    behind = camera_info((-0.32, 0.0, 0.3), yaw=math.pi)          # only the back camera's points
    back_rays, depth, _ = shoot(behind)
    ans = finder.find(bgr, "red", rgb_rays, [back_rays.points(depth)])
    assert not ans["found"] and ans["pixels"] > 100
    assert "no depth camera sees it" in ans["message"]


def test_other_colours_and_the_largest_blob():
    cup = Box((1.2, 0.1, 0.45), (1.26, 0.16, 0.52), GREEN)
    small = Box((1.3, -0.4, 0.45), (1.31, -0.39, 0.46), RED)       # a speck, smaller than the can
    rgb_rays, _, bgr = shoot(RGB_CAM, [CAN, small, cup, TABLE, wall_x(3.0)])
    depth_rays, depth, _ = shoot(DEPTH_CAM, [CAN, small, cup, TABLE, wall_x(3.0)])
    green = finder.find(bgr, "Green", rgb_rays, [depth_rays.points(depth)])
    assert green["found"] and green["point"][1] == pytest.approx(0.13, abs=0.02)
    red = finder.find(bgr, "red", rgb_rays, [depth_rays.points(depth)])
    assert red["point"][1] == pytest.approx(-0.2, abs=0.02)


def test_the_wooden_table_is_not_red_or_orange():
    rgb_rays, _, bgr = shoot(RGB_CAM, [TABLE, wall_x(3.0)])
    for colour in ("red", "orange"):
        assert finder.find_blob(bgr, colour) is None


def test_bad_requests_and_images_are_refused_with_a_sentence():
    rgb_rays, _, bgr = shoot(RGB_CAM)
    with pytest.raises(BadInput, match="unknown colour 'purple': ask for one of red, orange"):
        finder.find(bgr, "purple", rgb_rays, [])
    with pytest.raises(BadInput, match="unknown colour"):
        finder.check_color(3)
    with pytest.raises(BadInput, match="not a readable JPEG"):
        finder.decode_jpeg(b"not a jpeg", 320, 240)
    with pytest.raises(BadInput, match="320x240 but says 640x480"):
        finder.decode_jpeg(jpeg(bgr).jpeg, 640, 480)
    with pytest.raises(BadInput, match="CameraInfo says"):
        finder.find(np.zeros((10, 10, 3), np.uint8), "red", rgb_rays, [])

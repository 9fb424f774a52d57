"""The depth geometry (asibot.depth) on synthetic scenes with known answers: the kitchen camera
looking at a counter with the red can, a box and a wall, exact and with sensor noise."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from asibot import depth
from asibot.depth import DepthError

from .scenes import CAN_R, CAN_TOP, CAN_XY, COUNTER, Scene, kitchen_info, kitchen_scene, pixel_of


def test_a_pixel_and_its_depth_give_back_the_point_it_came_from():
    info = kitchen_info()
    point = np.array([0.12, -0.07, 1.3])
    u, v = depth.project(info, point)
    assert depth.deproject(info, u, v, point[2]) == pytest.approx(point)
    with pytest.raises(DepthError, match="behind"):
        depth.project(info, [0, 0, -1])


def test_intrinsics_and_their_camera_info_carry_the_same_numbers():
    info = kitchen_info()
    lens = depth.Intrinsics.of(info)
    again = lens.info(info.pose, info.frame, info.stamp)
    assert again == info and depth.Intrinsics.of(again) == lens


def test_a_pose_and_its_matrix_are_the_same_transform():
    pose = kitchen_info().pose
    t = depth.pose_matrix(pose)
    assert t[:3, :3] @ t[:3, :3].T == pytest.approx(np.eye(3))
    assert depth.matrix_pose(t) == pytest.approx(pose)
    # The optical axis looks back at the arm and down, as kitchen.xml places the camera.
    assert t[:3, 2] == pytest.approx([-0.757, 0, -0.654], abs=1e-3)
    with pytest.raises(DepthError, match="7 finite numbers"):
        depth.pose_matrix([0, 0, 0, 1, 0, 0])
    with pytest.raises(DepthError, match="quaternion is zero"):
        depth.pose_matrix([0, 0, 0, 0, 0, 0, 0])


def test_the_cloud_is_the_scene_in_the_robot_frame_with_its_colours():
    info = kitchen_info()
    image = kitchen_scene().depth(info)
    rgb = np.zeros((info.height, info.width, 3), np.uint8)
    rgb[..., 0] = np.arange(info.width)[None, :] % 256          # red says the column
    rgb[..., 1] = np.arange(info.height)[:, None] % 256         # green says the row
    xyz, colours = depth.cloud(image, rgb, info, depth.pose_matrix(info.pose))
    assert 4000 <= len(xyz) <= depth.CLOUD_POINTS and xyz.dtype == np.float32 and colours.dtype == np.uint8
    on_can = np.hypot(xyz[:, 0] - CAN_XY[0], xyz[:, 1] - CAN_XY[1]) <= CAN_R + 1e-3
    assert on_can.any()
    assert xyz[~on_can, 2] == pytest.approx(COUNTER, abs=1e-4)   # everything else is the counter
    assert xyz[on_can, 2].max() == pytest.approx(CAN_TOP, abs=1e-3)
    # Each point has the colour of its own pixel.
    for (x, y, z), (r, g, _) in zip(xyz[::97], colours[::97]):
        u, v = pixel_of(info, [x, y, z])
        assert (round(u) % 256, round(v) % 256) == (r, g)


def test_a_cloud_leaves_out_pixels_with_no_return_and_greys_a_depth_only_camera():
    info = kitchen_info()
    image = kitchen_scene().depth(info)
    image[:, : info.width // 2] = 0
    xyz, colours = depth.cloud(image, None, info, depth.pose_matrix(info.pose))
    assert 0 < len(xyz) < 3000 and (colours == 160).all()
    with pytest.raises(DepthError, match="wait for the next frame"):
        depth.cloud(image[:100], None, info, np.eye(4))


def test_a_colour_image_is_read_from_its_jpeg():
    rgb = np.zeros((8, 8, 3), np.uint8)
    rgb[..., 0] = 200
    ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert depth.decode_rgb(jpeg.tobytes())[4, 4] == pytest.approx([200, 0, 0], abs=3)
    with pytest.raises(DepthError, match="JPEG"):
        depth.decode_rgb(b"not a picture")


@pytest.mark.parametrize("noise", [0.0, 0.002])
@pytest.mark.parametrize("where", ["side", "top"])
def test_touching_the_can_finds_its_top_and_its_centre(noise, where):
    info = kitchen_info()
    image = kitchen_scene().depth(info, noise=noise)
    # The middle of the can's side facing the camera, or the middle of its top.
    touch = [CAN_XY[0] + CAN_R, CAN_XY[1], 0.02] if where == "side" else [CAN_XY[0], CAN_XY[1], CAN_TOP]
    u, v = pixel_of(info, touch)
    found = depth.object_at(image, info, depth.pose_matrix(info.pose), u, v)
    tolerance = 0.004 if noise == 0 else 0.012
    assert found.kind == "object"
    assert found.top == pytest.approx(CAN_TOP, abs=tolerance)
    assert found.centre[:2] == pytest.approx(CAN_XY, abs=tolerance)
    assert found.height == pytest.approx(CAN_TOP - COUNTER, abs=tolerance)
    assert found.width == pytest.approx(2 * CAN_R, abs=2 * tolerance)
    assert found.support == pytest.approx(COUNTER, abs=0.005)


def test_touching_a_box_finds_its_top_and_its_centre():
    info = kitchen_info()
    box = (0.3 - 0.05, -0.2 - 0.035, COUNTER, 0.3 + 0.05, -0.2 + 0.035, COUNTER + 0.3)
    image = Scene(boxes=[box]).depth(info)
    u, v = pixel_of(info, [0.35, -0.2, COUNTER + 0.15])    # the face towards the camera
    found = depth.object_at(image, info, depth.pose_matrix(info.pose), u, v)
    assert found.kind == "object"
    assert found.top == pytest.approx(COUNTER + 0.3, abs=0.004)
    assert found.height == pytest.approx(0.3, abs=0.004)
    assert found.centre[:2] == pytest.approx([0.3, -0.2], abs=0.01)


def test_touching_the_counter_is_a_surface_not_an_object():
    info = kitchen_info()
    image = kitchen_scene().depth(info)
    u, v = pixel_of(info, [0.3, 0.1, COUNTER])
    found = depth.object_at(image, info, depth.pose_matrix(info.pose), u, v)
    assert found.kind == "surface" and found.height == 0
    assert found.surface == pytest.approx([0.3, 0.1, COUNTER], abs=0.005)
    assert found.top == pytest.approx(COUNTER, abs=0.005)


def test_a_touch_with_no_depth_nearby_or_outside_the_picture_is_refused():
    info = kitchen_info()
    image = kitchen_scene().depth(info)
    image[100:130, 100:130] = 0
    with pytest.raises(DepthError, match="no depth at that spot"):
        depth.object_at(image, info, np.eye(4), 115, 115)
    with pytest.raises(DepthError, match="outside the picture"):
        depth.object_at(image, info, np.eye(4), 400, 10)
    # One missing pixel under the finger is not a refusal: the nearest return is used.
    image = kitchen_scene().depth(info)
    u, v = (round(c) for c in pixel_of(info, [CAN_XY[0], CAN_XY[1], CAN_TOP]))
    image[v, u] = 0
    assert depth.object_at(image, info, depth.pose_matrix(info.pose), u, v).kind == "object"


def _random_pose(rng) -> np.ndarray:
    q = rng.normal(size=4)
    t = depth.pose_matrix([*rng.uniform(-1, 1, 3), *q])
    return t


def test_marks_touched_with_the_tool_give_back_the_camera_pose():
    rng = np.random.default_rng(3)
    truth = _random_pose(rng)
    camera = rng.uniform([-0.3, -0.3, 0.8], [0.3, 0.3, 1.6], (5, 3))
    robot = depth.transform(truth, camera)
    fitted, rms = depth.fit_pose(camera, robot)
    assert fitted == pytest.approx(truth, abs=1e-9)
    assert rms == pytest.approx(0, abs=1e-9)
    # With 3 mm of noise on each mark the pose is close and the residual says how close.
    noisy = robot + rng.normal(0, 0.003, robot.shape)
    fitted, rms = depth.fit_pose(camera, noisy)
    assert 0.0005 < rms < 0.008
    assert fitted[:3, 3] == pytest.approx(truth[:3, 3], abs=0.02)
    angle = math.degrees(math.acos(np.clip((np.trace(fitted[:3, :3].T @ truth[:3, :3]) - 1) / 2, -1, 1)))
    assert angle < 2


def test_a_fit_with_too_few_marks_or_marks_in_a_line_is_refused():
    line = np.array([[0, 0, 1.0], [0.1, 0, 1.0], [0.2, 0, 1.0], [0.3, 0.001, 1.0]])
    with pytest.raises(DepthError, match="at least 3 marks.*there are 2"):
        depth.fit_pose(line[:2], line[:2])
    with pytest.raises(DepthError, match="one line"):
        depth.fit_pose(line, line + 0.5)
    with pytest.raises(DepthError, match="not a number"):
        depth.fit_pose([[0, 0, 1], [0.2, 0, 1], [0, float("nan"), 1]], [[0, 0, 1], [0.2, 0, 1], [0, 0.2, 1]])


@pytest.mark.parametrize("rgb, name", [((204, 13, 13), "red"), ((25, 153, 51), "green"), ((102, 153, 242), "blue"),
                                       ((242, 140, 25), "orange"), ((240, 240, 235), "white"), ((120, 120, 125), "grey"),
                                       ((20, 20, 22), "black"), ((230, 220, 40), "yellow"), ((150, 40, 200), "purple")])
def test_a_things_colour_is_named_from_its_pixels(rgb, name):
    picture = np.zeros((4, 6, 3), np.uint8)
    region = np.zeros((4, 6), bool)
    region[1:3, 2:5] = True
    picture[region] = rgb
    picture[~region] = (0, 0, 255)          # what is around it does not count
    assert depth.colour_name(picture, region) == name


def test_no_colour_is_named_from_a_picture_of_another_size():
    assert depth.colour_name(np.zeros((8, 8, 3), np.uint8), np.ones((4, 4), bool)) is None

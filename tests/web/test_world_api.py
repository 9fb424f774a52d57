"""The world API on the in-memory bus: a synthetic kitchen camera (depth, colour and CameraInfo
as the simulation publishes them) in front of the ideal ASIBOT and the real kinematics server.
The cloud is the scene in the robot's frame, a touch on the can offers the poses over it and
into it with their joints, a touch out of reach says why, and a camera with no pose of its
own is calibrated from marks touched with the tool."""

from __future__ import annotations

import dataclasses
import struct

import cv2
import numpy as np
import pytest

from asibot import depth, keys, messages as m, robots
from asibot.bus import Bus
from asibot.testing import wait_until
from asibot.web import world as world_module

from asibot.client import LookClient
from asibot.errors import RpcError

from ..common.scenes import CAN_R, CAN_TOP, CAN_XY, COUNTER, GREEN, Scene, kitchen_info, kitchen_scene, pixel_of
from .conftest import API_ROBOT as ROBOT, API_START as START, settle

CAMERA = "kitchen"
BASE = f"/api/robots/{ROBOT}/cameras/{CAMERA}"
RED = (200, 30, 30)


@pytest.fixture(scope="module")
def camera(web):
    """A publisher of the kitchen camera's three streams on the web fixture's bus."""
    bus = Bus("camera")
    pubs = (bus.publisher(keys.camera_depth(ROBOT, CAMERA), m.DepthImage),
            bus.publisher(keys.camera_rgb(ROBOT, CAMERA), m.RgbImage),
            bus.publisher(keys.camera_info(ROBOT, CAMERA), m.CameraInfo))
    yield pubs
    bus.close()


def show(web, camera, scene: Scene | np.ndarray, info: m.CameraInfo | None = None,
         coloured: bool = False) -> m.CameraInfo:
    """Publish one frame of `scene` (or of a depth image) and wait until the web server keeps it;
    its picture all red, or `coloured` as the scene paints its things."""
    svc = web[1]
    info = info or kitchen_info()
    image = scene if isinstance(scene, np.ndarray) else scene.depth(info, pose=kitchen_info().pose)
    if isinstance(scene, Scene) and coloured:
        rgb = scene.rgb(info, pose=kitchen_info().pose)
    else:
        rgb = np.zeros((info.height, info.width, 3), np.uint8)
        rgb[:] = RED
    ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    sent = m.DepthImage(depth=image)
    world = svc.web.world

    def kept() -> bool:
        # Sent again until kept, as a camera sends frame after frame: the server subscribes to
        # pictures only once a page asks for them (web/ondemand.py), and a frame before that is lost.
        camera[0].put(sent)
        camera[1].put(m.RgbImage(jpeg=jpeg.tobytes(), width=info.width, height=info.height))
        camera[2].put(info)
        try:
            newest = svc.web.cameras.newest(ROBOT, CAMERA)
            return (np.array_equal(world._depth(ROBOT, CAMERA)[1], image) and world._info(ROBOT, CAMERA) == info
                    and newest is not None and newest.jpeg == jpeg.tobytes())
        except Exception:
            return False
    wait_until(kept, timeout=5)
    return info


@pytest.fixture
def api(web, camera):
    settle(web)
    client, svc, driver, server = web
    client.delete(f"{BASE}/calibration")
    yield client


def refused(reply, status: int, *words: str) -> str:
    assert reply.status_code == status, reply.text
    message = reply.json()["message"]
    for w in words:
        assert w in message, message
    return message


def test_the_cloud_is_the_kitchen_in_the_robot_frame_in_the_camera_colours(web, camera, api):
    show(web, camera, kitchen_scene())
    listing = api.get(f"/api/robots/{ROBOT}/depth-cameras").json()["cameras"]
    assert listing == [{"name": CAMERA, "width": 320, "height": 240, "picture": True, "pose_from": "camera"}]
    reply = api.get(f"{BASE}/cloud")
    assert reply.status_code == 200 and reply.headers["content-type"] == "application/octet-stream"
    body = reply.content
    (n,) = struct.unpack_from("<I", body)
    assert n == int(reply.headers["x-point-count"]) and 4000 <= n <= 5000 and len(body) == 4 + 15 * n
    xyz = np.frombuffer(body, "<f4", 3 * n, 4).reshape(n, 3)
    rgb = np.frombuffer(body, np.uint8, 3 * n, 4 + 12 * n).reshape(n, 3)
    on_can = np.hypot(xyz[:, 0] - CAN_XY[0], xyz[:, 1] - CAN_XY[1]) < 0.034
    assert on_can.sum() >= 5 and xyz[~on_can, 2] == pytest.approx(COUNTER, abs=1e-3)
    assert rgb.mean(axis=0) == pytest.approx(RED, abs=6)


def test_the_same_cloud_again_is_a_304_and_a_changed_one_has_a_new_tag(web, camera, api):
    """A still world's camera sends the same pictures again: the cloud keeps its ETag, a page
    that names it gets a 304 and draws nothing again; a changed picture is a new cloud."""
    show(web, camera, kitchen_scene())
    first = api.get(f"{BASE}/cloud")
    tag = first.headers["etag"]
    show(web, camera, kitchen_scene())                       # the same pictures, new frames
    again = api.get(f"{BASE}/cloud", headers={"If-None-Match": tag})
    assert again.status_code == 304 and again.headers["etag"] == tag and again.content == b""
    assert api.get(f"{BASE}/cloud").content == first.content      # without the tag: the cloud
    show(web, camera, Scene(cylinders=[(CAN_XY[0] + 0.05, CAN_XY[1], CAN_R, COUNTER, CAN_TOP)]))   # the can moved
    changed = api.get(f"{BASE}/cloud", headers={"If-None-Match": tag})
    assert changed.status_code == 200 and changed.headers["etag"] != tag and changed.content != first.content


def test_touching_the_can_offers_above_it_and_reach_it_with_their_joints(web, camera, api):
    info = show(web, camera, kitchen_scene())
    spec = robots.get(ROBOT)
    u, v = pixel_of(info, [CAN_XY[0] + 0.033, CAN_XY[1], 0.0])      # the can's side facing the camera
    reply = api.post(f"{BASE}/touch", json={"u": u, "v": v})
    assert reply.status_code == 200, reply.text
    touched = reply.json()
    assert touched["says"] == "a red object 12 cm tall, 0.50 m away" and touched["colour"] == "red"
    assert touched["name"] == "red-object-1"
    assert touched["found"]["kind"] == "object" and touched["found"]["top"] == pytest.approx(CAN_TOP, abs=0.005)
    above, reach = touched["above"], touched["reach"]
    fingers = spec.finger_length
    assert above["point"] == pytest.approx([*CAN_XY, CAN_TOP + world_module.ABOVE_HEIGHT + fingers, 180, 0], abs=0.006)
    # The grasp of the worked example: the fingertips 3 cm below the top, at the centre.
    assert reach["point"] == pytest.approx([*CAN_XY, CAN_TOP - spec.grip_depth + fingers, 180, 0], abs=0.006)
    for candidate in (above, reach):
        assert candidate["unreachable"] is None and len(candidate["joints"]) == 5
        # The joints put the tool at the point: the kinematics' own inverse, as /inv answers it.
        same = api.post(f"/api/robots/{ROBOT}/inv", json={"point": candidate["point"]}).json()["joints"]
        assert candidate["joints"] == pytest.approx(same, abs=1e-6)
    assert touched["names"] == spec.joint_names


def test_touching_out_of_reach_answers_with_the_kinematics_sentence(web, camera, api):
    info = show(web, camera, Scene(wall=-0.3))
    u, v = pixel_of(info, [-0.3, 1.3, 0.3])          # the back wall, far to the arm's left
    reply = api.post(f"{BASE}/touch", json={"u": u, "v": v})
    assert reply.status_code == 200, reply.text
    touched = reply.json()
    assert touched["above"]["joints"] is None and touched["reach"]["joints"] is None
    sentence = touched["above"]["unreachable"]
    try:
        web[1].web.motion.inverse(ROBOT, touched["above"]["point"])
    except Exception as exc:       # the kinematics' own refusal, word for word
        assert sentence == exc.message
    else:
        pytest.fail("the kinematics reached a point on the wall 1.3 m to the arm's left")


def test_bad_touches_are_refused_with_a_sentence(web, camera, api):
    show(web, camera, kitchen_scene())
    refused(api.post(f"{BASE}/touch", json={"u": 500, "v": 10}), 400, "outside the picture")
    refused(api.post(f"{BASE}/touch", json={"u": -1, "v": 10}), 422, "u")
    refused(api.post(f"{BASE}/touch", json={"u": 10}), 422, "v")
    refused(api.post(f"/api/robots/{ROBOT}/cameras/attic/touch", json={"u": 1, "v": 1}), 503, "no depth camera 'attic'")
    refused(api.get(f"/api/robots/{ROBOT}/cameras/attic/cloud"), 503, "kitchen")
    refused(api.post(f"/api/robots/nobody/cameras/{CAMERA}/touch", json={"u": 1, "v": 1}), 503, "not connected")
    show(web, camera, Scene(floor=None))          # the camera sees nothing at all
    refused(api.post(f"{BASE}/touch", json={"u": 160, "v": 120}), 400, "no depth at that spot")


def _arm_at(web, joints_deg) -> list[float]:
    """Put the ideal arm at `joints_deg` and wait for its new point."""
    client, svc, driver, server = web
    before = svc.fleet.point(ROBOT)
    driver.set_joints(np.radians(joints_deg))
    wait_until(lambda: svc.fleet.point(ROBOT) != before, timeout=5)
    return svc.fleet.point(ROBOT)


def test_a_camera_with_no_pose_is_calibrated_from_marks_touched_with_the_tool(web, camera, api):
    """A real camera says nothing of where it stands: touch and cloud ask for a calibration;
    marks paired with the tool give back its true pose, which is used from then on."""
    spec = robots.get(ROBOT)
    true_info = kitchen_info()
    truth = depth.pose_matrix(true_info.pose)
    unknown = dataclasses.replace(true_info, pose=[])
    show(web, camera, kitchen_scene(), unknown)
    refused(api.post(f"{BASE}/touch", json={"u": 100, "v": 100}), 503, "calibrate the camera first")
    refused(api.get(f"{BASE}/cloud"), 503, "calibrate the camera first")
    assert api.get(f"/api/robots/{ROBOT}/depth-cameras").json()["cameras"][0]["pose_from"] is None
    refused(api.post(f"{BASE}/calibration/solve"), 400, "at least 3 marks")

    first_tip = None
    try:
        # Four tool points in front of the camera, not in one plane; the arm is put there.
        for point in ([0.4, 0.0, 0.1, 180, 0], [0.5, 0.3, 0.25, 150, 0], [0.3, -0.25, 0.05, 180, 0],
                      [0.45, 0.2, 0.4, 170, 0]):
            joints = web[1].web.motion.inverse(ROBOT, point)
            tip = world_module.fingertips(_arm_at(web, joints), spec)
            first_tip = first_tip or tip
            seen = depth.transform(np.linalg.inv(truth), np.array([tip]))[0]
            u, v = depth.project(unknown, seen)
            # The mark's pixel is a whole pixel: move the picture's centre by the fraction, so
            # the pair is exact and the fit must give back the true pose.
            pixel = (round(u), round(v))
            assert 0 <= pixel[0] < unknown.width and 0 <= pixel[1] < unknown.height, pixel
            info = dataclasses.replace(unknown, cx=unknown.cx + pixel[0] - u, cy=unknown.cy + pixel[1] - v)
            # A wall facing the camera, as deep as the mark.
            show(web, camera, np.full((info.height, info.width), seen[2], np.float32), info)
            reply = api.post(f"{BASE}/calibration/spot", json={"u": pixel[0], "v": pixel[1]})
            assert reply.status_code == 200, reply.text
            # The fingertips on the mark hide it from the camera: what it saw at the touch counts.
            show(web, camera, np.full((info.height, info.width), seen[2] - 0.05, np.float32), info)
            reply = api.post(f"{BASE}/calibration/marks")
            assert reply.status_code == 200, reply.text
    finally:
        web[2].set_joints(START)
    marks = api.get(f"{BASE}/calibration").json()["marks"]
    assert len(marks) == 4 and marks[0]["tool"] == pytest.approx(first_tip, abs=1e-6)
    solved = api.post(f"{BASE}/calibration/solve").json()
    assert solved["residual_mm"] == pytest.approx(0, abs=0.5)
    assert depth.pose_matrix(solved["pose"]) == pytest.approx(truth, abs=1e-3)
    assert api.get(f"/api/robots/{ROBOT}/depth-cameras").json()["cameras"][0]["pose_from"] == "calibration"
    # From now on the camera's picture is in the robot's frame: touching the can finds it.
    show(web, camera, kitchen_scene(), unknown)
    u, v = pixel_of(true_info, [CAN_XY[0], CAN_XY[1], CAN_TOP])
    touched = api.post(f"{BASE}/touch", json={"u": u, "v": v}).json()
    assert touched["found"]["centre"][:2] == pytest.approx(CAN_XY, abs=0.006)
    # Start again: the marks and the pose are gone, and the camera asks again.
    assert api.delete(f"{BASE}/calibration").json() == {"marks": [], "pose": None, "residual_mm": None}
    refused(api.get(f"{BASE}/cloud"), 503, "calibrate the camera first")


def test_calibration_refuses_marks_in_a_line_and_keeps_nothing_bad(web, camera, api):
    show(web, camera, kitchen_scene())
    refused(api.post(f"{BASE}/calibration/marks"), 400, "Touch the mark in the picture first")
    for _ in range(3):        # the arm does not move: three marks at one place
        assert api.post(f"{BASE}/calibration/spot", json={"u": 160, "v": 120}).status_code == 200
        assert api.post(f"{BASE}/calibration/marks").status_code == 200
    refused(api.post(f"{BASE}/calibration/solve"), 400, "one line")
    assert api.get(f"{BASE}/calibration").json()["pose"] is None
    refused(api.post(f"{BASE}/calibration/spot", json={"u": 999, "v": 1}), 400, "outside the picture")
    refused(api.post(f"{BASE}/calibration/marks"), 400, "Touch the mark in the picture first")
    assert len(api.get(f"{BASE}/calibration").json()["marks"]) == 3


def test_a_touched_pose_is_kept_as_a_named_point(web, camera, api):
    reply = api.post("/api/points", json={"values": [0.0, 0.5, 0.09, 180, 0]})
    assert reply.status_code == 200, reply.text
    name = reply.json()["name"]
    assert any(p["name"] == name and p["values"] == [0.0, 0.5, 0.09, 180, 0] for p in api.get("/api/points").json()["points"])
    assert api.post("/api/points", json={"values": [0.0, 0.5, 0.09, 180, 0], "name": "can"}).json()["name"] == "can"
    refused(api.post("/api/points", json={"values": [0.0, 0.5, 0.09, 180, 0], "name": "can"}), 409, "can")
    refused(api.post("/api/points", json={"values": [0.0, 0.5, 0.09, 180]}), 422, "values")


# --- issue 52: a taught thing, found where it stands now --------------------------------------
def test_a_taught_can_is_found_where_it_stands_now_through_the_bus(web, camera, api):
    """What a task's program asks (LookClient.find on keys.look_rpc): the can taught at CAN_XY,
    moved 12 cm, is found there with the points above it and to grasp it; gone, the answer says
    what the camera sees instead; a bad thing is a sentence."""
    taught = {"name": "red can", "colour": "red", "height": CAN_TOP - COUNTER, "width": 2 * CAN_R,
              "where": [CAN_XY[0], CAN_XY[1], (CAN_TOP + COUNTER) / 2]}
    look = LookClient.on(web[1].fleet.bus, ROBOT, timeout=15)
    moved = (CAN_XY[0] - 0.05, CAN_XY[1] + 0.11)
    show(web, camera, Scene(cylinders=[(moved[0], moved[1], CAN_R, COUNTER, CAN_TOP)], cylinder_colours=[RED]),
         coloured=True)
    found = look.find(taught)
    assert found["reach"][:2] == pytest.approx(moved, abs=0.02)      # depth.object_at's centre, seen from afar
    assert found["above"][:2] == found["reach"][:2] and found["above"][2] > found["reach"][2] + 0.1
    assert found["moved"] == pytest.approx(0.121, abs=0.02)
    assert found["says"] == f"I see the red can, {found['moved'] * 100:.0f} cm from where it was taught."
    green_box = (0.3 - 0.04, -0.2 - 0.04, COUNTER, 0.3 + 0.04, -0.2 + 0.04, COUNTER + 0.09)
    show(web, camera, Scene(boxes=[green_box], box_colours=[GREEN]), coloured=True)
    with pytest.raises(RpcError) as gone:
        look.find(taught)
    assert gone.value.code == "not_found"
    assert gone.value.message == "I looked for the red can and see a green object 9 cm tall, but no red can."
    with pytest.raises(RpcError, match="The thing to look for is not valid: .*height") as bad:
        look.find({**taught, "height": True})
    assert bad.value.code == "bad_request"

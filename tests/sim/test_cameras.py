"""Depth measures known distances (rendered and ray cast alike); RGB and intrinsics are right."""

import time

import cv2
import mujoco
import numpy as np
import pytest

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.sim.cameras import Camera, Intrinsics
from asibot.sim.service import Options, SimService
from asibot.sim.simulation import Simulation
from asibot.testing import wait_until

ROBOT = "pioneer-sim"


@pytest.fixture
def front(apartment):
    cam = Camera(apartment.model, "front", 160, 120, apartment.scene.base.body)
    yield cam
    cam.close()


@pytest.mark.parametrize("method", ["render", "ray"])
def test_depth_of_the_wall_ahead_is_its_distance(apartment, front, method):
    # The robot starts at x = 1.0 facing +x; the front camera sits 0.32 m ahead of its centre;
    # the middle wall's west face is at x = 5.0 - 0.05 (worlds/apartment.xml).
    depth = front.depth(apartment.data, method)
    assert depth.dtype == np.float32 and depth.shape == (120, 160)
    patch = depth[50:70, 70:90]
    assert np.allclose(patch, 4.95 - 1.32, atol=2e-3)


def test_render_and_ray_agree_everywhere(apartment, front):
    a, b = front.depth(apartment.data, "render"), front.depth(apartment.data, "ray")
    both = (a > 0) & (b > 0)
    assert both.mean() > 0.9
    # they may differ only on silhouette edges (rasterised coverage vs the pixel-centre ray)
    assert np.mean(np.abs(a - b)[both] < 5e-3) > 0.99


def test_unknown_depth_method_is_refused(apartment, front):
    with pytest.raises(ValueError, match="render' or 'ray"):
        front.depth(apartment.data, "lidar")


def test_camera_info_gives_intrinsics_and_the_mounting_pose(apartment, front):
    info = front.info(apartment.data)
    assert (info.width, info.height) == (160, 120)
    assert info.fx == pytest.approx(60 / np.tan(np.radians(22.5)))
    assert (info.cx, info.cy) == (79.5, 59.5)
    assert info.pose[:3] == pytest.approx([0.32, 0.0, 0.3])
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.array(info.pose[3:]))
    rot = rot.reshape(3, 3)
    assert rot[:, 2] == pytest.approx([1, 0, 0], abs=1e-9)   # optical axis looks forward
    assert rot[:, 1] == pytest.approx([0, 0, -1], abs=1e-9)  # image y points down


def test_kitchen_rgb_is_a_jpeg_showing_the_red_can(kitchen):
    cam = Camera(kitchen.model, "kitchen", 320, 240, kitchen.scene.arm_base_body)
    try:
        img = cam.rgb_jpeg(kitchen.data)
    finally:
        cam.close()
    bgr = cv2.imdecode(np.frombuffer(img.jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert bgr.shape == (240, 320, 3) and (img.width, img.height) == (320, 240)
    b, g, r = (bgr[..., i].astype(int) for i in range(3))
    red = (r > 120) & (g < 60) & (b < 60)
    assert red.sum() > 30, "the red can should be in view of the kitchen camera"


def test_intrinsics_refuse_tiny_images():
    with pytest.raises(ValueError, match="at least"):
        Intrinsics.from_fovy(1, 1, 45)


def test_every_image_of_a_frame_is_stamped_when_the_world_was_copied(memory_bus, monkeypatch):
    """Nav places a scan where the robot was at the scan's stamp. The cameras render one after
    the other from one copy of the world, 30-80 ms each on a loaded machine (slowed here to
    40 ms): each image, and its CameraInfo, carries the moment of that copy, not the end of
    its own render."""
    copied: list[int] = []
    copy, render = Simulation.copy_positions, Camera.depth_render

    def copy_and_note(self, out):
        copy(self, out)
        copied.append(m.now_ns())

    def slow_render(self, data):
        time.sleep(0.04)
        return render(self, data)

    monkeypatch.setattr(Simulation, "copy_positions", copy_and_note)
    monkeypatch.setattr(Camera, "depth_render", slow_render)
    svc_bus, user = Bus("sim"), Bus("test")
    stamps: dict[str, list[int]] = {"front": [], "back": [], "rgb": [], "front info": []}
    for name in ("front", "back"):
        user.subscribe(keys.camera_depth(ROBOT, name), m.DepthImage, lambda msg, n=name: stamps[n].append(msg.stamp))
    user.subscribe(keys.camera_rgb(ROBOT, "rgb"), m.RgbImage, lambda msg: stamps["rgb"].append(msg.stamp))
    user.subscribe(keys.camera_info(ROBOT, "front"), m.CameraInfo, lambda msg: stamps["front info"].append(msg.stamp))
    svc = SimService(svc_bus, Simulation(ROBOT, odom_noise=(0.0, 0.0)), Options(camera_hz=5.0))
    try:
        wait_until(lambda: all(len(s) >= 3 for s in stamps.values()), 20, message=lambda: f"frames: {stamps}")
    finally:
        svc.close()
        user.close()
        svc_bus.close()
    for i in range(3):
        frame = {name: s[i] for name, s in stamps.items()}
        assert len(set(frame.values())) == 1, f"frame {i}: {frame}"
        # the copy is noted a moment after it was made: within 5 ms of the stamp, never 40 ms
        assert min(abs(frame["front"] - t) for t in copied) < 5_000_000, (frame, copied)


def test_a_picture_nobody_subscribes_to_is_not_rendered(memory_bus):
    """Rendering is most of the sim's CPU (60 % of a core against 23 % in the kitchen): a
    picture is rendered only while someone subscribes to it, as a Gazebo camera sensor. The
    CameraInfo (no rendering) is sent all the time; the first frame warms the renderers. Health
    counts what was rendered."""
    svc_bus, user = Bus("sim"), Bus("test")
    infos: list[int] = []
    pictures: list[int] = []
    user.subscribe(keys.camera_info("asibot-sim", "kitchen"), m.CameraInfo, lambda msg: infos.append(msg.stamp))
    svc = SimService(svc_bus, Simulation("asibot-sim"), Options(camera_hz=20.0))
    try:
        def rendered() -> dict[str, int]:
            return svc.health()["pictures_rendered"]
        wait_until(lambda: len(infos) >= 6, 20, message=lambda: f"{len(infos)} CameraInfo")
        assert rendered() == {"depth": 1, "rgb": 1}, "only the first frame, which warms the renderers"
        watch = user.subscribe(keys.camera_rgb("asibot-sim", "kitchen"), m.RgbImage,
                               lambda msg: pictures.append(msg.stamp))
        wait_until(lambda: len(pictures) >= 3, 10, message=lambda: f"{len(pictures)} pictures")
        assert rendered()["depth"] == 1, "the depth image has still no subscriber"
        user.undeclare(watch)
        seen, after = rendered()["rgb"], len(infos)
        wait_until(lambda: len(infos) >= after + 6, 10)
        assert rendered()["rgb"] <= seen + 1, "a frame may be under way as the subscriber goes, no more"
    finally:
        svc.close()
        user.close()
        svc_bus.close()


def test_a_still_world_is_sent_again_and_a_moved_one_rendered_again(memory_bus):
    """A picture of a world that has not moved is the last one again, with the new frame's stamp
    (rendering a still kitchen was 0.3 of a core); a moved can is in the next picture."""
    svc_bus, user = Bus("sim"), Bus("test")
    pictures: list[m.RgbImage] = []
    sim = Simulation("asibot-sim")
    svc = SimService(svc_bus, sim, Options(camera_hz=20.0))
    try:
        def rendered() -> int:
            return svc.health()["pictures_rendered"].get("rgb", 0)
        user.subscribe(keys.camera_rgb("asibot-sim", "kitchen"), m.RgbImage, pictures.append)
        # The can and the arm settle in their first moments: wait for a picture sent again.
        wait_until(lambda: len(pictures) >= 2 and pictures[-1].jpeg == pictures[-2].jpeg, 20,
                   message=lambda: f"{len(pictures)} pictures, {rendered()} rendered, none sent again")
        still, seen = rendered(), len(pictures)
        wait_until(lambda: len(pictures) >= seen + 6, 10)
        assert rendered() == still, "a still world was rendered again"
        stamps = [p.stamp for p in pictures[seen:]]
        assert stamps == sorted(set(stamps)), "each frame sent again has its own stamp"

        can = sim.object_position("red_can")
        sim.set_object_pose("red_can", [can[0] + 0.1, can[1], can[2]])
        seen = len(pictures)
        wait_until(lambda: rendered() > still and len(pictures) > seen + 1, 10,
                   message="the moved can was not rendered")
        moved = cv2.imdecode(np.frombuffer(pictures[-1].jpeg, np.uint8), cv2.IMREAD_COLOR)
        before = cv2.imdecode(np.frombuffer(pictures[seen - 1].jpeg, np.uint8), cv2.IMREAD_COLOR)
        assert np.abs(moved.astype(int) - before.astype(int)).max() > 50, "the picture did not change"
    finally:
        svc.close()
        user.close()
        svc_bus.close()

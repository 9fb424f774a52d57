"""Touch to reach, in Debian's chromium on the kitchen simulation: the kitchen camera's picture
sits beside the Cartesian jog controls; clicking the red can in it (its pixel found by
projecting the can's known position through the camera's CameraInfo) offers "Go above it",
shown as the ghost; Move takes the arm there; a touch on the far wall answers with the
kinematics' own sentence; and the 3D view draws the camera's points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asibot import depth, keys, robots
from asibot.messages import CameraInfo
from asibot.testing import wait_until

from .conftest import API_ROBOT as ROBOT, fresh_page, screenshot

pytestmark = pytest.mark.slow     # the kitchen simulation and chromium: the arm moves in real time

CAMERA = "kitchen"
#: The red can's centre in the arm's base frame, m, and its radius (kitchen.xml).
CAN, CAN_R = (0.0, 0.5, 0.02), 0.033
#: A point of the back wall, far to the arm's left, m: seen by the camera, out of the arm's reach.
WALL = (-0.3, 1.3, 0.3)


def camera_info(kitchen) -> CameraInfo:
    got: list[CameraInfo] = []
    sub = kitchen.bus.subscribe(keys.camera_info(ROBOT, CAMERA), CameraInfo, got.append)
    try:
        wait_until(lambda: got, timeout=10)
    finally:
        sub.close()
    return got[-1]


def pixel_of(info: CameraInfo, point) -> tuple[float, float]:
    """Where a point of the arm's frame shows in the camera's picture."""
    seen = depth.transform(np.linalg.inv(depth.pose_matrix(info.pose)), np.array([point]))[0]
    return depth.project(info, seen)


def click_pixel(page, u: float, v: float):
    """Click image pixel (u, v) of the camera picture, whatever size it is drawn."""
    picture = page.locator("img.camera-picture")
    picture.scroll_into_view_if_needed()
    box = picture.bounding_box()
    width, height = picture.evaluate("i => [i.naturalWidth, i.naturalHeight]")
    with page.expect_response(lambda r: r.url.endswith(f"/cameras/{CAMERA}/touch")) as reply:
        picture.click(position={"x": (u + 0.5) / width * box["width"], "y": (v + 0.5) / height * box["height"]})
    assert reply.value.ok, reply.value.text()
    return reply.value.json()


def arm_point(kitchen) -> list[float]:
    status, robot = kitchen.web("GET", f"/api/robots/{ROBOT}")
    return robot["point"]


@pytest.mark.parametrize("size", [(1280, 800), (390, 844)], ids=["laptop", "phone"])
def test_touch_the_can_go_above_it_and_the_wall_is_out_of_reach(browser, kitchen, size):
    info = camera_info(kitchen)
    with fresh_page(browser, kitchen.web_url, size=size) as page:
        page.evaluate("location.hash = 'cartesian'")
        picture = page.locator("img.camera-picture")
        picture.wait_for(timeout=10000)
        wait_until(lambda: picture.evaluate("i => i.complete && i.naturalWidth > 0"), timeout=15)
        # Beside the jog controls on a laptop (to their right, side by side); under them on a phone.
        jog = page.locator(".jog-panel").bounding_box()
        cam = page.locator(".camera-panel").bounding_box()
        if size[0] >= 1000:
            assert cam["x"] >= jog["x"] + jog["width"] - 1 and cam["y"] < jog["y"] + jog["height"]
        # The 3D view draws the camera's points.
        viewer = page.locator(".viewer")
        wait_until(lambda: int(viewer.get_attribute("data-points") or 0) > 1000, timeout=15)
        # A still kitchen: the page names the cloud it has, and is told it has it (nothing to draw again).
        clouds: list[int] = []
        page.on("response", lambda r: clouds.append(r.status) if r.url.endswith(f"/cameras/{CAMERA}/cloud") else None)
        wait_until(lambda: page.wait_for_timeout(100) or clouds.count(304) >= 2, timeout=10,
                   message=lambda: f"the page's cloud requests were answered {clouds}")

        # The can's side facing the camera: its centre pushed towards the camera by its radius.
        cam_xy = np.array(info.pose[:2])
        towards = (cam_xy - CAN[:2]) / np.linalg.norm(cam_xy - CAN[:2])
        side = (CAN[0] + towards[0] * CAN_R, CAN[1] + towards[1] * CAN_R, CAN[2])
        touched = click_pixel(page, *pixel_of(info, side))
        says = page.locator(".touch-says")
        says.wait_for(timeout=10000)
        assert "a red object 12 cm tall, 0.50 m away" in says.inner_text(), says.inner_text()
        above = touched["above"]
        assert above["point"][:2] == pytest.approx(CAN[:2], abs=0.015) and above["joints"]
        page.locator(".touch-result button[data-offer=above]").click()
        wait_until(lambda: viewer.get_attribute("data-ghost") not in (None, "hidden"), timeout=5)
        ghost = [float(d) for d in viewer.get_attribute("data-ghost").split()]
        assert ghost == pytest.approx(above["joints"], abs=0.1)
        screenshot(page, f"touch-to-reach-{size[0]}x{size[1]}")
        page.get_by_role("button", name="Move: Go above it").click()
        wait_until(lambda: math.dist(arm_point(kitchen)[:3], above["point"][:3]) < 0.01, timeout=60, interval=0.3)

        # The far wall: the kinematics says why the arm cannot go there, in its own words.
        far = click_pixel(page, *pixel_of(info, WALL))
        assert far["above"]["joints"] is None
        status, refused = kitchen.web("POST", f"/api/robots/{ROBOT}/inv", {"point": far["above"]["point"]})
        assert status >= 400 and refused["message"] == far["above"]["unreachable"]
        sentence = page.locator(".touch-result .unreachable[data-offer=above]")
        sentence.wait_for(timeout=5000)
        assert refused["message"] in sentence.inner_text()
        screenshot(page, f"touch-unreachable-{size[0]}x{size[1]}")

        # Enlarge fills the panel, and back; the cross-hair can be moved without touching.
        normal = picture.bounding_box()
        page.get_by_role("button", name="Enlarge").click()
        big = picture.bounding_box()
        assert big["width"] > normal["width"] * (1.2 if size[0] >= 1000 else 0.99)
        assert page.locator(".camera-panel").bounding_box()["width"] > page.locator(".world-columns").bounding_box()["width"] * 0.95
        screenshot(page, f"camera-enlarged-{size[0]}x{size[1]}")
        page.get_by_role("button", name="Smaller").click()
        page.get_by_role("button", name="Pick a spot").click()
        page.get_by_role("button", name="Cross-hair left").click()
        with page.expect_response(lambda r: r.url.endswith(f"/cameras/{CAMERA}/touch")) as reply:
            page.get_by_role("button", name="Select this spot").click()
        assert reply.value.ok, reply.value.text()


#: The calibration's marks, in the arm's frame, m: the red can's top (its centre is CAN, its
#: height 12 cm) and two spots of the counter top (4 cm below the arm's base), spread out, not
#: in one line, all within a short swing of the arm.
MARKS = [(CAN[0], CAN[1], CAN[2] + 0.06), (0.25, 0.7, -0.04), (0.2, 0.25, -0.04)]


def move_and_wait(kitchen, kind: str, point: list[float]) -> None:
    status, answer = kitchen.web("POST", f"/api/robots/{ROBOT}/move", {"kind": kind, "values": point})
    assert status < 400, answer
    def robot() -> dict:
        return kitchen.web("GET", f"/api/robots/{ROBOT}")[1]

    def done() -> bool:      # there, and the move over (the controller takes the next one)
        now = robot()
        return math.dist(now["point"][:3], point[:3]) < 0.003 and now["state"] == "not_controlling"
    wait_until(done, timeout=60, interval=0.2,
               message=lambda: f"the arm never reached {point}: it is at {robot()['point']}, {robot()['state']}")


def test_the_camera_is_calibrated_by_touching_three_marks_with_the_fingertips(browser, kitchen):
    """The installer's walk-through, on the sim's camera whose true pose is known: touch a mark,
    put the fingertips on it, "The tool is on the mark", three times; Solve gives back the pose."""
    kitchen.bus.call(keys.driver_rpc(ROBOT, "reset_world"), {}, timeout=10)
    info = camera_info(kitchen)
    fingers = robots.get(ROBOT).fingertip_reach
    tops = [np.array(mark) for mark in MARKS]
    with fresh_page(browser, kitchen.web_url, size=(1280, 800)) as page:
        page.evaluate("location.hash = 'cartesian'")
        picture = page.locator("img.camera-picture")
        wait_until(lambda: picture.evaluate("i => i.complete && i.naturalWidth > 0"), timeout=15)
        page.get_by_role("button", name="Calibrate the camera").click()
        panel = page.get_by_role("region", name="Calibrate the camera")
        try:
            for i, top in enumerate(tops):
                u, v = pixel_of(info, top)
                box = picture.bounding_box()
                width, height = picture.evaluate("i => [i.naturalWidth, i.naturalHeight]")
                with page.expect_response(lambda r: r.url.endswith(f"/cameras/{CAMERA}/calibration/spot")) as seen:
                    picture.click(position={"x": (u + 0.5) / width * box["width"], "y": (v + 0.5) / height * box["height"]})
                assert seen.value.ok, seen.value.text()
                # The fingertips onto the mark, from above it (a few mm over, as a careful hand leaves them).
                over = [float(top[0]), float(top[1]), float(top[2]) + fingers, 180.0, 0.0]
                move_and_wait(kitchen, "movj", [*over[:2], over[2] + 0.12, 180.0, 0.0])
                move_and_wait(kitchen, "movl", [*over[:2], over[2] + 0.003, 180.0, 0.0])
                panel.get_by_role("button", name="The tool is on the mark").click()
                panel.get_by_text(f"{i + 1} mark{'s' if i else ''} so far").wait_for(timeout=10000)
                move_and_wait(kitchen, "movl", [*over[:2], over[2] + 0.12, 180.0, 0.0])
            panel.get_by_role("button", name="Solve").click()
            result = panel.locator(".calibration-result")
            result.get_by_text("Solved from 3 marks").wait_for(timeout=10000)
            screenshot(page, "calibration-solved")
            status, solved = kitchen.web("GET", f"/api/robots/{ROBOT}/cameras/{CAMERA}/calibration")
            assert solved["residual_mm"] < 5, solved
            # What counts is where the arm's work is: a spot the camera sees there is put within a
            # centimetre of where it is (the camera's 320x240 pixels are ~8 mm wide at the counter).
            found, truth = depth.pose_matrix(solved["pose"]), depth.pose_matrix(info.pose)
            workspace = np.array([*MARKS, CAN, (0.1, 0.5, 0.0)])
            moved = depth.transform(found @ np.linalg.inv(truth), workspace)
            assert np.linalg.norm(moved - workspace, axis=1).max() < 0.01, (moved, workspace)
            assert f"{solved['residual_mm']} mm" in result.inner_text()
        finally:
            kitchen.web("DELETE", f"/api/robots/{ROBOT}/cameras/{CAMERA}/calibration")
            kitchen.bus.call(keys.driver_rpc(ROBOT, "reset_world"), {}, timeout=10)

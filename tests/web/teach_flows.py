"""Two ways a carer teaches "Give me the red can" on the page, as scripts of the person's
actions, each action counted: by touch (the camera picture, the "Pick it up" steps program, the
Assigner, the Launcher; no typed coordinates, no typed code) and the way before it (typed
coordinates into the Cartesian form, a Python program written in the editor). The browser
test of issue 27 runs the first; bench/bench_teach.py runs both and prints the table."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from asibot import keys
from asibot.testing import wait_until

from .test_touch_to_reach import CAMERA, CAN_R, camera_info, pixel_of

ROBOT = "asibot-sim"
TASK, WORD = "Give me the red can", "give me the red can"
#: The arm's base in the kitchen's world frame (kitchen.xml: the station's arm_mount), m.
MOUNT = np.array([-0.2, 0.0, 0.94])
#: The points the typed way moves through, [x, y, z, rot(y'), rot(z'')] (m, deg).
ABOVE, AT, LIFTED = [0.0, 0.5, 0.21, 180, 0], [0.0, 0.5, 0.09, 180, 0], [0.0, 0.5, 0.19, 180, 0]


@dataclass
class Actions:
    """What the person did on the page: each click, touch, field filled or key, with its words."""

    page: object
    done: list[str] = field(default_factory=list)

    def click(self, locator, what: str) -> None:
        locator.click()
        self.done.append(f"click {what}")

    def fill(self, locator, text: str, what: str) -> None:
        locator.fill(text)
        self.done.append(f"type {what}")

    def choose(self, locator, value: str, what: str) -> None:
        locator.select_option(value)
        self.done.append(f"choose {what}")

    def write(self, text: str, what: str) -> None:
        self.page.keyboard.insert_text(text)
        self.done.append(f"type {what}")

    def keys(self, combo: str, what: str) -> None:
        self.page.keyboard.press(combo)
        self.done.append(f"press {what}")

    def touch_picture(self, u: float, v: float, what: str) -> dict:
        """Touch image pixel (u, v) of the camera picture, whatever size it is drawn; the touch's answer."""
        picture = self.page.locator("img.camera-picture")
        picture.scroll_into_view_if_needed()
        box = picture.bounding_box()
        width, height = picture.evaluate("i => [i.naturalWidth, i.naturalHeight]")
        with self.page.expect_response(lambda r: r.url.endswith(f"/cameras/{CAMERA}/touch")) as reply:
            picture.click(position={"x": (u + 0.5) / width * box["width"], "y": (v + 0.5) / height * box["height"]})
        self.done.append(f"touch {what}")
        assert reply.value.ok, reply.value.text()
        return reply.value.json()

    def __len__(self) -> int:
        return len(self.done)


def can_position(kitchen) -> list[float]:
    return kitchen.bus.call(keys.driver_rpc(ROBOT, "object_pose"), {"name": "red_can"})["pos"]


def tab(page, act: Actions, name: str) -> None:
    act.click(page.get_by_role("tab", name=name, exact=True), f"the {name} tab")


def can_side_pixel(kitchen) -> tuple[float, float]:
    """Where the person sees the red can in the camera picture: the middle of its side that faces
    the camera (found from the sim's truth through the camera's pose, never a fixed pixel)."""
    info = camera_info(kitchen)
    centre = np.array(can_position(kitchen)) - MOUNT                   # in the arm's frame
    towards = (np.array(info.pose[:2]) - centre[:2]) / np.linalg.norm(np.array(info.pose[:2]) - centre[:2])
    return pixel_of(info, (centre[0] + towards[0] * CAN_R, centre[1] + towards[1] * CAN_R, centre[2]))


def reset(kitchen) -> list[float]:
    """The kitchen as it started; where the can is (world frame)."""
    kitchen.bus.call(keys.driver_rpc(ROBOT, "reset_world"), {}, timeout=10)
    return can_position(kitchen)


def word_icon_save_and_launch(page, act: Actions, shot: Callable[[str], object] = lambda name: None) -> None:
    """On the Assigner, the task named: a new word chosen, the can icon, saved; then launched."""
    act.fill(page.get_by_label("New word or phrase"), WORD, "its word")
    act.click(page.get_by_role("button", name="Add and choose it"), "Add and choose it")
    page.get_by_role("button", name=WORD, exact=True).wait_for(timeout=5000)
    act.click(page.get_by_role("radio", name="Icon can"), "the can icon")
    act.click(page.get_by_role("button", name="Save task"), "Save task")
    replace = page.get_by_role("button", name="A task has this name: touch again to replace it")
    try:       # taught before on this page's stack: saving under its name asks first
        replace.wait_for(timeout=1000)
        act.click(replace, "touch again to replace the task of that name")
    except PlaywrightTimeout:
        pass
    page.get_by_text(f'Task "{TASK}" saved').wait_for(timeout=5000)
    shot("teach-3-task-saved")
    tab(page, act, "Launcher")
    act.click(page.get_by_role("button", name=f"Launch {TASK}"), f"Launch {TASK}")


def by_touch(page, kitchen, act: Actions, shot: Callable[[str], object] = lambda name: None) -> None:
    """Touch the can, make the "Pick it up" task from it with a word and an icon, launch it;
    `shot(name)` is called at each stage (a screenshot)."""
    tab(page, act, "Cartesian")
    picture = page.locator("img.camera-picture")
    wait_until(lambda: picture.evaluate("i => i.complete && i.naturalWidth > 0"), timeout=15)
    touched = act.touch_picture(*can_side_pixel(kitchen), "the red can in the camera picture")
    assert touched["reach"]["joints"], touched
    page.locator(".touch-says").wait_for(timeout=10000)
    shot("teach-1-touched")
    act.click(page.get_by_role("button", name="Pick it up: make a task"), "Pick it up: make a task")
    assigner, update = page.get_by_role("heading", name="Make a task"), page.get_by_role("button", name="Update it")
    wait_until(lambda: assigner.is_visible() or update.is_visible(), timeout=10)
    if update.is_visible():      # taught before on this stack (a bench's second run): update that program
        act.click(update, "Update it")
        assigner.wait_for(timeout=10000)
    shot("teach-2-assigner")
    act.fill(page.get_by_label("Task name"), TASK, "the task's name")
    word_icon_save_and_launch(page, act, shot)


def by_typing(page, kitchen, act: Actions, arm_still) -> None:
    """The way before touch and steps: typed points moved to and captured, a typed program."""
    tab(page, act, "Cartesian")
    act.click(page.get_by_role("button", name="Open gripper"), "Open gripper")
    page.get_by_text("Gripper open.").wait_for(timeout=10000)
    inputs = page.locator(".form-grid input")
    for point, kind, name in ((ABOVE, "movj", "above_can"), (AT, "movl", "at_can"), (LIFTED, "movl", "lifted")):
        for i, value in enumerate(point):
            act.fill(inputs.nth(i), str(value), f"{name} coordinate {i + 1}")
        act.choose(page.get_by_label("Movement"), kind, kind)
        act.click(page.get_by_role("button", name="Move", exact=True), "Move")
        arm_still(point)
        act.fill(page.get_by_label("Name of the next point"), name, "the point's name")
        act.click(page.get_by_role("button", name="Capture point"), "Capture point")
        page.get_by_role("button", name=f"Go to {name}").wait_for(timeout=5000)
    tab(page, act, "Program")
    act.fill(page.get_by_label("New program name"), "red_can", "the program's name")
    act.click(page.get_by_role("button", name="New program"), "New program")
    editor = page.locator(".cm-content")
    wait_until(lambda: "CartesianClient" in editor.inner_text(), timeout=5)
    act.click(editor, "the editor")
    act.keys("Control+a", "select all")
    act.write("import sys\nfrom asibot.client import CartesianClient\n\n"
              "simCart = CartesianClient()\nsimCart.open(sys.argv[1])\nsimCart.grip(close=False)\n", "the program's start")
    act.click(page.get_by_role("button", name="Insert point above_can"), "Insert point above_can")
    act.click(page.get_by_role("button", name="Insert point at_can"), "Insert point at_can")
    act.write("print('holding:', simCart.grip())\n", "the grip")
    act.click(page.get_by_role("button", name="Insert point lifted"), "Insert point lifted")
    act.write("simCart.close()\n", "the end")
    act.click(page.get_by_role("button", name="Save", exact=True), "Save")
    page.get_by_text("Saved red_can.py.").wait_for(timeout=5000)
    tab(page, act, "Assigner")
    act.fill(page.get_by_label("Task name"), TASK, "the task's name")
    act.choose(page.get_by_label("Program"), "red_can", "the program")
    word_icon_save_and_launch(page, act)


def run_ends(page, since: float, timeout_s: float = 120) -> str:
    """Wait until a run started after `since` (time.time()) has ended; the Launcher's output."""
    def ended() -> bool:
        status = page.evaluate("fetch('/api/run', {headers: {'X-Asibot-Session': "
                               "document.querySelector('meta[name=asibot-session]').content}}).then(r => r.json())")
        last = status.get("last") or {}
        return not status.get("running") and (last.get("started") or 0) >= since
    wait_until(ended, timeout=timeout_s, interval=0.25, message="the task's run did not end")
    return page.get_by_role("log", name="Program output").inner_text()

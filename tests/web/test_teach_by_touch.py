"""Issue 27's "done when", in Debian's chromium on the kitchen simulation: with no typed
coordinates and no typed code, a carer touches the red can in the camera picture, makes a
"Pick it up" program from it, gives the task a word and an icon, launches it from the Launcher,
and the can is lifted (the sim's truth). Issue 52: moved 12 cm, the same task finds it and
lifts it; gone, it says what it saw instead, and the arm never goes down."""

from __future__ import annotations

import time

import pytest

from asibot import keys
from asibot.testing import wait_until

from .conftest import fresh_page, screenshot
from .teach_flows import ROBOT, TASK, Actions, by_touch, can_position, can_side_pixel, reset, run_ends

pytestmark = [pytest.mark.slow, pytest.mark.timeout(400)]

#: The issue's goal: a one-button red-can task in this many actions or fewer.
GOAL_ACTIONS = 15


def test_a_carer_teaches_the_red_can_by_touch_and_it_is_lifted_then_moved_3_cm(browser, kitchen):
    start = reset(kitchen)
    with fresh_page(browser, kitchen.web_url, size=(1280, 800)) as page:
        act = Actions(page)
        since = time.time()
        by_touch(page, kitchen, act, lambda name: screenshot(page, name))
        output = run_ends(page, since)
        screenshot(page, "teach-by-touch-launched")
        assert len(act) <= GOAL_ACTIONS, "\n".join(act.done)
        assert "Close the gripper and check it holds something" in output and "done!" in output
        assert "Notice:" not in output              # every straight move was made straight
        lifted = can_position(kitchen)
        assert lifted[2] - start[2] > 0.08, f"the can is at {lifted}, it was at {start}; the run said:\n{output}"
        assert abs(lifted[0] - start[0]) < 0.02 and abs(lifted[1] - start[1]) < 0.02

        # Issue 52: the task remembers what, not where. Moved 12 cm, or 10 cm the other way and
        # 8 cm nearer, the same task finds the can where it stands and lifts it.
        for dx, dy in ((0.0, 0.12), (-0.08, -0.10)):
            reset(kitchen)
            moved = [start[0] + dx, start[1] + dy, start[2]]
            kitchen.bus.call(keys.driver_rpc(ROBOT, "set_object_pose"), {"name": "red_can", "pos": moved}, timeout=5)
            since = time.time()
            page.get_by_role("button", name=f"Launch {TASK}").click()
            output = run_ends(page, since)
            screenshot(page, f"teach-by-touch-moved-{dx:+.2f}-{dy:+.2f}")
            lifted = can_position(kitchen)
            assert lifted[2] - moved[2] > 0.08, f"moved to {moved}, the can is at {lifted}; the run said:\n{output}"
            assert "I see the red object" in output and "from where it was taught" in output, output

        # Gone from the counter: the task says what it saw instead, and the arm never went down.
        reset(kitchen)
        kitchen.bus.call(keys.driver_rpc(ROBOT, "set_object_pose"), {"name": "red_can", "pos": [start[0], start[1] + 3.0, start[2]]},
                         timeout=5)
        since = time.time()
        page.get_by_role("button", name=f"Launch {TASK}").click()
        output = run_ends(page, since)
        screenshot(page, "teach-by-touch-not-found")
        said = page.locator("main").inner_text()
        assert "I looked for the red object" in output and "no red object" in output, output
        assert "Move above" not in output, output
        assert f"{TASK}: finished." not in said

        # Taught again (the can put somewhere else): the page asks, by the button, whether to
        # update the program the task runs; updated, the same task and program, no second one.
        reset(kitchen)
        moved = [start[0] - 0.06, start[1] + 0.08, start[2]]
        kitchen.bus.call(keys.driver_rpc(ROBOT, "set_object_pose"), {"name": "red_can", "pos": moved}, timeout=5)
        page.get_by_role("tab", name="Cartesian", exact=True).click()
        picture = page.locator("img.camera-picture")
        wait_until(lambda: picture.evaluate("i => i.complete && i.naturalWidth > 0"), timeout=15)
        act.touch_picture(*can_side_pixel(kitchen), "the red can where it stands now")
        page.get_by_role("button", name="Pick it up: make a task").click()
        question = page.get_by_role("group", name="Update or make another")
        question.wait_for(timeout=10000)
        assert "A program already picks up the red object: pick_up_red_object, which “Give me the red can” runs" \
            in question.inner_text(), question.inner_text()
        screenshot(page, "teach-by-touch-again-asks")
        question.get_by_role("button", name="Update it").click()
        page.get_by_text("Updated pick_up_red_object: it picks up what you touched now, and so does “Give me the red "
                         "can”.").wait_for(timeout=10000)
        assert page.locator("#tab-cartesian[aria-selected=true]").is_visible(), "it left the Cartesian page"
        programs = [p for p in kitchen.web("GET", "/api/programs")[1]["programs"] if p.startswith("pick_up")]
        assert programs == ["pick_up_red_object"], programs

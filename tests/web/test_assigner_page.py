"""Issue 52's frictions on the Assigner, in Debian's chromium: a task saved without a name is
told so at the name field (not "Method Not Allowed." in a banner off-screen), and nothing is
sent; saving under the name of another task asks before it replaces it; deleting a task asks
first, and the notice that says it is gone can bring it back.

Only the web service runs (no robot): the Assigner's files need none."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from .conftest import _stack, fresh_page, http, screenshot

pytestmark = [pytest.mark.slow, pytest.mark.browser, pytest.mark.timeout(300)]

PROGRAM = "wave"


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """`asibot up --only web` with one program to make tasks of."""
    stack = _stack(tmp_path_factory.mktemp("assigner"), [], [])
    http(stack, "POST", "/api/programs", {"name": PROGRAM})
    yield stack
    stack.stop()


def tasks(store) -> dict[str, dict]:
    return {t["name"]: t for t in http(store, "GET", "/api/tasks")["tasks"]}


def open_assigner(page):
    page.evaluate("() => { location.hash = 'assigner'; }")
    page.get_by_role("heading", name="Make a task").wait_for(timeout=10000)
    page.get_by_role("radio", name="Icon can").wait_for(timeout=10000)


def test_a_task_without_a_name_is_told_at_the_field_and_nothing_is_sent(browser, store):
    with fresh_page(browser, store.web_url, robots=(), size=(1024, 768)) as page:
        open_assigner(page)
        sent: list[str] = []
        page.on("request", lambda r: sent.append(f"{r.method} {r.url}") if "/api/tasks/" in r.url else None)
        page.get_by_role("radio", name="Icon can").click()
        page.get_by_role("button", name="Save task").click()
        name = page.get_by_label("Task name")
        said = page.locator("#assigner-name-error")
        expect(said).to_have_text('Name the task first: the words on its button, such as "Give me the red can".')
        expect(name).to_have_attribute("aria-invalid", "true")
        expect(name).to_be_focused()
        # Beside the field, on screen at 1024x768, and not the server's "Method Not Allowed.".
        field, words = name.bounding_box(), said.bounding_box()
        assert 0 <= words["y"] - (field["y"] + field["height"]) < 60 and words["y"] + words["height"] <= 768
        assert "Method Not Allowed" not in page.locator("main").inner_text()
        assert not sent
        screenshot(page, "assigner-no-name-1024x768")
        name.fill("Wave")
        expect(said).to_be_hidden()
        expect(name).not_to_have_attribute("aria-invalid", "true")


def test_replacing_a_task_asks_first_and_deleting_one_can_be_undone(browser, store):
    http(store, "PUT", "/api/tasks/Wave%20hello", {"program": PROGRAM, "words": [], "icon": "can.svg"})
    with fresh_page(browser, store.web_url, robots=(), size=(1280, 800)) as page:
        open_assigner(page)
        page.get_by_label("Task name").fill("Wave hello")
        page.get_by_role("radio", name="Icon drink").click()
        page.get_by_role("button", name="Save task").click()
        again = page.get_by_role("button", name="A task has this name: touch again to replace it")
        again.wait_for(timeout=5000)
        assert tasks(store)["Wave hello"]["icon"] == "can.svg"          # nothing replaced yet
        again.click()
        page.get_by_text('Task "Wave hello" saved').wait_for(timeout=5000)
        assert tasks(store)["Wave hello"]["icon"] == "drink.svg"

        page.get_by_role("button", name="Delete task Wave hello").click()
        sure = page.get_by_role("button", name="Sure? Touch again to delete: Delete task Wave hello")
        sure.wait_for(timeout=5000)
        assert "Wave hello" in tasks(store)                              # the first press deletes nothing
        sure.click()
        page.get_by_text('Task "Wave hello" deleted.').wait_for(timeout=5000)
        screenshot(page, "assigner-deleted-undo")
        assert "Wave hello" not in tasks(store)
        page.locator("#notice").get_by_role("button", name="Undo").click()
        page.get_by_text('Task "Wave hello" is back.').wait_for(timeout=5000)
        back = tasks(store)["Wave hello"]
        assert (back["program"], back["icon"]) == (PROGRAM, "drink.svg")

"""Python for those who want it (issue 27, point 4), in Debian's chromium against the kitchen:
gripper buttons beside the point buttons, completion of the clients' methods with their docs,
the reference beside the editor as the server reads it from asibot.client, and a failed run told
as one sentence with its line and a single full stop, the traceback under Details, no path of
the machine anywhere on the page.
"""

from __future__ import annotations

import re

import pytest

from asibot.web import reference

from .conftest import ROOT, fresh_page, screenshot

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ROBOT = "asibot-sim"
AXE = ROOT / "services" / "web" / "frontend" / "node_modules" / "axe-core" / "axe.min.js"
WCAG = ["wcag2a", "wcag2aa", "wcag21a", "wcag21aa", "wcag22aa"]
#: Both ends reachable; the straight line between them crosses the base axis (line 8).
THROUGH_A_SINGULARITY = """\
import sys
from asibot.client import CartesianClient

simCart = CartesianClient()
simCart.open(sys.argv[1])
simCart.movj([0.5, 0.0, 1.2, 0, 0])
simCart.wait()
simCart.movl([-0.5, 0.001, 1.2, 0, 0])
simCart.wait()
"""


def http(stack, method: str, path: str, body: dict | None = None) -> dict:
    status, answer = stack.web(method, path, body)
    assert status < 400, f"{method} {path}: {status} {answer}"
    return answer or {}


@pytest.fixture
def page(browser, kitchen):
    """A fresh page (its own storage) at 1280x800 that commands asibot-sim."""
    with fresh_page(browser, kitchen.web_url, (ROBOT,), (1280, 800)) as page:
        yield page


def open_program(page, kitchen, name: str, text: str):
    """Program `name` with `text`, made through the API, then the Program tab (which lists the
    programs as it opens) with it open in the editor; the editor."""
    http(kitchen, "POST", "/api/programs", {"name": name})
    http(kitchen, "PUT", f"/api/programs/{name}", {"text": text})
    page.evaluate("() => { location.hash = 'home'; }")
    page.wait_for_selector("text=Teach the robot a task", timeout=15000)
    page.evaluate("() => { location.hash = 'program'; }")
    page.get_by_role("button", name=name, exact=True).click()
    page.get_by_role("heading", name=f"{name}.py").wait_for(timeout=10000)
    return page.locator(".cm-content")


def editor_text(page) -> str:
    return page.locator(".cm-content .cm-line").evaluate_all("(lines) => lines.map((l) => l.textContent).join('\\n')")


def methods_of(client: str) -> list[dict]:
    return next(c for c in reference.build()["clients"] if c["name"] == client)["methods"]


def test_gripper_buttons_insert_the_call_on_the_programs_own_client(page, kitchen):
    from playwright.sync_api import expect
    editor = open_program(page, kitchen, "gripper_calls",
                          "from asibot.client import CartesianClient\n\nrobot = CartesianClient('asibot-sim')\n")
    editor.click()
    page.keyboard.press("Control+End")                         # the empty last line
    page.get_by_role("button", name="Insert: open gripper").click()
    close = page.get_by_role("button", name="Insert: close gripper")
    close.focus()
    page.keyboard.press("Enter")                               # a real button: the keyboard inserts too
    expect(page.locator(".cm-content")).to_contain_text('robot.act("open")robot.act("close")', timeout=5000)
    assert editor_text(page).endswith('robot = CartesianClient(\'asibot-sim\')\nrobot.act("open")\nrobot.act("close")\n')
    # Beside the point buttons, in the same row; the same size as every button (44 px and more).
    row = page.locator(".inserts")
    assert row.get_by_role("group", name="Insert a gripper call").is_visible()
    assert row.get_by_role("group", name="Insert a point").is_visible()
    for name in ("Insert: open gripper", "Insert: close gripper"):
        box = page.get_by_role("button", name=name).bounding_box()
        assert box["height"] >= 44 and box["width"] >= 44
    screenshot(page, "program-help-1-gripper-buttons")


def test_completion_offers_the_clients_methods_with_their_signature_and_first_line(page, kitchen):
    from playwright.sync_api import expect
    open_program(page, kitchen, "complete_me",
                 "import sys\nfrom asibot.client import CartesianClient, NavClient\n\n"
                 "arm = CartesianClient(sys.argv[1])\nbase = NavClient('pioneer-sim')\n")
    page.locator(".cm-content").click()
    page.keyboard.press("Control+End")
    popup = page.locator(".cm-tooltip-autocomplete")
    page.keyboard.type("arm.mov")
    expect(popup.locator("li").first).to_be_visible(timeout=5000)
    offered = popup.locator(".cm-completionLabel").all_inner_texts()
    assert {"movj", "movl", "movv", "movjv"} <= set(offered) and "goto" not in offered
    movl = next(m for m in methods_of("CartesianClient") if m["name"] == "movl")
    # The option chosen shows its call, and its signature and its docstring's first line, as the server reads them.
    page.keyboard.type("l")
    selected = popup.locator("li[aria-selected]")
    expect(selected.locator(".cm-completionLabel")).to_have_text("movl")
    expect(selected.locator(".cm-completionDetail")).to_have_text("(point, *, duration=None, speed=None)")
    info = page.locator(".cm-completionInfo")
    expect(info).to_contain_text(f"CartesianClient.{movl['signature']}")
    expect(info).to_contain_text(movl["summary"])
    screenshot(page, "program-help-2-completion")
    page.keyboard.press("Enter")
    expect(page.locator(".cm-content")).to_contain_text("arm.movl")
    # A NavClient's name offers the base's verbs, not the arm's.
    page.keyboard.type("\nbase.")
    expect(popup.locator(".cm-completionLabel", has_text="goto").first).to_be_visible(timeout=5000)
    assert "movl" not in popup.locator(".cm-completionLabel").all_inner_texts()
    page.keyboard.press("Escape")                               # closes the list only (estop.js): nothing stops
    expect(popup).to_have_count(0)
    # Any other name (a function's parameter, say) offers the methods of both.
    page.keyboard.type("\ndef fetch(robot):\nrobot.gri")
    expect(popup.locator(".cm-completionLabel", has_text="grip").first).to_be_visible(timeout=5000)
    page.keyboard.press("Escape")
    status = http(kitchen, "GET", f"/api/robots/{ROBOT}")
    assert not status["estop"]["engaged"]


def test_the_reference_beside_the_editor_is_the_servers_from_the_docstrings(page, kitchen):
    from playwright.sync_api import expect
    open_program(page, kitchen, "read_the_docs", "from asibot.client import NavClient\n\nbase = NavClient('pioneer-sim')\n")
    panel = page.get_by_role("region", name="Python reference")
    expect(panel.get_by_role("heading", name="Python reference")).to_be_visible()
    # The program uses a NavClient: its methods are shown first.
    nav = panel.get_by_role("button", name="NavClient")
    expect(nav).to_have_attribute("aria-pressed", "true", timeout=10000)
    terms = panel.locator(".methods dt")
    expect(terms).to_have_count(len(methods_of("NavClient")))
    cart = panel.get_by_role("button", name="CartesianClient")
    cart.click()
    expect(cart).to_have_attribute("aria-pressed", "true")
    expected = methods_of("CartesianClient")
    expect(terms).to_have_count(len(expected))
    assert terms.all_inner_texts() == [m["call"] + (f" -> {m['returns']}" if m["returns"] else "") for m in expected]
    docs = panel.locator(".methods dd").all_inner_texts()
    assert docs == [m["doc"].replace("`", "") for m in expected]    # `code` spans shown as code
    act = docs[[m["name"] for m in expected].index("act")]
    assert act.startswith('Gripper "open" or "close"')
    # Beside the editor: to its right, their tops level, both on screen at 1280x800.
    editor_box = page.locator(".cm-editor").bounding_box()
    panel_box = panel.bounding_box()
    assert panel_box["x"] >= editor_box["x"] + editor_box["width"] and abs(panel_box["y"] - editor_box["y"]) < 40
    assert panel_box["x"] + panel_box["width"] <= 1280
    # The list scrolls by itself, and a keyboard can scroll it.
    methods = panel.get_by_role("region", name="Methods")
    methods.focus()
    page.keyboard.press("PageDown")
    page.wait_for_function("() => document.querySelector('.reference-body').scrollTop > 0", timeout=5000)
    screenshot(page, "program-help-3-reference")


def test_a_failed_run_is_one_sentence_with_its_line_and_the_traceback_under_details(page, kitchen):
    from playwright.sync_api import expect
    open_program(page, kitchen, "give_me_the_can", THROUGH_A_SINGULARITY)
    page.get_by_role("button", name="Run", exact=True).click()
    sentence = page.locator(".run-error-sentence")
    expect(sentence).to_be_visible(timeout=90000)
    text = sentence.inner_text()
    assert re.fullmatch(r"Line 8: The straight line passes a singularity or configuration change at \d+ % of the path: "
                        r".+; use movj for this move or pick an intermediate point\.", text), text
    assert ".." not in text
    expect(page.locator(".run-status")).to_have_text(re.compile(rf"^{ROBOT}: give_me_the_can failed\. Ended .+\.$"))
    # The traceback is behind Details; the output holds none of it, and no path of the machine.
    output = page.get_by_role("log", name="Program output")
    details_button = page.get_by_role("button", name="Details")
    expect(details_button).to_have_attribute("aria-expanded", "false")
    traceback = page.get_by_label("Traceback")
    expect(traceback).to_be_hidden()
    details_button.focus()
    page.keyboard.press("Enter")
    expect(details_button).to_have_attribute("aria-expanded", "true")
    expect(traceback).to_be_visible()
    shown = traceback.inner_text()
    assert 'File "give_me_the_can.py", line 8, in <module>' in shown and "simCart.movl([-0.5, 0.001, 1.2, 0, 0])" in shown
    assert re.search(r'File "asibot\.client", line \d+, in movl', shown), shown
    assert "asibot.errors.RpcError: The straight line passes" in shown
    whole = page.locator("#view").inner_text()
    assert "Traceback" not in output.inner_text()
    assert str(kitchen.data) not in whole and "/asibot/" not in whole and "site-packages" not in whole
    # The server says the same; the run's reason takes the page's full stop without doubling it.
    last = http(kitchen, "GET", "/api/run")["last"]
    assert last["error"] == text and last["line"] == 8 and not last["reason"].endswith(".")
    # "Show line 8" puts the cursor on the line that failed.
    page.get_by_role("button", name="Show line 8").click()
    expect(page.locator(".cm-activeLine")).to_have_text("simCart.movl([-0.5, 0.001, 1.2, 0, 0])")
    screenshot(page, "program-help-4-failed-run")
    if AXE.exists():
        page.add_script_tag(path=str(AXE))
        result = page.evaluate("(tags) => axe.run(document, { runOnly: { type: 'tag', values: tags } })", WCAG)
        assert [f"{v['id']}: {v['help']} at {[n['target'] for n in v['nodes']]}" for v in result["violations"]] == []

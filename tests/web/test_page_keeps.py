"""The page keeps what the user did (issue 27, point 5), in a real browser against both worlds
(the kitchen's asibot-sim and the apartment's pioneer-sim):

1. Esc closes what it closes (the editor's completion list, a name being changed) and the next
   Esc is the emergency stop; outside a text field one Esc stops.
2. Unsaved program text is a draft per program: it survives a tab switch and a reload, the page
   says it is unsaved, and discarding it asks first.
3. Typed form values survive a tab switch and a reload.
4. Opening the Base or Pioneer arm tab does not change the commanded robot; those tabs offer the
   switch, and the page's messages about a robot name it.
5. The Program tab and the Launcher show the current run as the server has it.
"""

from __future__ import annotations

import pytest

from asibot.testing import wait_until

from .conftest import _stack, fresh_page, screenshot

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ASIBOT, PIONEER = "asibot-sim", "pioneer-sim"
ROBOTS = (ASIBOT, PIONEER)


@pytest.fixture(scope="module")
def worlds(tmp_path_factory):
    """Both simulations (only the kitchen's arm has its kinematics) and the web page."""
    stack = _stack(tmp_path_factory.mktemp("worlds"), ["kinematics-asibot-sim", "sim-apartment"],
                   ["sim/asibot-sim", "kinematics/asibot-sim", "sim/pioneer-sim"])
    yield stack
    stack.stop()


def http(stack, method: str, path: str, body: dict | None = None) -> dict:
    status, answer = stack.web(method, path, body)
    assert status < 400, f"{method} {path}: {status} {answer}"
    return answer or {}


def engaged(worlds, robot: str) -> bool:
    return http(worlds, "GET", f"/api/robots/{robot}")["estop"]["engaged"]


@pytest.fixture
def page(browser, worlds):
    """A fresh page (its own storage) at 1280x800 that commands asibot-sim, both robots on it;
    both emergency stops released after the test."""
    try:
        with fresh_page(browser, worlds.web_url, ROBOTS, (1280, 800)) as page:
            commanding(page, ASIBOT).wait_for(timeout=10000)
            yield page
    finally:
        for robot in ROBOTS:
            http(worlds, "POST", f"/api/robots/{robot}/release")


def second_esc_stops(page, worlds, hint) -> None:
    """The first Esc was taken (the hint says so and nothing stopped); the second stops both
    robots, which are then released for what the test does next."""
    hint.get_by_text(HINT).wait_for(timeout=5000)
    assert not any(engaged(worlds, r) for r in ROBOTS)
    page.keyboard.press("Escape")
    wait_until(lambda: all(engaged(worlds, r) for r in ROBOTS), timeout=10)
    for robot in ROBOTS:
        http(worlds, "POST", f"/api/robots/{robot}/release")


def commanding(page, robot: str):
    """The Connection Manager's button that says the page commands `robot`."""
    return page.get_by_role("button", name=f"Commanding {robot}", exact=True)


def go(page, view: str, ready: str) -> None:
    page.evaluate("(v) => { location.hash = v; }", view)
    page.wait_for_selector(ready, timeout=15000)


def program(worlds, name: str, text: str) -> None:
    http(worlds, "POST", "/api/programs", {"name": name})
    http(worlds, "PUT", f"/api/programs/{name}", {"text": text})


def open_program(page, name: str):
    go(page, "program", ".cm-content")
    page.get_by_role("button", name=name).click()
    page.get_by_role("heading", name=f"{name}.py").wait_for(timeout=10000)
    return page.locator(".cm-content")


# --- 1. Esc ---------------------------------------------------------------------------------------
HINT = "Esc again: emergency stop"


def test_esc_closes_the_completion_list_and_the_second_esc_stops(page, worlds):
    estop = page.get_by_role("button", name="Emergency stop")
    assert "Esc" in estop.inner_text() and "Esc" in estop.get_attribute("title")
    assert estop.get_attribute("aria-keyshortcuts") == "Escape"
    assert "two Esc presses in a row always stop" in page.locator("#esc-rule").inner_text()   # the Home page's help
    screenshot(page, "keeps-home-esc-rule")
    hint = page.locator("#estop-hint")

    program(worlds, "esc_check", "import sys\nprint(sys.argv)\n")
    editor = open_program(page, "esc_check")
    editor.click()
    page.keyboard.press("Control+End")
    page.keyboard.type("\npri")
    completions = page.locator(".cm-tooltip-autocomplete")
    completions.wait_for(timeout=5000)
    screenshot(page, "keeps-esc-completions")
    page.keyboard.press("Escape")                                  # closes the list, and only that
    completions.wait_for(state="detached", timeout=5000)
    hint.get_by_text(HINT).wait_for(timeout=5000)                  # the key was taken: this Esc did not stop
    assert not any(engaged(worlds, r) for r in ROBOTS)
    assert page.evaluate("document.activeElement.closest('.cm-editor') !== null"), "the editor lost the focus"
    screenshot(page, "keeps-esc-armed")
    page.keyboard.press("Escape")                                  # the second Esc stops
    wait_until(lambda: all(engaged(worlds, r) for r in ROBOTS), timeout=10, message="two Esc presses did not stop")
    wait_until(lambda: hint.inner_text() == "", timeout=5)
    for robot in ROBOTS:
        http(worlds, "POST", f"/api/robots/{robot}/release")

    # In the editor with nothing open: the first Esc only warns; a typed key starts over.
    editor.click()
    page.keyboard.press("Escape")
    hint.get_by_text(HINT).wait_for(timeout=5000)
    page.keyboard.type("x")
    wait_until(lambda: hint.inner_text() == "", timeout=5)
    page.keyboard.press("Escape")
    second_esc_stops(page, worlds, hint)

    # A name being changed: Esc cancels it; the next Esc stops.
    page.get_by_role("button", name="Rename", exact=True).click()
    rename = page.get_by_label("New name of the program")
    rename.wait_for()
    page.keyboard.press("Escape")
    rename.wait_for(state="detached", timeout=5000)
    second_esc_stops(page, worlds, hint)

    # Anywhere else one Esc stops: the focus on a button.
    page.get_by_role("button", name="Check syntax").focus()
    page.keyboard.press("Escape")
    wait_until(lambda: all(engaged(worlds, r) for r in ROBOTS), timeout=10, message="one Esc on a button did not stop")
    page.locator("#notice").get_by_text("Emergency stop:").wait_for(timeout=5000)


# --- 2. drafts ------------------------------------------------------------------------------------
def test_unsaved_program_text_is_kept_as_a_draft_and_discarding_it_asks_first(page, worlds):
    saved = "print('saved')\n"
    program(worlds, "draft_me", saved)
    editor = open_program(page, "draft_me")
    state = page.locator(".draft-state")
    state.get_by_text("All changes saved.").wait_for(timeout=5000)
    editor.click()
    page.keyboard.press("Control+End")
    page.keyboard.insert_text("print('not saved yet')\n")
    state.get_by_text("Unsaved changes").wait_for(timeout=5000)
    page.get_by_role("button", name="draft_me (unsaved)").wait_for(timeout=5000)   # the list says it too
    screenshot(page, "keeps-draft-unsaved")

    go(page, "cartesian", ".jog-grid button")                      # a tab switch
    editor = open_program(page, "draft_me")
    wait_until(lambda: "not saved yet" in editor.inner_text(), timeout=5, message="the tab switch lost the edit")
    state.get_by_text("Unsaved changes").wait_for(timeout=5000)
    page.reload()                                                  # a reload
    page.wait_for_selector("body[data-ready=true]")
    editor = page.locator(".cm-content")
    wait_until(lambda: "not saved yet" in editor.inner_text(), timeout=10, message="the reload lost the edit")
    state.get_by_text("Unsaved changes").wait_for(timeout=5000)
    assert http(worlds, "GET", "/api/programs/draft_me")["text"] == saved   # a draft, not saved

    # Discard asks first (the page's own "Sure? Touch again", as Delete and Remove do).
    discard = page.get_by_role("button", name="Discard changes")
    discard.click()
    sure = page.get_by_role("button", name="Sure? Touch again")
    sure.wait_for(timeout=5000)
    assert "not saved yet" in editor.inner_text(), "the first touch discarded already"
    screenshot(page, "keeps-draft-discard-asks")
    sure.click()
    wait_until(lambda: "not saved yet" not in editor.inner_text(), timeout=5)
    state.get_by_text("All changes saved.").wait_for(timeout=5000)
    assert page.evaluate("localStorage.getItem('asibot.draft.draft_me')") is None
    assert page.get_by_role("button", name="Discard changes").is_disabled()

    # Saved: no draft is left.
    editor.click()
    page.keyboard.press("Control+End")
    page.keyboard.insert_text("print('saved too')\n")
    state.get_by_text("Unsaved changes").wait_for(timeout=5000)
    page.get_by_role("button", name="Save", exact=True).click()
    page.get_by_text("Saved draft_me.py.").wait_for(timeout=5000)
    state.get_by_text("All changes saved.").wait_for(timeout=5000)
    assert "saved too" in http(worlds, "GET", "/api/programs/draft_me")["text"]
    assert page.evaluate("localStorage.getItem('asibot.draft.draft_me')") is None


# --- 3. form fields -------------------------------------------------------------------------------
def test_typed_values_stay_across_tab_switches_and_reloads(page):
    go(page, "cartesian", ".jog-grid button")
    point = ["0.1", "0.45", "0.3", "180", "-5"]
    inputs = page.locator(".form-grid input")
    for i, value in enumerate(point):
        inputs.nth(i).fill(value)
    page.get_by_label("Movement").select_option("movl")
    page.get_by_label("Name of the next point").fill("over_the_sink")

    def kept() -> None:
        wait_until(lambda: [inputs.nth(i).input_value() for i in range(5)] == point, timeout=5,
                   message=lambda: f"the form shows {[inputs.nth(i).input_value() for i in range(5)]}")
        assert page.get_by_label("Movement").input_value() == "movl"
        assert page.get_by_label("Name of the next point").input_value() == "over_the_sink"

    go(page, "home", "text=Teach the robot a task")
    go(page, "cartesian", ".jog-grid button")
    kept()
    page.reload()
    page.wait_for_selector("body[data-ready=true]")
    page.wait_for_selector(".jog-grid button")
    kept()
    screenshot(page, "keeps-cartesian-form")

    go(page, "joint", ".form-grid input")
    page.locator(".form-grid input").nth(1).fill("33")
    go(page, "speech", "text=Words and phrases")
    page.get_by_label("Word or phrase").fill("half typed")
    go(page, "joint", ".form-grid input")
    wait_until(lambda: page.locator(".form-grid input").nth(1).input_value() == "33", timeout=5)
    go(page, "speech", "text=Words and phrases")
    assert page.get_by_label("Word or phrase").input_value() == "half typed"


# --- 4. the commanded robot -----------------------------------------------------------------------
def test_opening_the_pioneer_and_base_tabs_keeps_the_commanded_robot(page):
    go(page, "pioneer", ".about-robot")
    page.get_by_text(f"This page is about {PIONEER}").wait_for(timeout=5000)
    page.get_by_text(f"The page commands {ASIBOT} now").wait_for()
    assert page.locator(".jog-grid").count() == 0, "the tab shows controls of a robot the page does not command"
    screenshot(page, "keeps-pioneer-offer")
    go(page, "base", ".about-robot")
    page.get_by_text(f"This page is about {PIONEER}").wait_for(timeout=5000)
    page.locator(".about-robot").get_by_role("button", name=f"Command {PIONEER}").wait_for()
    screenshot(page, "keeps-base-offer")
    commanding(page, ASIBOT).wait_for()
    assert page.evaluate("localStorage.getItem('asibot.robot')") in (None, ASIBOT)

    # The Cartesian tab after them: it names its robot, and a refusal names it too.
    go(page, "cartesian", ".jog-grid button")
    page.get_by_role("heading", name=f"Move the tool of {ASIBOT}").wait_for(timeout=5000)
    for i, value in enumerate([3.0, 0, 0, 0, 0]):
        page.locator(".form-grid input").nth(i).fill(str(value))
    page.get_by_role("button", name="Move", exact=True).click()
    notice = page.locator("#notice")
    notice.wait_for(state="visible", timeout=10000)
    text = notice.inner_text()
    assert text.startswith(f"{ASIBOT}: ") and "reach" in text.lower(), text
    screenshot(page, "keeps-refusal-names-the-robot")

    # The switch is one button, on the tab, when the person wants it.
    go(page, "pioneer", ".about-robot")
    page.locator(".about-robot").get_by_role("button", name=f"Command {PIONEER}").click()
    page.get_by_text(f"This page commands {PIONEER}").wait_for(timeout=10000)
    commanding(page, PIONEER).wait_for(timeout=5000)
    page.locator(".jog-grid").first.wait_for(timeout=10000)
    # Back to the kitchen's arm, by the Connection Manager.
    page.locator("#connection").get_by_role("button", name=f"Command {ASIBOT}", exact=True).click()
    commanding(page, ASIBOT).wait_for(timeout=5000)
    page.locator(".about-robot").wait_for(timeout=5000)            # the tab is about pioneer-sim again


# --- 5. the run's state ---------------------------------------------------------------------------
SLOW = "import time\nprint('hello', flush=True)\ntime.sleep(4)\nprint('bye', flush=True)\n"


def test_program_and_launcher_show_the_current_run(page, worlds):
    program(worlds, "slow_hello", SLOW)
    http(worlds, "PUT", "/api/tasks/Slow%20hello", {"program": "slow_hello", "words": [], "icon": "can.svg"})
    http(worlds, "POST", "/api/programs/slow_hello/run", {"robot": ASIBOT})            # a run before the page looks
    wait_until(lambda: not http(worlds, "GET", "/api/run")["running"], timeout=60)

    go(page, "launcher", ".task-button")
    status = page.locator(".run-status")
    status.get_by_text(f"{ASIBOT}: slow_hello: finished.").wait_for(timeout=10000)
    page.get_by_role("button", name="Launch Slow hello").click()
    status.get_by_text(f"Slow hello is running on {ASIBOT}").wait_for(timeout=10000)   # not the last run's "finished"
    output = page.get_by_role("log", name="Program output")
    wait_until(lambda: "hello" in output.inner_text(), timeout=30)
    assert "bye" not in output.inner_text(), "the last run's output is still shown"
    screenshot(page, "keeps-launcher-running")
    status.get_by_text(f"{ASIBOT}: Slow hello: finished.").wait_for(timeout=60000)

    # The Program tab: a run started elsewhere (another page, the voice service) shows too.
    open_program(page, "slow_hello")
    status.get_by_text("Slow hello: finished.").wait_for(timeout=10000)
    http(worlds, "POST", "/api/programs/slow_hello/run", {"robot": ASIBOT})
    status.get_by_text(f"slow_hello is running on {ASIBOT}").wait_for(timeout=10000)
    screenshot(page, "keeps-program-running")
    status.get_by_text(f"{ASIBOT}: slow_hello: finished.").wait_for(timeout=60000)
    # And one started here.
    page.get_by_role("button", name="Run", exact=True).click()
    status.get_by_text(f"slow_hello is running on {ASIBOT}").wait_for(timeout=10000)
    status.get_by_text(f"{ASIBOT}: slow_hello: finished.").wait_for(timeout=60000)
    assert output.inner_text().split() == ["hello", "bye"]


def test_the_runner_tells_of_a_start_before_the_runs_first_line(tmp_path):
    """What the pages' `run` message rests on: on_start, with the new run's status, comes before
    any line of its output, so a page clears the last run's output and never the new one's."""
    import threading

    from asibot.web.runner import ProgramRunner

    heard: list[tuple] = []
    ended = threading.Event()
    runner = ProgramRunner(on_start=lambda s: heard.append(("start", s["running"], s["program"])),
                           on_output=lambda stream, line: heard.append((stream, line)),
                           on_exit=lambda result: ended.set())
    try:
        path = tmp_path / "quick.py"
        path.write_text("print('first', flush=True)\n")
        runner.start(path, ASIBOT, name="quick")
        wait_until(ended.is_set, timeout=30, message="the program did not end")
        assert heard == [("start", True, "quick"), ("out", "first")]
    finally:
        runner.close()

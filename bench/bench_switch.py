"""One switch, few presses: what a person with one switch (Space: tap = next, hold = select)
pays for the robot's common tasks, beside the page as it was before issue 30, in the same run.

Rows, each in presses and in seconds from the first press to the robot doing it:
- launch the red-can task (the task started on the arm);
- send the Pioneer to the fridge (its nav took the goal);
- the emergency stop from the farthest point (the ring inside the tab row, on its first tab);
- release it (every robot stopped by it released);
- make a program of steps (issue 27): a "Pick it up" program from a captured point, a Wait added
  and moved up before the lift, saved; scanning the whole page, as a carer who edits does. Its
  seconds are the script's, not a person's: this flow runs with two-tap stop off, so its taps
  are not paced as a person's are, and only its presses say what a person pays.

The reference is the page of `--reference` (a commit; by default the one before issue 30),
served by today's server (ASIBOT_WEB_STATIC): the routes it calls are all still there. The
steps row's reference is the page of `--steps-reference` (by default the one before the ring
went on from where the person works, with Save above the steps: 83 presses then). It is
driven as it was set up then: switch scanning on, the whole page. Today's page is driven as a
carer sets it up once on Home ("Turn switch scanning on": the person's tasks and places first;
two quick taps stop every robot). The script takes the shortest way a person would: tap to the
entry that holds the control, hold to open it, and so on (tests/web/switch.py).

    python bench/bench_switch.py [--reference COMMIT] [--steps-reference COMMIT] [--quick]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from table import QUICK_HELP, print_table  # noqa: E402

from asibot.testing import Stack, wait_until  # noqa: E402
from tests.web import switch  # noqa: E402
from tests.web.conftest import CHROMIUM, CHROMIUM_ARGS, fresh_page  # noqa: E402

ARM, BASE = "asibot-sim", "pioneer-sim"
TASK = "Give me the red can"
RED_CAN = ROOT / "libs" / "common" / "asibot" / "examples" / "give_me_the_red_can.py"
#: The page before issue 30 (one switch, few presses).
REFERENCE = "32b0496"
#: The page before the ring went on from where the person works (the steps editor's reference).
STEPS_REFERENCE = "694058f"
STEPS = "make a program of steps"
#: Issue 30's goals, in presses; the steps row has none (issue 27 counts a carer's touches).
GOALS = {"launch the red-can task": 5, "send the Pioneer to the fridge": 8,
         "emergency stop from the farthest point": 2, "release it": 3}
TASKS = (*GOALS, STEPS)
#: The point the steps row's program picks at: the red can, tool pointing down.
AT_THE_CAN = "grasp-can 0.0 0.5 0.09 180.0 0.0\n"
STEPS_SERVICES = ["web", "kinematics-asibot-sim"]
STEPS_ALIVE = [f"sim/{ARM}", f"kinematics/{ARM}", "web/main"]
STATIC = Path("services/web/asibot/web/static")
SERVICES = ["web", "kinematics-asibot-sim", "kinematics-pioneer-sim", "nav-pioneer-sim"]
ALIVE = [f"sim/{ARM}", f"kinematics/{ARM}", f"sim/{BASE}", f"nav/{BASE}", "web/main"]
#: The smoke run's tasks: today's page only, and no trip, so no perception or nav to start; the
#: red-can run is stopped once launched instead of lifting the can.
QUICK_TASKS = ("launch the red-can task", "emergency stop from the farthest point", "release it", STEPS)
QUICK_SERVICES = ["web", "kinematics-asibot-sim", "sim-apartment"]
QUICK_ALIVE = [f"sim/{ARM}", f"kinematics/{ARM}", f"sim/{BASE}", "web/main"]


def old_page(commit: str, into: Path) -> Path:
    """The page's files at `commit`, with today's npm bundle (it is built, not kept in git)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit, str(STATIC)], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    static = into / STATIC
    # A copy: the server follows no symbolic link out of its static folder.
    shutil.copytree(ROOT / "services" / "web" / "asibot" / "web" / "static" / "vendor", static / "vendor")
    return static


def served(url: str) -> bool:
    try:
        return urllib.request.urlopen(url, timeout=1).status == 200
    except OSError:
        return False


def stack(folder: Path, services: list[str], alive: list[str]) -> Stack:
    s = Stack(folder, "sim", services, ROOT / "compose.yaml")
    s.wait_alive(*alive, timeout=120)
    wait_until(lambda: served(s.web_url), timeout=30, interval=0.3)
    s.web("PUT", "/api/programs/give_me_the_red_can", {"text": RED_CAN.read_text()})
    s.web("PUT", "/api/tasks/Give%20me%20the%20red%20can", {"program": "give_me_the_red_can", "words": [], "icon": "can.svg"})
    return s


def engaged(s: Stack) -> list[str]:
    return [r for r in (ARM, BASE) if s.web("GET", f"/api/robots/{r}")[1]["estop"]["engaged"]]


def measured(page, act: Callable[[switch.Presses], None], done: Callable[[], bool]) -> tuple[int, float]:
    """Presses and seconds from the first press until `done`."""
    presses = switch.Presses(page)
    t0 = time.monotonic()
    act(presses)
    wait_until(done, timeout=60, interval=0.05)
    return presses.count, time.monotonic() - t0


def steps_program(s: Stack, page) -> tuple[int, float]:
    """The steps row: presses and seconds from the first press until the program is saved."""
    s.data.mkdir(exist_ok=True)
    (s.data / "points.ini").write_text(AT_THE_CAN)
    switch.with_settings(page, "#program", ".cm-content", ARM, enabled=True)
    before = set(s.web("GET", "/api/programs")[1]["programs"])

    def saved() -> bool:
        made = set(s.web("GET", "/api/programs")[1]["programs"]) - before
        return len(made) == 1 and s.web("GET", f"/api/programs/{made.pop()}/steps")[1]["in_sync"]

    def act(p: switch.Presses) -> None:
        p.start()
        switch.make_pick_program(page, p, "grasp-can")
    return measured(page, act, saved)


def flows(s: Stack, page, today: bool, quick: bool) -> dict[str, tuple[int, float]]:
    out = {}
    tasks = [t for t in (QUICK_TASKS if quick else TASKS) if t != STEPS]
    ready = "#for-me .favourite" if today else "text=Teach the robot a task"
    settings = {"enabled": True, "scope": "home", "doubleTapStop": True} if today else {"enabled": True}
    if not today:
        # The page before knew no setting it did not have: a stored file with one is refused whole.
        page.evaluate("localStorage.setItem('asibot.access', JSON.stringify({format: 'asibot-access-settings', version: 1, enabled: true}))")
        page.goto(page.url.split("#")[0] + "#home")
        page.reload()
        page.wait_for_selector("body[data-ready=true]")
        page.wait_for_selector(ready, timeout=15000)
    else:
        switch.with_settings(page, "#home", ready, ARM, **settings)

    def launched() -> bool:
        run = s.web("GET", "/api/run")[1]
        return run["program"] == TASK and (run["running"] or run["last"] is not None)

    def launch(p: switch.Presses) -> None:
        p.start()
        if not today:
            p.to("Launcher")
            page.wait_for_selector(".task-button")
        p.to(f"Launch {TASK}")
    if "launch the red-can task" in tasks:
        out["launch the red-can task"] = measured(page, launch, launched)
        if quick:
            s.web("POST", "/api/run/stop")
        wait_until(lambda: not s.web("GET", "/api/run")[1]["running"], timeout=180)

    def going() -> bool:
        nav = s.web("GET", f"/api/robots/{BASE}")[1].get("nav") or {}
        status = nav.get("status") or {}
        return status.get("state") == "active" and "fridge" in (status.get("text") or "")

    def fridge(p: switch.Presses) -> None:
        if not today:
            p.to("Base")
            page.wait_for_selector(f"text=Command {BASE}")
            p.to(f"Command {BASE}")
            page.wait_for_selector(".points li[data-place=fridge]", timeout=15000)
        p.to("Go to fridge")
    if "send the Pioneer to the fridge" in tasks:
        out["send the Pioneer to the fridge"] = measured(page, fridge, going)
        s.web("POST", f"/api/base/{BASE}/cancel")

    def farthest() -> None:
        """The ring inside the first row of tabs, on its first entry: the farthest from the stop."""
        tabs = page.evaluate("[...document.querySelectorAll('#tabs [role=tab]')].map((t) => t.innerText)")
        walk = switch.Presses(page)
        if today:
            walk.to("The whole page")
        walk.until(lambda r: "Home" in r and set(r) <= set(tabs))   # the first row of tabs
        walk.hold()
        page.wait_for_timeout(walk.gap_ms)

    def stop(p: switch.Presses) -> None:
        if today:
            p.quick_taps()
        else:                                     # round and round the row until it closes
            p.to("Emergency stop Esc")
    farthest()
    out["emergency stop from the farthest point"] = measured(page, stop, lambda: engaged(s) == [ARM, BASE])

    def release(p: switch.Presses) -> None:
        if today:
            page.wait_for_selector("#release-all[data-idle=false]")
            p.to("Release all emergency stops")
            return
        for robot in (ARM, BASE):
            page.wait_for_selector(f"[aria-label='Release emergency stop of {robot}']")
            p.to(f"Release emergency stop of {robot}")
    out["release it"] = measured(page, release, lambda: not engaged(s))
    if today:
        out[STEPS] = steps_program(s, page)
    return out


def on_a_page(s: Stack, robots: tuple[str, ...], drive: Callable[[Any], dict]) -> dict:
    """`drive` a fresh page of the stack `s` in chromium at 1280 x 800; what it measured."""
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            with fresh_page(browser, s.web_url, robots=robots, size=(1280, 800)) as page:
                return drive(page)
        finally:
            browser.close()


def run(reference: str, steps_reference: str, quick: bool) -> list[tuple]:
    results: dict[str, dict] = {}
    tasks = QUICK_TASKS if quick else TASKS
    services, alive = (QUICK_SERVICES, QUICK_ALIVE) if quick else (SERVICES, ALIVE)
    plan = [("before", reference, services, alive), ("today", None, services, alive),
            ("steps before", steps_reference, STEPS_SERVICES, STEPS_ALIVE)]
    with tempfile.TemporaryDirectory() as d:
        for name, commit, wanted, ready in plan:
            folder = Path(d) / name.replace(" ", "-")
            folder.mkdir()
            if commit is not None:
                old = old_page(commit, folder)        # in a smoke run too: a reference gone must show
                if quick:
                    continue
                os.environ["ASIBOT_WEB_STATIC"] = str(old)
            s = stack(folder, wanted, ready)
            os.environ.pop("ASIBOT_WEB_STATIC", None)
            try:
                if name == "steps before":
                    results["before"][STEPS] = on_a_page(s, (ARM,), lambda page: steps_program(s, page))
                else:
                    results[name] = on_a_page(s, (ARM, BASE), lambda page: flows(s, page, name == "today", quick))
            finally:
                s.stop()
    rows = []
    for task in tasks:
        goal = GOALS.get(task)
        ref = steps_reference if task == STEPS else reference
        (n0, t0), (n1, t1) = results.get("before", {}).get(task, ("-", "-")), results["today"][task]
        met = "" if goal is None else f"goal {goal}: {'met' if n1 <= goal else 'NOT met'}"
        rows.append((f"{task}: presses", "presses", n1, f"page at {ref}", n0, met))
        rows.append((f"{task}: time", "s", t1, f"page at {ref}", t0,
                     "the script's taps, unpaced" if task == STEPS else ""))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", default=REFERENCE, help="the commit whose page is the reference")
    parser.add_argument("--steps-reference", default=STEPS_REFERENCE,
                        help="the commit whose page is the steps row's reference")
    parser.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = parser.parse_args()
    print("One switch (Space: tap = next, hold = select), chromium at 1280 x 800\n")
    print_table(run(args.reference, args.steps_reference, args.quick), ("what", "unit", "today", "reference", "reference value", "goal"))


if __name__ == "__main__":
    main()

"""A page's CPU, by process: what the Task Creator costs the machine that also runs the robot.

The kitchen stack (`asibot up --only web kinematics-asibot-sim`) with one page open in a real
browser (Chromium without a graphics card, as on a robot's own computer or these machines), on
Home and on the Cartesian tab (camera picture, 3D view, camera points), the arm still and then
moving. Each process's CPU is read from /proc over the same window: the sim, the web server,
kinematics, the browser, and the browser's GPU process, where WebGL is drawn in software.
The reference, in the same run: the stack with no page open. The last rows draw the 3D view as a
browser with a graphics card gets it (antialiased, 25 pictures a second), made to believe it has
one: what the software-drawn view saves.

    python bench/bench_page_cpu.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from bench_web import CHROMIUM_ARGS, ROBOT, answers  # noqa: E402
from table import QUICK_HELP, print_table  # noqa: E402

from asibot.client import CartesianClient  # noqa: E402
from asibot.testing import PRETEND_GPU, Stack, wait_until  # noqa: E402

#: The columns, in order: which processes each one sums (by their command line).
KINDS = ("sim", "web", "kinematics", "browser", "browser's GPU process")
HZ = os.sysconf("SC_CLK_TCK")


def kind(cmdline: str) -> str | None:
    if "chromium" in cmdline or "chrome" in cmdline:
        return "browser's GPU process" if "--type=gpu-process" in cmdline else "browser"
    for name in ("sim", "web", "kinematics"):
        if f"-m asibot.{name}" in cmdline:
            return name
    return None


def descendants(root: int) -> dict[int, str]:
    """Every process under `root` (this bench: its stack, its browser), with its command line."""
    parents: dict[int, int] = {}
    lines: dict[int, str] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            lines[int(entry)] = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        parents[int(entry)] = int(stat.rsplit(")", 1)[1].split()[1])
    found, todo = {}, [root]
    while todo:
        pid = todo.pop()
        for child, parent in parents.items():
            if parent == pid and child not in found:
                found[child] = lines.get(child, "")
                todo.append(child)
    return found


def cpu_ticks(pids: dict[int, str]) -> dict[int, int]:
    ticks = {}
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        ticks[pid] = int(fields[11]) + int(fields[12])
    return ticks


def cores(seconds: float) -> dict[str, float]:
    """Each kind's CPU over the next `seconds`, in cores."""
    pids = descendants(os.getpid())
    before, start = cpu_ticks(pids), time.monotonic()
    time.sleep(seconds)
    after, wall = cpu_ticks(pids), time.monotonic() - start
    used: Counter[str] = Counter()
    for pid, ticks in after.items():
        name = kind(pids[pid])
        if name is not None and pid in before:
            used[name] += (ticks - before[pid]) / HZ / wall
    return {name: used[name] for name in KINDS}


class Swinging:
    """The arm's first joint swung back and forth until stopped: a robot at work."""

    def __init__(self, client: CartesianClient) -> None:
        self.client, self.stopping = client, threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        sign = 1
        while not self.stopping.is_set():
            self.client.relj([30 * sign, 0, 0, 0, 0], speed=0.5)
            self.client.wait(timeout=30)
            sign = -sign

    def __enter__(self) -> "Swinging":
        self.thread.start()
        time.sleep(0.3)                 # under way
        return self

    def __exit__(self, *exc: object) -> None:
        self.stopping.set()
        self.client.stop()              # now, not at the end of the swing under way
        self.thread.join(timeout=30)


def row(page: str, arm: str, used: dict[str, float]) -> tuple:
    return (page, arm, sum(used.values()), *(used[name] for name in KINDS))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    quick = ap.parse_args().quick
    window, settle = (1.0, 0.3) if quick else (10.0, 2.0)
    from playwright.sync_api import sync_playwright

    rows = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=CHROMIUM_ARGS)
        stack = Stack(Path(tmp), "sim", ["web", "kinematics-asibot-sim"], ROOT / "compose.yaml")
        os.environ["ASIBOT_ROUTER"] = stack.endpoint   # for this process's client
        try:
            client = CartesianClient(timeout=5.0)
            wait_until(lambda: answers(client), timeout=120, interval=0.2)
            stack.wait_alive("web/main", timeout=60)

            def measure(page_name: str) -> None:
                time.sleep(settle)              # what opening the page started has settled
                rows.append(row(page_name, "still", cores(window)))
                with Swinging(client):
                    rows.append(row(page_name, "moving", cores(window)))

            measure("no page (reference)")
            for tab, pretend in (("home", False), ("cartesian", False), ("cartesian", True)):
                context = browser.new_context(viewport={"width": 1366, "height": 900})
                if pretend:
                    context.add_init_script(PRETEND_GPU)
                page = context.new_page()
                page.goto(f"{stack.web_url}#{tab}")
                page.wait_for_selector("body[data-ready=true]", timeout=30000)
                page.wait_for_selector(f".robot-card[data-robot={ROBOT}]", timeout=30000)
                name = tab.capitalize()
                if tab == "cartesian":
                    page.wait_for_selector(".viewer canvas", timeout=30000)
                    drawn = page.get_attribute(".viewer", "data-renderer")
                    name += (", 3D view as with a graphics card" if drawn == "gpu" else ", 3D view drawn in software")
                    if pretend and drawn != "gpu":
                        raise SystemExit("the page did not take the pretended graphics card: the row would compare nothing")
                measure(name)
                context.close()
        finally:
            client.close()
            stack.stop()
    print_table(rows, header=("page", "arm", "all (cores)", *KINDS))
    print(f"\n(each figure: CPU over {window:.0f} s, in cores of this machine's {os.cpu_count()}; "
          "the arm swings its first joint 30 degrees at half speed)")


if __name__ == "__main__":
    main()

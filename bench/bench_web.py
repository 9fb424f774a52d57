"""Web Task Creator benchmark: what a person waits for, in a real browser against the kitchen.

Rows (each beside a reference measured in the same run):
- `asibot up` to a usable page (the page loaded, its feed live, the arm listed), beside `asibot
  up` to the kinematics service answering;
- arm state from the driver to the page, p50/p99, beside the driver to a plain bus subscriber;
- jog press (pointer down on a hold-to-move button) to the first arm command, p50/p99, beside a
  Python program's movjv call to the first arm command;
- handheld pointer (the Pointer tab, a simulated phone's tilt): the dead-man toggled on (Space)
  to the first arm command, and a tilt report to the first arm command that follows it,
  p50/p99, beside a Python program's `pointer` call to the first arm command;
- one-switch scanning (the Launcher, Space as the switch): a tap to the ring moved onto the
  next element, p50/p99, beside the browser's frame time;
- page weight and load time, beside the npm packages' share;
- a fresh page (a new browser context) usable on Home, Joint and Program, beside a blank page
  in a new context.

Times in the browser and in this process are both the machine's wall clock (the browser's
`performance.timeOrigin + performance.now()`), so one-way delays need no round trip.

    python bench/bench_web.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from table import QUICK_HELP, print_table  # noqa: E402

from asibot import keys  # noqa: E402
from asibot.client import CartesianClient  # noqa: E402
from asibot.messages import ArmCommand, ArmState  # noqa: E402
from asibot.testing import Stack, wait_until  # noqa: E402
from asibot.web.pointer import PointerSettings  # noqa: E402

ROBOT = "asibot-sim"
BEAT_MS = PointerSettings().beat_ms
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def served(url: str) -> bool:
    try:
        return urllib.request.urlopen(url, timeout=1).status == 200
    except OSError:
        return False


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    quick = ap.parse_args().quick
    n_jogs, move_s, hops = (1, 0.5, 5) if quick else (20, 3.0, 50)
    from playwright.sync_api import sync_playwright

    rows = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=CHROMIUM_ARGS)
        t0 = time.monotonic()
        stack = Stack(Path(tmp), "sim", ["web", "kinematics-asibot-sim"], ROOT / "compose.yaml")
        os.environ["ASIBOT_ROUTER"] = stack.endpoint   # for this process's client
        try:
            # --- start-up ----------------------------------------------------------------------
            client = CartesianClient(timeout=1.0)
            wait_until(lambda: answers(client), timeout=120, interval=0.1)
            t_kinematics = time.monotonic() - t0
            wait_until(lambda: served(stack.web_url), timeout=60, interval=0.05)
            page = browser.new_page(viewport={"width": 1366, "height": 900})
            sizes: dict[str, int] = {}
            def weigh(response) -> None:
                sizes[response.url] = len(response.body()) if response.ok else 0
            page.on("response", weigh)
            load_start = time.monotonic()
            page.goto(stack.web_url + "#joint")
            page.wait_for_selector("body[data-ready=true]")
            page.wait_for_selector(".robot-card[data-robot=asibot-sim]")
            t_page = time.monotonic() - t0
            t_load = time.monotonic() - load_start
            rows.append(("`asibot up` to a usable page", "s", t_page, "kinematics answering", t_kinematics, "10 s"))
            page.wait_for_timeout(500)
            total = sum(sizes.values())
            vendor = sum(v for k, v in sizes.items() if "/static/vendor/" in k)
            # The first load only: a body asked for after a later reload of the page is gone.
            page.remove_listener("response", weigh)
            rows.append(("page weight", "KiB", total / 1024, "of which npm packages", vendor / 1024, ""))
            rows.append(("page load to usable (cached server, fresh browser)", "s", t_load, "", "", ""))
            rows += fresh_page_rows(browser, stack.web_url, 1 if quick else 10)

            # --- arm state to the page ---------------------------------------------------------
            page.evaluate("""() => {
                window.__seen = [];
                const session = document.querySelector('meta[name=asibot-session]').content;
                const ws = new WebSocket(`ws://${location.host}/ws?session=${session}`);
                ws.onmessage = (e) => { const m = JSON.parse(e.data);
                  if (m.type === 'robot' && m.robot.id === 'asibot-sim' && m.robot.joints)
                    window.__seen.push([performance.timeOrigin + performance.now(), m.robot.joints.deg]); };
            }""")
            published: list[tuple[float, list[float]]] = []
            bus = stack.bus
            sub = bus.subscribe(keys.arm_state(ROBOT), ArmState,
                                lambda m: published.append((time.time() * 1000, [round(float(np.degrees(v)), 3) for v in m.positions])))
            client.movj(joints=[40, 20, 30, 20, 30], duration=move_s)
            client.wait(timeout=20)
            client.movj(joints=[0, 10, 20, 10, 0], duration=move_s)
            client.wait(timeout=20)
            sub.close()
            seen = page.evaluate("window.__seen")
            first_seen: dict[tuple, float] = {}
            for t, deg in seen:
                first_seen.setdefault(tuple(deg), t)
            to_page, to_bus = [], []
            for t, deg in published:
                if tuple(deg) in first_seen:
                    to_page.append(first_seen[tuple(deg)] - t)
            # The reference: the same states to a subscriber in this process (driver -> bus).
            # The subscriber above stamped arrival; the driver's own send time is not on the wire,
            # so measure the bus hop as half an RPC round trip to the sim.
            for _ in range(hops):
                s = time.perf_counter()
                bus.call(keys.driver_rpc(ROBOT, "object_pose"), {"name": "red_can"})
                to_bus.append((time.perf_counter() - s) * 1000 / 2)
            rows.append(("arm state, driver to page p50", "ms", pct(to_page, 50), "bus hop p50", pct(to_bus, 50), ""))
            rows.append(("arm state, driver to page p99", "ms", pct(to_page, 99), "bus hop p99", pct(to_bus, 99), ""))
            rows.append(("arm states shown in the page", "%", 100.0 * len(to_page) / max(1, len(published)),
                         "push rate", "30 Hz", "20 Hz or more"))

            # --- jog press to the first arm command -------------------------------------------
            commands: list[float] = []
            csub = bus.subscribe(keys.arm_command(ROBOT), ArmCommand, lambda m: commands.append(time.time() * 1000))
            page.get_by_role("button", name="Hold to move").click()
            page.evaluate("""() => { window.__press = [];
                document.addEventListener('pointerdown', () => window.__press.push(performance.timeOrigin + performance.now()), true); }""")
            jog = []
            for i in range(n_jogs):
                wait_until(lambda: _idle(client), timeout=10)
                commands.clear()
                name = "Joint 1 plus" if i % 2 == 0 else "Joint 1 minus"
                box = page.get_by_role("button", name=name).bounding_box()
                page.mouse.move(box["x"] + 20, box["y"] + 20)
                page.mouse.down()
                wait_until(lambda: commands, timeout=5)
                page.wait_for_timeout(300)
                page.mouse.up()
                press = page.evaluate("window.__press")[-1]
                jog.append(commands[0] - press)
                page.wait_for_timeout(400)
            reference = []
            for i in range(n_jogs):
                wait_until(lambda: _idle(client), timeout=10)
                commands.clear()
                s = time.time() * 1000
                client.movjv([5 if i % 2 == 0 else -5, 0, 0, 0, 0])
                wait_until(lambda: commands, timeout=5)
                reference.append(commands[0] - s)
                time.sleep(0.4)
            csub.close()
            rows.append(("jog press to first arm command p50", "ms", pct(jog, 50), "movjv from Python p50", pct(reference, 50), ""))
            rows.append(("jog press to first arm command p99", "ms", pct(jog, 99), "movjv from Python p99", pct(reference, 99), ""))
            rows += switch_rows(page, n_jogs * 3)
            rows += pointer_rows(page, bus, client, n_jogs)
            client.close()
        finally:
            browser.close()
            stack.stop()
    print_table(rows, ("what", "unit", "value", "reference", "reference value", "budget"))
    print(f"\n(samples: {len(to_page)} arm states, {len(jog)} jog presses; median of the page lag "
          f"{statistics.median(to_page) if to_page else float('nan'):.1f} ms)")


#: What each timed tab shows once it is usable: Home's first button, the 3D view (three.js, the
#: robot's model), the editor (CodeMirror). A tab's code is loaded when it is first shown.
SHOWN = {"home": "text=Teach the robot a task", "joint": ".viewer canvas", "program": ".cm-content"}


def fresh_page_rows(browser, url: str, n: int) -> list[tuple]:
    """A page of its own (a new browser context: nothing cached in the browser) opened on a tab
    until usable (its feed live, the arm listed, the tab shown), p50 of n, beside a blank page in
    a new context: what the browser costs before our page does anything."""
    def opened(target: str, ready: list[str]) -> float:
        start = time.monotonic()
        context = browser.new_context(viewport={"width": 1366, "height": 900})
        try:
            page = context.new_page()
            page.goto(target)
            for selector in ready:
                page.wait_for_selector(selector, timeout=30000)
            return time.monotonic() - start
        finally:
            context.close()
    blank = [opened("about:blank", []) for _ in range(n)]
    rows = []
    for tab, shown in SHOWN.items():
        times = [opened(f"{url}#{tab}", ["body[data-ready=true]", ".robot-card[data-robot=asibot-sim]", shown])
                 for _ in range(n)]
        rows.append((f"a fresh page usable on {tab.capitalize()} p50", "s", pct(times, 50),
                     "a blank page, fresh context p50", pct(blank, 50), ""))
    return rows


def pointer_rows(page, bus, client: CartesianClient, n: int) -> list[tuple]:
    """The Pointer tab with a phone that reports its tilt every 20 ms: the dead-man switched on
    to the first arm command; a tilt report to the first arm command after it (the page sends one
    report a beat); a Python `pointer` call to the first arm command."""
    commands: list[float] = []
    sub = bus.subscribe(keys.arm_command(ROBOT), ArmCommand, lambda m: commands.append(time.time() * 1000))
    page.evaluate("""() => { window.__reports = [];
        setInterval(() => { window.dispatchEvent(new DeviceOrientationEvent('deviceorientation', { alpha: 0, beta: 0, gamma: 0 }));
                            window.__reports.push(performance.timeOrigin + performance.now()); }, 20);
        window.__keys = [];
        document.addEventListener('keydown', (e) => { if (e.key === ' ') window.__keys.push(performance.timeOrigin + performance.now()); }, true); }""")
    page.goto(page.url.split("#")[0] + "#pointer")
    page.wait_for_selector("text=Motion control")
    for name in ("Phone tilt", "Tap the dead-man on and off"):
        page.get_by_role("button", name=name, exact=True).focus()
        page.keyboard.press("Space")
    press, report, reference = [], [], []
    for _ in range(n):
        wait_until(lambda: _idle(client), timeout=10)
        commands.clear()
        page.get_by_role("button", name="Dead-man: off", exact=True).focus()
        page.keyboard.press("Space")                       # on: the tool follows the phone
        wait_until(lambda: commands, timeout=5, message=lambda: _pointer_said(page, client))
        page.wait_for_timeout(300)
        page.get_by_role("button", name="Dead-man: on", exact=True).focus()
        page.keyboard.press("Space")                       # off: the arm stops
        pressed = page.evaluate("window.__keys")[-2]
        press.append(commands[0] - pressed)
        reports = page.evaluate("window.__reports")
        # each command after the first follows the latest report sent before it
        for c in commands[1:6]:
            before = [r for r in reports if r <= c]
            if before:
                report.append(c - before[-1])
        page.wait_for_timeout(400)
    for _ in range(n):
        wait_until(lambda: _idle(client), timeout=10)
        commands.clear()
        s = time.time() * 1000
        bus.call(keys.cart_rpc(ROBOT, "pointer"), {"deadman": True, "direction": "forward", "pitch": 90.0}, timeout=5)
        wait_until(lambda: commands, timeout=5)
        reference.append(commands[0] - s)
        bus.call(keys.cart_rpc(ROBOT, "pointer"), {"deadman": False}, timeout=5)
        time.sleep(0.3)
    sub.close()
    return [("pointer: dead-man on to first arm command p50", "ms", pct(press, 50), "pointer from Python p50", pct(reference, 50), ""),
            ("pointer: dead-man on to first arm command p99", "ms", pct(press, 99), "pointer from Python p99", pct(reference, 99), ""),
            ("pointer: tilt report to arm command p50", "ms", pct(report, 50), "the page's beat", float(BEAT_MS), ""),
            ("pointer: tilt report to arm command p99", "ms", pct(report, 99), "", "", "")]


def switch_rows(page, n: int) -> list[tuple]:
    """One-switch step scanning on the Launcher: a tap of Space to the ring moved onto the next
    element (its step changed in the page), beside the page's frame time."""
    page.evaluate("(s) => localStorage.setItem('asibot.access', JSON.stringify(s))",
                  {"format": "asibot-access-settings", "version": 1, "enabled": True, "doubleTapStop": False})
    # The scanner's own capturing listener swallows the switch: ours must come first, so it is
    # installed before the page's scripts run.
    page.add_init_script("""window.__taps = [];
        window.addEventListener('keydown', (e) => { if (e.key === ' ') window.__taps.push(performance.now()); }, true);""")
    page.goto(page.url.split("#")[0] + "#launcher")
    page.reload()
    page.wait_for_selector("body[data-ready=true]")
    page.wait_for_selector(f".robot-card[data-robot={ROBOT}]", timeout=15000)
    page.evaluate("""() => { window.__moved = [];
        new MutationObserver(() => window.__moved.push(performance.now()))
            .observe(document.getElementById('scan-ring'), { attributes: true, attributeFilter: ['data-step'] }); }""")
    step = "document.getElementById('scan-ring').dataset.step || '0'"
    for _ in range(n):
        before = page.evaluate(step)
        page.keyboard.press("Space")
        # after `rounds` rounds a tap stops the scan instead (the next one starts it again)
        page.wait_for_function(f"(s) => ({step}) !== s || document.getElementById('scan-ring').hidden",
                               arg=before, timeout=5000)
        page.wait_for_timeout(50)
    taps, moved = page.evaluate("[window.__taps, window.__moved]")
    # a tap that stopped the scan moved nothing: the next tap's ring is not its answer
    ends = taps[1:] + [float("inf")]
    lag = [min(m for m in moved if t <= m < end) - t for t, end in zip(taps, ends)
           if any(t <= m < end for m in moved)]
    frames = page.evaluate("""() => new Promise((done) => { const t = [];
        const f = (now) => { t.push(now); if (t.length < 61) requestAnimationFrame(f);
                             else done(t.slice(1).map((v, i) => v - t[i])); }; requestAnimationFrame(f); })""")
    page.evaluate("() => localStorage.removeItem('asibot.access')")
    page.reload()                                # scanning off again for what follows
    page.wait_for_selector("body[data-ready=true]")
    page.wait_for_selector(f".robot-card[data-robot={ROBOT}]", timeout=15000)
    return [("switch tap to the ring on the next element p50", "ms", pct(lag, 50), "frame time p50", pct(frames, 50), ""),
            ("switch tap to the ring on the next element p99", "ms", pct(lag, 99), "frame time p99", pct(frames, 99), "")]


def answers(client: CartesianClient) -> bool:
    try:
        if client.robot is None:
            client.open(ROBOT)
        client.stat()
        return True
    except Exception:
        return False


def _pointer_said(page, client: CartesianClient) -> str:
    """What the page and the arm said when the dead-man sent nothing: a failure's message."""
    said = page.evaluate("""() => ({
        status: [...document.querySelectorAll('#view [role=status]')].map((n) => n.textContent).join(' | '),
        notice: (document.getElementById('notice') || {}).textContent || '',
        deadman: [...document.querySelectorAll('button.deadman')].map((b) => `${b.textContent} pressed=${b.getAttribute('aria-pressed')} disabled=${b.disabled}`).join(', '),
        focused: document.activeElement ? (document.activeElement.textContent || document.activeElement.tagName) : '',
        scanning: !document.getElementById('scan-ring')?.hidden,
        reports: (window.__reports || []).length,
    })""")
    return f"the dead-man sent no arm command within 5 s; the page: {said}; the arm: {client.state()}"


def _idle(client: CartesianClient) -> bool:
    return client.state()["state"] == "not_controlling"


if __name__ == "__main__":
    main()

"""Browser tests: `asibot up` with the kitchen, its kinematics and the web page, and Debian's
chromium driven by Playwright (never a downloaded browser)."""

from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from asibot import robots
from asibot.bus import Bus
from asibot.kinematics.model import solver_for
from asibot.kinematics.server import KinematicsServer
from asibot.web import service
from asibot.testing import IdealDriver, Stack, memory_bus, wait_until

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
SHOTS = ROOT / "tests" / "web" / "screenshots"
#: The `web` fixture's robot and where its ideal driver starts (rad).
API_ROBOT = "asibot-sim"
API_START = np.radians([0.0, 20.0, 40.0, 30.0, 0.0])


def _stack(folder: Path, services: list[str], alive: list[str]):
    """`asibot up --only SERVICES` with the web page, once every `alive` service announced itself
    and the page is served."""
    import urllib.request
    stack = Stack(folder, "sim", ["web", *services], ROOT / "compose.yaml")
    try:
        stack.wait_alive(*alive, "web/main", timeout=90)

        def page_served() -> bool:
            try:
                return urllib.request.urlopen(stack.web_url, timeout=2).status == 200
            except OSError:
                return False
        wait_until(page_served, timeout=30, interval=0.3)
    except BaseException:
        stack.stop()
        raise
    return stack


@pytest.fixture(scope="module")
def kitchen(tmp_path_factory):
    """The kitchen simulation, its kinematics service and the web page, for one test module."""
    stack = _stack(tmp_path_factory.mktemp("kitchen"), ["kinematics-asibot-sim"], ["sim/asibot-sim", "kinematics/asibot-sim"])
    yield stack
    stack.stop()


@pytest.fixture(scope="module")
def apartment(tmp_path_factory):
    """The apartment simulation with the Pioneer and its Katana arm, its kinematics, perception
    and navigation, and the page."""
    stack = _stack(tmp_path_factory.mktemp("apartment"), ["kinematics-pioneer-sim", "nav-pioneer-sim"],
                   ["sim/pioneer-sim", "kinematics/pioneer-sim", "perception/pioneer-sim", "nav/pioneer-sim"])
    yield stack
    stack.stop()


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


@contextlib.contextmanager
def fresh_page(browser, url: str, robots: tuple[str, ...] = (API_ROBOT,), size: tuple[int, int] = (1366, 900)):
    """A page of its own (its own storage) on the Task Creator at `url`, ready: its script
    started, its feed live and the cards of `robots` shown. It must raise no script error."""
    context = browser.new_context(viewport={"width": size[0], "height": size[1]})
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_selector("body[data-ready=true]", timeout=15000)
    for robot in robots:
        page.wait_for_selector(f".robot-card[data-robot={robot}]", timeout=30000)
    yield page
    context.close()
    assert not errors, f"the page raised: {errors}"


@pytest.fixture
def page(browser, kitchen, request):
    """A fresh page on the Task Creator, ready (its script started and its feed live), at the
    test module's PAGE_SIZE (width, height) if it names one."""
    size = getattr(request.module, "PAGE_SIZE", (1366, 900))
    with fresh_page(browser, kitchen.web_url, size=size) as page:
        yield page


@pytest.fixture(scope="class")
def looking_page(browser, kitchen):
    """One page for a class of tests that only look at views (axe, Tab), one view after another:
    a fresh page costs about 2 s of a loaded machine each, and looking changes nothing that a
    later look would see. A test that clicks, types or changes settings takes `page`. Closed
    with its class, as an open page takes its share of the cores."""
    with fresh_page(browser, kitchen.web_url) as page:
        yield page


def http(stack, method: str, path: str, body: dict | None = None) -> dict:
    """A call of the web's API that must succeed; its answer."""
    status, answer = stack.web(method, "/" + path.lstrip("/"), body)
    assert status < 400, f"{method} {path}: {status} {answer}"
    return answer or {}


class HeldAnswers:
    """The page's requests to `pattern`, their answers held while `holding` (a server that is
    slow to answer, at the moment a test chooses), then let through with `release`."""

    def __init__(self, page, pattern: str, holding: bool = False) -> None:
        self.page, self.pattern, self.holding = page, pattern, holding
        self.routes: list = []
        page.route(pattern, lambda route: self.routes.append(route) if self.holding else route.continue_())

    def wait(self, message: str) -> None:
        """Until a request is held. Playwright calls a route's handler only while the test is
        inside a Playwright call: a wait that only sleeps would never see the request."""
        wait_until(lambda: self.page.wait_for_timeout(50) or self.routes, 5, message=message)

    def release(self) -> None:
        """Stop holding, and let the held requests through, once one of them is answered."""
        self.holding = False
        with self.page.expect_response(self.pattern):
            while self.routes:
                self.routes.pop(0).continue_()


def screenshot(page, name: str) -> Path:
    SHOTS.mkdir(exist_ok=True)
    path = SHOTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    """The web service on the in-memory bus with an ideal ASIBOT driver (at START) and the real
    kinematics server: (TestClient, the service, the driver, the kinematics server)."""
    with memory_bus("web-api"):
        spec = robots.get(API_ROBOT)
        driver = IdealDriver(API_ROBOT, spec)
        driver.set_joints(API_START)
        kin_bus = Bus("kinematics")
        server = KinematicsServer(kin_bus, API_ROBOT, solver_for(spec), spec)
        web_bus = Bus("web")
        svc = service.build(web_bus, argparse.Namespace(host="127.0.0.1", port=8080, lan=False, new_token=False,
                                                         data=tmp_path_factory.mktemp("data")))
        client = page_client(svc)
        wait_until(lambda: API_ROBOT in svc.fleet.ids() and svc.fleet.point(API_ROBOT) is not None, timeout=10)
        yield client, svc, driver, server
        svc.close()
        server.close()
        driver.close()
        for bus in (web_bus, kin_bus):
            bus.close()


def page_client(svc) -> TestClient:
    """A test client that calls the API as the served page does: by the server's own name, with
    its session token (asibot.web.guard)."""
    return TestClient(svc.app, base_url="http://127.0.0.1:8080", headers={"X-Asibot-Session": svc.web.session})


def settle(web) -> None:
    """The `web` fixture's arm at rest, its controller idle and no command still on its way."""
    client, svc, driver, server = web
    server.ctl.stop()
    wait_until(lambda: server.ctl.state == "not_controlling", timeout=2)
    # The hold that a stop sends may still be on its way: wait until the driver hears nothing new.
    seen = [len(driver.commands), time.monotonic()]

    def quiet() -> bool:
        if len(driver.commands) != seen[0]:
            seen[:] = [len(driver.commands), time.monotonic()]
        return time.monotonic() - seen[1] > 0.3
    wait_until(quiet, timeout=5)

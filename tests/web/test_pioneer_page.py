"""The Pioneer arm page against the apartment simulation: the Katana jogged from the browser."""

from __future__ import annotations

import math

import pytest

from asibot import keys
from asibot.messages import ArmState
from asibot.testing import Inbox, wait_until

from .conftest import screenshot

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def test_the_pioneer_page_jogs_the_katana(browser, apartment):
    page = browser.new_page(viewport={"width": 1366, "height": 900})
    try:
        page.goto(apartment.web_url + "#pioneer")        # straight to the tab, before any robot is known
        page.wait_for_selector("body[data-ready=true]")
        page.get_by_text("This page commands pioneer-sim").wait_for(timeout=15000)
        states = Inbox()
        sub = apartment.bus.subscribe(keys.arm_state("pioneer-sim"), ArmState, states)
        wait_until(lambda: len(states), timeout=10)
        q0 = states.last().positions[0]
        page.get_by_role("button", name="Joint 1 plus").click()
        wait_until(lambda: abs(states.last().positions[0] - q0 - math.radians(5)) < math.radians(0.3), timeout=15)
        z = page.locator(".jog-grid").nth(1).locator(".value").nth(2)
        z0 = float(z.inner_text())
        page.get_by_role("button", name="z minus").click()
        wait_until(lambda: abs(float(z.inner_text()) - (z0 - 0.1)) < 0.005, timeout=15)
        screenshot(page, "pioneer-arm")
        sub.close()
    finally:
        page.close()
